//! The SID U-Net (Chen et al., "Learning to See in the Dark", 2018) for
//! raw -> raw denoising: 4 packed Bayer planes in, 4 out.
//!
//! Five levels of two 3x3 convolutions with LeakyReLU(0.2) at widths w, 2w,
//! 4w, 8w, 16w; 2x2 max-pool down, 2x2 stride-2 transposed convolution up,
//! skip connections by concatenation, a 1x1 head. Four pooling steps need
//! sides that are multiples of 16: other sizes are padded by reflection
//! (zeros when the image is too small to reflect) and the output is cropped
//! back, so any packed image size works.

use super::network::NetworkConfig;
use super::{Extras, Method};
use crate::condition::Conditioning;
use crate::error::{ArchFault, NnError, Result as NnResult};
use crate::layers::Layer;
use crate::named::NamedTensor;
use crate::ops::{self, PgrfOps};
use burn::config::Config;
use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::pool::{MaxPool2d, MaxPool2dConfig};
use burn::nn::{LeakyRelu, LeakyReluConfig, PaddingConfig2d};
use burn::tensor::backend::Backend;
use burn::tensor::ops::PadMode;
use burn::tensor::Tensor;
use std::collections::BTreeMap;

/// Multiple that input sides are padded to (2^4 for four poolings).
const SIDE_MULTIPLE: usize = 16;

/// The SID U-Net's architecture (burn `Config`: `SidUnetConfig::new()` gives
/// the defaults, `with_width(..)` etc. change one field). Stored in weight
/// files (`arch = "sid-unet"`) and built by [`SidUnetConfig::init`].
#[derive(Config, Debug)]
pub struct SidUnetConfig {
    /// Width of the first level (32 in the paper); level k has
    /// `width * 2^k` channels, k = 0..4.
    #[config(default = 32)]
    pub width: usize,
    /// Input planes: 4, the packed R, G1, B, G2 of the amplified noisy raw,
    /// plus the conditioning's planes (4 + `conditioning.extra_channels()`).
    #[config(default = 4)]
    pub in_channels: usize,
    /// Output planes: 4, the packed clean estimate (not clamped; inference
    /// clamps it to [0, 1]).
    #[config(default = 4)]
    pub out_channels: usize,
    /// Add the input to the output, so the network learns the correction
    /// to the amplified input rather than the clean image. Not SID's design
    /// (off by default): it starts from the identity instead of a constant
    /// and reaches the noisy input's PSNR at once, which small models trained
    /// for a few thousand steps on a CPU need.
    #[config(default = false)]
    pub residual: bool,
    /// How the network is told its input's noise level
    /// ([`crate::condition`]); absent in files written before it existed.
    #[config(default = "Conditioning::None")]
    pub conditioning: Conditioning,
    /// Read the capture's values below black as recorded (negative after the
    /// black is subtracted), instead of clamped at 0 (SID's convention, and
    /// every file written before it existed): the clamp biases dark areas up
    /// and hides half of the read noise (MODELS.md, issue 51).
    #[config(default = false)]
    pub keep_below_black: bool,
}

#[derive(Module, Debug)]
struct DoubleConv<B: Backend> {
    first: Conv2d<B>,
    second: Conv2d<B>,
    act: LeakyRelu,
}

impl<B: Backend> DoubleConv<B> {
    fn new(cin: usize, cout: usize, device: &B::Device) -> Self {
        let conv = |a, b| {
            Conv2dConfig::new([a, b], [3, 3])
                .with_padding(PaddingConfig2d::Same)
                .init(device)
        };
        DoubleConv {
            first: conv(cin, cout),
            second: conv(cout, cout),
            act: LeakyReluConfig::new().with_negative_slope(0.2).init(),
        }
    }

    /// What `forward` runs on an `h` x `w` input, appended to `out`.
    fn layers(&self, h: usize, w: usize, out: &mut Vec<Layer>) {
        for conv in [&self.first, &self.second] {
            let layer = Layer::conv(conv, h, w);
            let channels = layer.out_channels().expect("a convolution");
            out.extend([layer, Layer::LeakyRelu { channels, h, w }]);
        }
    }
}

impl<B: PgrfOps> DoubleConv<B> {
    fn forward(&self, x: Tensor<B, 4>) -> Tensor<B, 4> {
        let slope = self.act.negative_slope as f32;
        let x = ops::conv2d_leaky(&self.first, x, slope);
        ops::conv2d_leaky(&self.second, x, slope)
    }
}

/// The SID U-Net denoiser of the SPC method, on backend `B`: raw -> raw,
/// `(n, 4, h, w)` in and out, any `h` and `w` ([`SidUnet::forward`]). Built
/// by [`SidUnetConfig::init`] or loaded from a weight file; its parameters
/// are private, named by their field path in weight files
/// ([`crate::named`]).
#[derive(Module, Debug)]
pub struct SidUnet<B: Backend> {
    down: Vec<DoubleConv<B>>,
    pool: MaxPool2d,
    up: Vec<ConvTranspose2d<B>>,
    merge: Vec<DoubleConv<B>>,
    head: Conv2d<B>,
    residual: bool,
    #[module(skip)]
    conditioning: Conditioning,
    #[module(skip)]
    keep_below_black: bool,
}

impl SidUnetConfig {
    /// What pgrf cannot run in this configuration (read from a file): a
    /// width of 0, or planes other than pgrf's four (and the
    /// conditioning's) in and four out.
    pub(crate) fn fault(&self) -> Result<(), ArchFault> {
        let planes = 4 + self.conditioning.extra_channels();
        if self.width == 0 || self.in_channels != planes || self.out_channels != 4 {
            return Err(ArchFault::SidPlanes {
                planes,
                conditioning: self.conditioning,
                width: self.width,
                found_in: self.in_channels,
                found_out: self.out_channels,
            });
        }
        Ok(())
    }

    /// A network of this architecture on `device`, with burn's default
    /// initialisation (drawn lazily from burn's generator: see
    /// [`crate::seeded`] for reproducible weights); a residual network's
    /// output layer starts at zero.
    pub fn init<B: Backend>(&self, device: &B::Device) -> SidUnet<B> {
        let w = self.width;
        let widths = [w, 2 * w, 4 * w, 8 * w, 16 * w];
        let mut down = Vec::new();
        let mut cin = self.in_channels;
        for &c in &widths {
            down.push(DoubleConv::new(cin, c, device));
            cin = c;
        }
        let mut up = Vec::new();
        let mut merge = Vec::new();
        for level in (0..4).rev() {
            let (hi, lo) = (widths[level + 1], widths[level]);
            up.push(
                ConvTranspose2dConfig::new([hi, lo], [2, 2])
                    .with_stride([2, 2])
                    .init(device),
            );
            merge.push(DoubleConv::new(2 * lo, lo, device));
        }
        SidUnet {
            down,
            pool: MaxPool2dConfig::new([2, 2]).with_strides([2, 2]).init(),
            up,
            merge,
            head: if self.residual {
                // Zero output layer: a residual network starts as the
                // identity, at the noisy input's PSNR, not below it.
                Conv2dConfig::new([w, self.out_channels], [1, 1])
                    .with_initializer(burn::nn::Initializer::Zeros)
                    .init(device)
            } else {
                Conv2dConfig::new([w, self.out_channels], [1, 1]).init(device)
            },
            residual: self.residual,
            conditioning: self.conditioning,
            keep_below_black: self.keep_below_black,
        }
    }
}

impl<B: PgrfOps> SidUnet<B> {
    /// `x`: `(batch, 4 + extra, H, W)` packed, normalised and amplified
    /// raw, then the conditioning's planes ([`crate::condition`]). Returns
    /// `(batch, 4, H, W)`; a residual network adds the first four planes.
    pub fn forward(&self, x: Tensor<B, 4>) -> Tensor<B, 4> {
        let [n, _, h, w] = x.dims();
        let input = self
            .residual
            .then(|| x.clone().slice([0..n, 0..4, 0..h, 0..w]));
        let (ph, pw) = (pad_to(h), pad_to(w));
        let mode = if ph < h && pw < w {
            PadMode::Reflect
        } else {
            PadMode::Constant(0.0)
        };
        let mut x = if ph + pw > 0 {
            x.pad((0, pw, 0, ph), mode)
        } else {
            x
        };
        let mut skips = Vec::with_capacity(4);
        for (level, block) in self.down.iter().enumerate() {
            x = block.forward(x);
            if level < 4 {
                skips.push(x.clone());
                x = self.pool.forward(x);
            }
        }
        for (up, merge) in self.up.iter().zip(&self.merge) {
            let skip = skips.pop().expect("one skip per level");
            x = merge.forward(Tensor::cat(vec![ops::conv_transpose2d(up, x), skip], 1));
        }
        let out = ops::conv2d(&self.head, x);
        let c = out.dims()[1];
        let out = out.slice([0..n, 0..c, 0..h, 0..w]);
        match input {
            Some(i) => out + i,
            None => out,
        }
    }
}

impl<B: Backend> SidUnet<B> {
    /// How the network is told its input's noise level.
    pub fn conditioning(&self) -> Conditioning {
        self.conditioning
    }

    /// Whether the network reads values below black as recorded
    /// ([`SidUnetConfig::keep_below_black`]).
    pub fn keeps_below_black(&self) -> bool {
        self.keep_below_black
    }

    /// The layers [`SidUnet::forward`] runs on a `(batch, 4, h, w)` input, in
    /// order, at the sizes they run at (after the padding to a multiple of
    /// 16), read from this network's modules; see [`crate::layers`]. Max
    /// pooling, concatenation and the residual add are not listed.
    pub fn layers(&self, h: usize, w: usize) -> Vec<Layer> {
        let (mut h, mut w) = (h + pad_to(h), w + pad_to(w));
        let mut out = Vec::new();
        let levels = self.down.len();
        for (level, block) in self.down.iter().enumerate() {
            block.layers(h, w, &mut out);
            if level + 1 < levels {
                (h, w) = (h / 2, w / 2);
            }
        }
        for (up, merge) in self.up.iter().zip(&self.merge) {
            out.push(Layer::conv_transpose(up, h, w));
            (h, w) = (2 * h, 2 * w);
            merge.layers(h, w, &mut out);
        }
        out.push(Layer::conv(&self.head, h, w));
        out
    }
}

impl SidUnetConfig {
    /// Every convolution's channels at this configuration's widths, in the
    /// order `init` builds them: what starting a wider network from this one
    /// needs ([`super::widen`]).
    pub(super) fn channel_layout(&self) -> Vec<super::widen::Layout> {
        let w = self.width;
        let widths = [w, 2 * w, 4 * w, 8 * w, 16 * w];
        let conv = |name: String, input: Vec<usize>, out: usize| super::widen::Layout {
            name,
            transposed: false,
            out: vec![out],
            input,
        };
        let mut v = Vec::new();
        let mut cin = self.in_channels;
        for (level, &c) in widths.iter().enumerate() {
            v.push(conv(format!("down.{level}.first"), vec![cin], c));
            v.push(conv(format!("down.{level}.second"), vec![c], c));
            cin = c;
        }
        for (k, level) in (0..4).rev().enumerate() {
            let (hi, lo) = (widths[level + 1], widths[level]);
            v.push(super::widen::Layout {
                name: format!("up.{k}"),
                transposed: true,
                out: vec![lo],
                input: vec![hi],
            });
            // The merge reads the concatenation [upsampled, skip].
            v.push(conv(format!("merge.{k}.first"), vec![lo, lo], lo));
            v.push(conv(format!("merge.{k}.second"), vec![lo], lo));
        }
        v.push(conv("head".into(), vec![w], self.out_channels));
        v
    }
}

impl NetworkConfig for SidUnetConfig {
    fn method(&self) -> Method {
        Method::Spc
    }

    fn describe(&self) -> String {
        format!(
            "SPC denoiser (SID U-Net, width {}{}{}{})",
            self.width,
            if self.residual { ", residual" } else { "" },
            conditioning_words(self.conditioning),
            below_black_words(self.keep_below_black)
        )
    }

    fn check(&self) -> NnResult<()> {
        Ok(self.fault()?)
    }

    fn conditioning(&self) -> Conditioning {
        self.conditioning
    }

    fn keeps_below_black(&self) -> bool {
        self.keep_below_black
    }

    fn input_conv(&self) -> &'static str {
        "down.0.first.weight"
    }

    /// Exact: every convolution's weights and biases, counted from the widths.
    fn min_params(&self) -> f64 {
        let conv = |k: f64, a: f64, b: f64| k * k * a * b + b;
        let w = self.width as f64;
        let widths = [w, 2.0 * w, 4.0 * w, 8.0 * w, 16.0 * w];
        let mut total = conv(1.0, w, self.out_channels as f64);
        let mut a = self.in_channels as f64;
        for &ch in &widths {
            total += conv(3.0, a, ch) + conv(3.0, ch, ch);
            a = ch;
        }
        for level in 0..4 {
            let (hi, lo) = (widths[level + 1], widths[level]);
            total += conv(2.0, hi, lo) + conv(3.0, 2.0 * lo, lo) + conv(3.0, lo, lo);
        }
        total
    }

    /// Measured (peak resident memory of `pgrf enhance --json` at two tile
    /// sizes, the difference over the difference in pixels): width 32 took
    /// 305 MiB at 512^2 and 804 MiB at 1024^2, ~670 B/px, 5.2 floats per
    /// pixel per channel of width; rounded up by about a third.
    fn bytes_per_pixel(&self) -> f64 {
        7.0 * self.width as f64 * 4.0
    }

    fn attention_tokens(&self, _h: usize, _w: usize) -> usize {
        0
    }

    fn side_multiple(&self) -> usize {
        SIDE_MULTIPLE
    }

    /// The convolutional denoiser is limited by memory alone.
    fn tile_cap(&self, _trained_patch: Option<usize>) -> usize {
        super::network::MEMORY_TILE_CAP
    }

    fn sampled(&self) -> bool {
        false
    }

    fn extras(&self, _time_max: f32) -> Extras {
        Extras::None
    }

    fn residual(&self) -> bool {
        self.residual
    }
}

/// The tensors of a weight file in UNetSeeInDark's names (SID's, ELD's and
/// PMN's PyTorch code), for `pgrf export-weights`; the naming in words.
pub(crate) fn export_names(
    tensors: &BTreeMap<String, NamedTensor>,
) -> NnResult<(Vec<(String, &NamedTensor)>, &'static str)> {
    let mut v = Vec::new();
    for (t, p) in super::sid_names::pairs() {
        let x = tensors.get(&p).ok_or_else(|| NnError::MissingTensor {
            name: p.clone(),
            hint: "not a SID U-Net?",
        })?;
        v.push((t, x));
    }
    Ok((v, "UNetSeeInDark's names (conv1_1 .. conv10_1)"))
}

/// ", sigma-map conditioned" and the like for descriptions; nothing for an
/// unconditioned network (descriptions of older files stay as they were).
pub(super) fn conditioning_words(c: Conditioning) -> String {
    match c {
        Conditioning::None => String::new(),
        c => format!(", {} conditioned", c.name()),
    }
}

/// ", values below black kept" for descriptions; nothing for a network that
/// reads them clamped (descriptions of older files stay as they were).
pub(super) fn below_black_words(keep: bool) -> &'static str {
    if keep {
        ", values below black kept"
    } else {
        ""
    }
}

/// Padding that brings `side` up to a multiple of 16.
fn pad_to(side: usize) -> usize {
    (SIDE_MULTIPLE - side % SIDE_MULTIPLE) % SIDE_MULTIPLE
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::backend::Flex;

    type B = Flex;

    #[test]
    fn a_fresh_residual_network_is_the_identity() {
        use burn::tensor::Distribution;
        let device = Default::default();
        let net = SidUnetConfig::new()
            .with_width(4)
            .with_residual(true)
            .init::<B>(&device);
        let x = Tensor::<B, 4>::random([1, 4, 20, 36], Distribution::Uniform(0.0, 1.0), &device);
        let y = net.forward(x.clone());
        let d: f32 = (y - x).abs().max().into_scalar();
        assert_eq!(d, 0.0);
        // The plain network is not.
        let plain = SidUnetConfig::new().with_width(4).init::<B>(&device);
        let x = Tensor::<B, 4>::random([1, 4, 16, 16], Distribution::Uniform(0.0, 1.0), &device);
        let d: f32 = (plain.forward(x.clone()) - x).abs().max().into_scalar();
        assert!(d > 1e-3);
    }

    /// Parameters of the architecture, counted by hand in
    /// [`crate::arch::Architecture::min_params`] (exact for this network):
    /// a k x k conv from a to b channels has k*k*a*b weights and b biases.
    fn expected_params(w: usize, cin: usize, cout: usize) -> usize {
        let c = SidUnetConfig::new()
            .with_width(w)
            .with_in_channels(cin)
            .with_out_channels(cout);
        crate::arch::Architecture::SidUnet(c).min_params() as usize
    }

    #[test]
    fn parameter_count_matches_the_architecture() {
        let device = Default::default();
        let net = SidUnetConfig::new().init::<B>(&device);
        // w = 32, 4 -> 4 channels: 7,760,484 by the hand count.
        assert_eq!(expected_params(32, 4, 4), 7_760_484);
        assert_eq!(net.num_params(), expected_params(32, 4, 4));
        let small = SidUnetConfig::new().with_width(8).init::<B>(&device);
        assert_eq!(small.num_params(), expected_params(8, 4, 4));
    }

    #[test]
    fn any_size_in_same_size_out_and_deterministic() {
        let device = Default::default();
        let net = SidUnetConfig::new().with_width(4).init::<B>(&device);
        for (h, w) in [(32, 48), (36, 52), (10, 7)] {
            let x = Tensor::<B, 4>::random(
                [2, 4, h, w],
                burn::tensor::Distribution::Uniform(0.0, 1.0),
                &device,
            );
            let y = net.forward(x.clone());
            assert_eq!(y.dims(), [2, 4, h, w]);
            let y2 = net.forward(x);
            let d: f32 = (y - y2).abs().max().into_scalar();
            assert_eq!(d, 0.0);
        }
    }

    #[test]
    fn the_layer_list_covers_every_parameter_at_the_right_sizes() {
        let device = Default::default();
        for width in [32, 8] {
            let net = SidUnetConfig::new().with_width(width).init::<B>(&device);
            // 36 x 50 runs padded to 48 x 64.
            let layers = net.layers(36, 50);
            let params: usize = layers.iter().map(Layer::params).sum();
            assert_eq!(params, net.num_params());
            assert_eq!(
                layers
                    .iter()
                    .filter(|l| matches!(l, Layer::Conv { .. }))
                    .count(),
                19
            );
            assert_eq!(
                layers[0],
                Layer::Conv {
                    cin: 4,
                    cout: width,
                    kernel: 3,
                    stride: 1,
                    padding: 1,
                    h: 48,
                    w: 64
                }
            );
            // The bottom level runs at 1/16 of the padded size, the head at full size.
            assert!(layers.contains(&Layer::LeakyRelu {
                channels: 16 * width,
                h: 3,
                w: 4
            }));
            assert_eq!(
                *layers.last().unwrap(),
                Layer::Conv {
                    cin: width,
                    cout: 4,
                    kernel: 1,
                    stride: 1,
                    padding: 0,
                    h: 48,
                    w: 64
                }
            );
        }
    }

    #[test]
    fn padding_reaches_the_next_multiple_of_16() {
        assert_eq!(pad_to(16), 0);
        assert_eq!(pad_to(17), 15);
        assert_eq!(pad_to(1424), 0);
        assert_eq!(pad_to(2128), 0);
    }
}
