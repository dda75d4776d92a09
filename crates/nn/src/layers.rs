//! The layers a network runs, in the order its `forward` runs them, with the
//! shapes they run at.
//!
//! [`crate::SidUnet::layers`] and [`crate::Sr3Unet::layers`] read every
//! channel count, kernel, stride and padding from the built modules, so the
//! architecture stays defined once (in each config's `init`); only the walk
//! over the spatial sizes mirrors `forward`, next to it in the same file.
//! `pgrf-bench train --breakdown` times each listed layer on its own at its
//! shape to attribute a training step to the layer kinds; the unit tests
//! check that the parameters of the listed layers add up to the network's.
//!
//! Listed: convolutions, transposed convolutions, GroupNorm, activations,
//! the self-attention cores and the fully connected layers. Not listed
//! (they carry no parameters and are cheap): padding, pooling,
//! concatenation, interpolation, slicing, adds and the time embedding's
//! sines and cosines.

use burn::nn::conv::{Conv2d, ConvTranspose2d};
use burn::nn::{GroupNorm, Linear, PaddingConfig2d};
use burn::tensor::backend::Backend;

/// One layer at the shape it runs at, for one batch item: `h` x `w` is the
/// spatial size of the layer's input, in pixels of the packed image (or of
/// the level the layer runs at); channel counts are per batch item.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Layer {
    /// 2-D convolution from `cin` to `cout` channels, `kernel` x `kernel`,
    /// `stride`, `padding` zeros on every side; with a bias.
    Conv {
        /// Input channels.
        cin: usize,
        /// Output channels.
        cout: usize,
        /// Side of the square kernel.
        kernel: usize,
        /// Stride along both axes.
        stride: usize,
        /// Zeros added on each of the four sides.
        padding: usize,
        /// Input height.
        h: usize,
        /// Input width.
        w: usize,
    },
    /// Transposed convolution from `cin` to `cout` channels, `kernel` x
    /// `kernel`, `stride`, no padding; with a bias.
    ConvTranspose {
        /// Input channels.
        cin: usize,
        /// Output channels.
        cout: usize,
        /// Side of the square kernel.
        kernel: usize,
        /// Stride along both axes (the upsampling factor).
        stride: usize,
        /// Input height.
        h: usize,
        /// Input width.
        w: usize,
    },
    /// GroupNorm of `channels` channels in `groups` groups, with its affine.
    GroupNorm {
        /// Channels normalised.
        channels: usize,
        /// Groups the channels are split into.
        groups: usize,
        /// Input height.
        h: usize,
        /// Input width.
        w: usize,
    },
    /// LeakyReLU (the SID U-Net's activation).
    LeakyRelu {
        /// Channels of the feature map.
        channels: usize,
        /// Height of the feature map.
        h: usize,
        /// Width of the feature map.
        w: usize,
    },
    /// SiLU (SR3's activation; `h` = `w` = 1 for the time MLP's vector).
    Silu {
        /// Channels of the feature map (features of the time MLP's vector).
        channels: usize,
        /// Height of the feature map.
        h: usize,
        /// Width of the feature map.
        w: usize,
    },
    /// The single-head self-attention core [`crate::arch::sr3::attention_core`]:
    /// from the query/key/value projection `(3 channels, h * w)` to the
    /// attended values `(channels, h * w)`. The 1x1 convolutions around it
    /// and its GroupNorm are listed as layers of their own.
    Attention {
        /// Channels of the attended feature map (queries, keys and values
        /// have as many each).
        channels: usize,
        /// Height of the feature map (`h * w` tokens).
        h: usize,
        /// Width of the feature map.
        w: usize,
    },
    /// Fully connected layer from `d_in` to `d_out` features on one vector
    /// per batch item (SR3's time MLP and per-block embedding projections);
    /// with a bias.
    Linear {
        /// Input features.
        d_in: usize,
        /// Output features.
        d_out: usize,
    },
}

impl Layer {
    /// Learnable parameters of the layer (weights, biases, GroupNorm's
    /// scale and shift). Only the unit tests count them.
    #[cfg(test)]
    pub(crate) fn params(&self) -> usize {
        match *self {
            Layer::Conv {
                cin, cout, kernel, ..
            }
            | Layer::ConvTranspose {
                cin, cout, kernel, ..
            } => kernel * kernel * cin * cout + cout,
            Layer::GroupNorm { channels, .. } => 2 * channels,
            Layer::Linear { d_in, d_out } => d_in * d_out + d_out,
            Layer::LeakyRelu { .. } | Layer::Silu { .. } | Layer::Attention { .. } => 0,
        }
    }

    /// `m` (a square-kernel convolution) on an `h` x `w` input.
    pub(crate) fn conv<B: Backend>(m: &Conv2d<B>, h: usize, w: usize) -> Self {
        let [cout, cin_per_group, kernel, _] = m.weight.dims();
        let padding = match m.padding {
            PaddingConfig2d::Valid => 0,
            PaddingConfig2d::Same => (kernel - 1) / 2,
            PaddingConfig2d::Explicit(top, ..) => top,
        };
        Layer::Conv {
            cin: cin_per_group * m.groups,
            cout,
            kernel,
            stride: m.stride[0],
            padding,
            h,
            w,
        }
    }

    /// `m` (a square-kernel transposed convolution) on an `h` x `w` input.
    pub(crate) fn conv_transpose<B: Backend>(m: &ConvTranspose2d<B>, h: usize, w: usize) -> Self {
        let [cin, _, kernel, _] = m.weight.dims();
        Layer::ConvTranspose {
            cin,
            cout: m.channels[1],
            kernel,
            stride: m.stride[0],
            h,
            w,
        }
    }

    /// `m` on an `h` x `w` input.
    pub(crate) fn group_norm<B: Backend>(m: &GroupNorm<B>, h: usize, w: usize) -> Self {
        Layer::GroupNorm {
            channels: m.num_channels,
            groups: m.num_groups,
            h,
            w,
        }
    }

    /// `m` (stored in burn's default row layout, `[d_in, d_out]`).
    pub(crate) fn linear<B: Backend>(m: &Linear<B>) -> Self {
        let [d_in, d_out] = m.weight.dims();
        Layer::Linear { d_in, d_out }
    }

    /// Output channels of a layer that produces a feature map (input
    /// channels for the shape-preserving ones), None for `Linear`.
    pub(crate) fn out_channels(&self) -> Option<usize> {
        match *self {
            Layer::Conv { cout, .. } | Layer::ConvTranspose { cout, .. } => Some(cout),
            Layer::GroupNorm { channels, .. }
            | Layer::LeakyRelu { channels, .. }
            | Layer::Silu { channels, .. }
            | Layer::Attention { channels, .. } => Some(channels),
            Layer::Linear { .. } => None,
        }
    }
}
