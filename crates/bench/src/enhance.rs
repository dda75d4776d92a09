//! `pgrf-bench enhance`: what `pgrf enhance` costs on a whole frame, the
//! network part of it (`pgrf_nn::infer::restore_image`: start noise, tiles,
//! network evaluations, blend, clamp), with either network, fresh weights of
//! any configuration or a trained weight file.
//!
//! The input is a deterministic amplified "noisy" packed frame, cheap to
//! rebuild in numpy so that bench/enhance_torch.py runs PyTorch on the very
//! same values (a frame of H x W is the top-left crop of any larger one):
//!
//! ```text
//! clean[c, i, j] = f32(4 |(i + 2 j + 16 c) % 512 - 256| + (7 i + 3 j) % 41) / f32(1100)
//! u[c, i, j]     = (splitmix64(SEED + (c << 42) + (i << 21) + j) >> 40) / 2^24
//! input          = clamp(0.8 * clean + (u - 0.5) * 0.3, 0, 1)      (f32 operations)
//! ```
//!
//! `splitmix64` is one step of SplitMix64, `pgrf_core::seed::mix64`.
//!
//! Every network is told the frame's own noise level, [`FRAME_NOISE`]: a
//! noise-conditioned one (both built-ins) refuses to run without one, as in
//! `pgrf enhance`, and an unconditioned one ignores it; the value does not
//! change the amount of arithmetic.
//!
//! The default frame is a Sony A7S2 raw (4256 x 2848 mosaic, 12.1 MP) packed:
//! 4 x 1424 x 2128. The default tile is the one `pgrf enhance` would choose
//! on this machine (`pgrf_nn::infer::memory::auto_tile`).

use anyhow::{ensure, Context, Result};
use burn::module::Module;
use clap::{Args, ValueEnum};
use pgrf_core::parse::ParseError;
use pgrf_core::seed::mix64;
use pgrf_core::stats::median;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::condition::NoiseLevel;
use pgrf_nn::flow::SamplerKind;
use pgrf_nn::infer::image::frame_plan;
use pgrf_nn::infer::memory::{attention_tokens, auto_tile, fixed_bytes, windowed_tile_bytes};
use pgrf_nn::infer::restorer::UNSEARCHED_T2;
use pgrf_nn::infer::DEFAULT_OVERLAP;
use pgrf_nn::infer::{restore_image, ImageOptions, Restore, Restorer, SamplerChoice};
use pgrf_nn::weights::{NoiseSource, WeightMeta};
use pgrf_nn::Architecture;
use pgrf_nn::{SidUnetConfig, Sr3Config};
use pgrf_raw::ndarray::Array3;
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// Seed of the benchmark frame's noise (see the module docs).
pub const SEED: u64 = 11;

/// The benchmark frame's noise level, given to every network, as a
/// capture's: Var = 0.01 x + 0.0035, which is 0.0075 (the variance of the
/// frame's uniform noise, 0.3^2 / 12) at its mean signal, 0.8 x 0.48 ~ 0.4,
/// with a shot-noise part as every capture has (the restorer needs one).
pub const FRAME_NOISE: NoiseLevel = NoiseLevel {
    gain: 0.01,
    floor: 0.0035,
};

/// The network `--net` picks when no weight file is given.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum NetKind {
    /// SPC: the SID U-Net, one network evaluation.
    Unet,
    /// PGRF: the SR3 velocity field through the chosen sampler.
    Sr3,
}

/// A packed frame size, `HxW` or `N` (square).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameSize {
    /// Packed rows.
    pub h: usize,
    /// Packed columns.
    pub w: usize,
}

impl std::str::FromStr for FrameSize {
    type Err = ParseError;
    fn from_str(s: &str) -> Result<Self, ParseError> {
        let parse = |v: &str| {
            v.trim()
                .parse::<usize>()
                .ok()
                .filter(|n| *n > 0)
                .ok_or_else(|| {
                    ParseError::malformed(
                        s,
                        format!("'{s}': expected HxW or N in packed pixels, e.g. 1424x2128"),
                    )
                })
        };
        match s.split_once(['x', 'X']) {
            Some((h, w)) => Ok(FrameSize {
                h: parse(h)?,
                w: parse(w)?,
            }),
            None => {
                let n = parse(s)?;
                Ok(FrameSize { h: n, w: n })
            }
        }
    }
}

/// Flags of `pgrf-bench enhance`.
#[derive(Args, Debug)]
pub struct EnhanceArgs {
    /// Which network: the SPC denoiser (SID U-Net) or the PGRF flow model (SR3).
    #[arg(long, value_enum, default_value = "unet")]
    pub net: NetKind,
    /// SID U-Net: width of the first level.
    #[arg(long, default_value_t = 32)]
    pub width: usize,
    /// SR3: channels of the first level.
    #[arg(long, default_value_t = 64)]
    pub inner_channels: usize,
    /// SR3: channel multiplier per level, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,8")]
    pub channel_mults: Vec<usize>,
    /// SR3: levels (0 = full resolution) with self-attention, comma-separated,
    /// or "none".
    #[arg(long, default_value = "3")]
    pub attn_levels: String,
    /// A trained weight file instead of fresh weights (its architecture wins
    /// over --net and the configuration flags).
    #[arg(long, short = 'm')]
    pub model: Option<PathBuf>,
    /// Packed frame, HxW or N (square); the default is a 12.1 MP A7S2 frame.
    /// Smaller frames are the top-left crop of the same image.
    #[arg(long, default_value = "1424x2128")]
    pub frame: FrameSize,
    /// Tile side in packed pixels (default: what `pgrf enhance` chooses here).
    #[arg(long)]
    pub tile: Option<usize>,
    /// Minimum overlap of neighbouring tiles, packed pixels.
    #[arg(long, default_value_t = DEFAULT_OVERLAP)]
    pub overlap: usize,
    /// Flow model sampler: two-stage (2 evaluations), one-step, or euler:N.
    #[arg(long, default_value = "two-stage")]
    pub sampler: SamplerKind,
    /// Second time of the two-stage sampler (default: the file's, else 0.5).
    #[arg(long)]
    pub t2: Option<f32>,
    /// Timed runs (the median is reported).
    #[arg(long, default_value_t = 1)]
    pub iters: usize,
    /// Untimed runs first (a full-frame run takes minutes; the first run pays
    /// page faults for the buffers and the thread pool's start).
    #[arg(long, default_value_t = 0)]
    pub warmup: usize,
    /// cpu, or cuda (needs a build with `--features cuda`).
    #[arg(long, default_value = "cpu")]
    pub device: DeviceKind,
    /// Print one JSON line instead of text.
    #[arg(long)]
    pub json: bool,
    /// Print the plan (tile, tiles, memory estimates, attention size) and
    /// stop without running the network.
    #[arg(long)]
    pub dry_run: bool,
}

/// The JSON line bench/enhance.sh reads.
#[derive(Serialize)]
struct Report {
    burn: &'static str,
    device: String,
    threads: usize,
    net: &'static str,
    model: String,
    params: usize,
    weights: String,
    /// Packed frame `[4, H, W]` and its mosaic size in megapixels.
    frame: [usize; 3],
    megapixels: f64,
    tile: usize,
    /// Tile shape actually run (an axis that fits is not cut).
    tile_hw: [usize; 2],
    tiles: usize,
    overlap: usize,
    auto_tile: bool,
    sampler: String,
    nfe: usize,
    iters: usize,
    warmup: usize,
    /// Wall time of `restore_image` on the frame, seconds.
    seconds: f64,
    seconds_min: f64,
    /// One network evaluation over the whole frame (all tiles), seconds.
    seconds_per_eval: f64,
    /// One network evaluation of one tile, seconds.
    seconds_per_tile_eval: f64,
    /// Pixels the network evaluates per evaluation (tiles x tile area) over
    /// the frame's pixels: the tiling's overlap overhead.
    tiled_pixel_factor: f64,
    /// Building the input frame (not timed above), seconds.
    input_seconds: f64,
    /// `pgrf_nn::infer::memory`'s estimate of the peak for one tile plus the
    /// frame buffers and weights, MiB (what the default tile is chosen by).
    estimated_peak_mib: f64,
    /// SR3: tokens of the largest self-attention (at the highest-resolution
    /// attention level of one tile) and the size of one of its score
    /// matrices (tokens^2 floats), MiB; 0 for the U-Net.
    attention_tokens: usize,
    attention_scores_mib: f64,
    /// Peak resident memory of this process (VmHWM), MiB.
    peak_rss_mib: Option<f64>,
    /// Mean of the restored frame (a checksum that the work was done).
    output_mean: f64,
}

/// The benchmark's amplified noisy packed frame `(4, h, w)`; see the module docs.
pub fn frame(h: usize, w: usize) -> Array3<f32> {
    let mut a = Array3::<f32>::zeros((4, h, w));
    a.as_slice_mut()
        .expect("standard layout")
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(row, out)| {
            let (c, i) = (row / h, row % h);
            for (j, v) in out.iter_mut().enumerate() {
                let tri = ((i + 2 * j + 16 * c) % 512).abs_diff(256);
                let clean = (4 * tri + (7 * i + 3 * j) % 41) as f32 / 1100.0;
                let key = ((c as u64) << 42) + ((i as u64) << 21) + j as u64;
                let u = (mix64(SEED.wrapping_add(key)) >> 40) as f32 / 16_777_216.0;
                *v = (0.8 * clean + (u - 0.5) * 0.3).clamp(0.0, 1.0);
            }
        });
    a
}

fn parse_levels(s: &str) -> Result<Vec<usize>> {
    let s = s.trim();
    if s.is_empty() || s.eq_ignore_ascii_case("none") {
        return Ok(Vec::new());
    }
    s.split(',')
        .map(|v| {
            v.trim().parse::<usize>().with_context(|| {
                format!("--attn-levels '{s}': expected levels like 3 or 2,3, or none")
            })
        })
        .collect()
}

/// The network to time and its parameter count, on backend `B`.
/// A restorer, its parameter count and where its weights came from.
type Built = (Box<dyn Restore>, usize, String);

fn build<B: pgrf_nn::ops::PgrfOps>(a: &EnhanceArgs, device: B::Device) -> Result<Built> {
    let choice = SamplerChoice {
        kind: a.sampler,
        t2: a.t2,
        samples: 1,
    };
    let (net, meta, weights) = match &a.model {
        Some(path) => {
            let (net, meta) = pgrf_nn::model::load::<B>(path, &device)
                .with_context(|| format!("--model {}", path.display()))?;
            (net, meta, path.display().to_string())
        }
        None => {
            let arch = match a.net {
                NetKind::Unet => Architecture::SidUnet(SidUnetConfig::new().with_width(a.width)),
                NetKind::Sr3 => Architecture::Sr3(
                    Sr3Config::new()
                        .with_inner_channels(a.inner_channels)
                        .with_channel_mults(a.channel_mults.clone())
                        .with_attn_levels(parse_levels(&a.attn_levels)?),
                ),
            };
            let net = arch.init::<B>(&device)?;
            // Fresh weights learned no noise: the record's default source.
            let meta = WeightMeta::new(arch, NoiseSource::default());
            (net, meta, "fresh (random initialisation)".to_string())
        }
    };
    let params = net.num_params();
    let t2 = choice.t2.or(meta.t2).unwrap_or(UNSEARCHED_T2);
    let r = Restorer::<B>::new(net, meta, choice, t2, device)?;
    Ok((Box::new(r), params, weights))
}

/// Build the network, the frame and the tiling; print the plan (`--dry-run`)
/// or time `restore_image` on the frame.
pub fn run(a: &EnhanceArgs) -> Result<()> {
    ensure!(a.iters > 0, "--iters must be at least 1");
    if let Some(t) = a.t2 {
        ensure!((0.0..=1.0).contains(&t), "--t2 must be in [0, 1], got {t}");
    }
    struct Build<'a>(&'a EnhanceArgs);
    impl pgrf_nn::backend::OnBackend for Build<'_> {
        type Output = Built;
        fn run<B: pgrf_nn::ops::PgrfOps>(self, device: B::Device) -> pgrf_nn::Result<Built> {
            build::<B>(self.0, device).map_err(|e| pgrf_nn::NnError::Invalid(format!("{e:#}")))
        }
    }
    let (r, params, weights) = pgrf_nn::backend::on_device(a.device, Build(a))?;
    let r = r.as_ref();
    let t0 = Instant::now();
    let input = frame(a.frame.h, a.frame.w);
    let input_seconds = t0.elapsed().as_secs_f64();
    let plan = Plan::of(a, r)?;
    if a.dry_run {
        println!("{}", plan.json(r, params));
        return Ok(());
    }
    if !a.json {
        eprintln!(
            "{} ({} parameters, {weights} weights); frame 4 x {} x {}; {} tile{} of {} x {}; {}, {} evaluation{}; {} threads",
            r.meta().arch.describe(),
            params,
            plan.ph,
            plan.pw,
            plan.tiles,
            if plan.tiles == 1 { "" } else { "s" },
            plan.th,
            plan.tw,
            plan.sampler,
            plan.nfe,
            if plan.nfe == 1 { "" } else { "s" },
            rayon::current_num_threads(),
        );
    }
    let (mut times, output_mean) = time_runs(a, r, &input, &plan.opts)?;
    let seconds_min = times.iter().copied().fold(f64::MAX, f64::min);
    let seconds = median(&mut times);
    let report = plan.report(
        a,
        r,
        (params, weights),
        (seconds, seconds_min),
        input_seconds,
        output_mean,
    );
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_summary(&report);
    }
    Ok(())
}

/// The frame's tiling and what it costs, before anything runs.
struct Plan {
    auto_tile: bool,
    ph: usize,
    pw: usize,
    opts: ImageOptions,
    tiles: usize,
    th: usize,
    tw: usize,
    sampler: String,
    nfe: usize,
    estimated_peak_mib: f64,
    attention_tokens: usize,
    attention_scores_mib: f64,
}

/// Bytes in MiB.
fn mib(b: f64) -> f64 {
    b / (1 << 20) as f64
}

impl Plan {
    /// `a`'s frame tiled for `r` (`--tile`, else the automatic tile).
    fn of(a: &EnhanceArgs, r: &dyn Restore) -> Result<Plan> {
        let (ph, pw) = (a.frame.h, a.frame.w);
        let tile = a.tile.unwrap_or_else(|| auto_tile(a.device, r, ph, pw));
        let opts = ImageOptions {
            tile,
            overlap: a.overlap,
            seed: 0,
            noise: Some(FRAME_NOISE),
        };
        let plan = frame_plan(r, ph, pw, &opts)?;
        let (th, tw) = (plan.rows.len, plan.cols.len);
        let attention_tokens = attention_tokens(&r.meta().arch, th, tw);
        Ok(Plan {
            auto_tile: a.tile.is_none(),
            ph,
            pw,
            tiles: plan.count(),
            th,
            tw,
            sampler: match r.sampler() {
                None => "one pass".to_string(),
                Some(s) => s.to_string(),
            },
            nfe: r.nfe(),
            estimated_peak_mib: mib(windowed_tile_bytes(&r.meta().arch, th, tw, r.window())
                + fixed_bytes(r, ph, pw) as f64),
            attention_tokens,
            attention_scores_mib: mib(4.0 * (attention_tokens as f64).powi(2)),
            opts,
        })
    }

    /// What `--dry-run` prints.
    fn json(&self, r: &dyn Restore, params: usize) -> serde_json::Value {
        serde_json::json!({
            "model": r.meta().arch.describe(),
            "params": params,
            "frame": [4, self.ph, self.pw],
            "tile": self.opts.tile,
            "auto_tile": self.auto_tile,
            "tile_hw": [self.th, self.tw],
            "tiles": self.tiles,
            "nfe": self.nfe,
            "estimated_peak_mib": self.estimated_peak_mib,
            "available_mib": pgrf_core::mem::available_memory().map(|b| mib(b as f64)),
            "attention_tokens": self.attention_tokens,
            "attention_scores_mib": self.attention_scores_mib,
        })
    }

    /// The timed run's record: `model` (parameters, weights' origin),
    /// `timing` (median and fastest seconds).
    fn report(
        &self,
        a: &EnhanceArgs,
        r: &dyn Restore,
        (params, weights): (usize, String),
        (seconds, seconds_min): (f64, f64),
        input_seconds: f64,
        output_mean: f64,
    ) -> Report {
        let (th, tw, ph, pw, nfe, tiles) =
            (self.th, self.tw, self.ph, self.pw, self.nfe, self.tiles);
        Report {
            burn: "0.21.0",
            // backend::describe counts the machine's cores, not rayon's pool.
            device: match a.device {
                DeviceKind::Cpu => "Flex (CPU)".to_string(),
                DeviceKind::Cuda => pgrf_nn::backend::describe(a.device, Default::default()),
            },
            threads: rayon::current_num_threads(),
            net: match r.meta().arch {
                Architecture::SidUnet(_) => "unet",
                Architecture::Sr3(_) => "sr3",
                Architecture::Sr3Prior(_) => "sr3-prior",
            },
            model: r.meta().arch.describe(),
            params,
            weights,
            frame: [4, ph, pw],
            megapixels: (4 * ph * pw) as f64 / 1e6,
            tile: self.opts.tile,
            tile_hw: [th, tw],
            tiles,
            overlap: a.overlap,
            auto_tile: self.auto_tile,
            sampler: self.sampler.clone(),
            nfe,
            iters: a.iters,
            warmup: a.warmup,
            seconds,
            seconds_min,
            seconds_per_eval: seconds / nfe as f64,
            seconds_per_tile_eval: seconds / (nfe * tiles) as f64,
            tiled_pixel_factor: (tiles * th * tw) as f64 / (ph * pw) as f64,
            input_seconds,
            estimated_peak_mib: self.estimated_peak_mib,
            attention_tokens: self.attention_tokens,
            attention_scores_mib: self.attention_scores_mib,
            peak_rss_mib: pgrf_core::mem::peak_rss_mib(),
            output_mean,
        }
    }
}

/// `--warmup` untimed and `--iters` timed restorations of `input`: the
/// timed seconds, and the last output's mean (a check that work was done).
fn time_runs(
    a: &EnhanceArgs,
    r: &dyn Restore,
    input: &Array3<f32>,
    opts: &ImageOptions,
) -> Result<(Vec<f64>, f64)> {
    let mut times = Vec::with_capacity(a.iters);
    let mut output_mean = f64::NAN;
    for i in 0..a.warmup + a.iters {
        let t = Instant::now();
        let out = restore_image(r, input.view(), opts, &pgrf_core::NoProgress)?;
        let s = t.elapsed().as_secs_f64();
        output_mean = out.iter().map(|&v| v as f64).sum::<f64>() / out.len() as f64;
        let timed = i >= a.warmup;
        if timed {
            times.push(s);
        }
        if !a.json {
            eprintln!(
                "  run {}/{}{}: {s:.2} s",
                i + 1,
                a.warmup + a.iters,
                if timed { "" } else { " (warm-up)" }
            );
        }
    }
    Ok((times, output_mean))
}

/// The timed run on one line (without `--json`).
fn print_summary(report: &Report) {
    let [th, tw] = report.tile_hw;
    println!(
        "{:.2} s/image (median of {}, min {:.2} s), {} NFE: {:.2} s per evaluation of the frame, {:.3} s per tile evaluation; {} tiles of {}x{} ({:.2}x the frame's pixels); peak {} MiB",
        report.seconds,
        report.iters,
        report.seconds_min,
        report.nfe,
        report.seconds_per_eval,
        report.seconds_per_tile_eval,
        report.tiles,
        th,
        tw,
        report.tiled_pixel_factor,
        report
            .peak_rss_mib
            .map_or("?".to_string(), |m| format!("{m:.0}")),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_sizes_parse() {
        assert_eq!(
            "1424x2128".parse::<FrameSize>(),
            Ok(FrameSize { h: 1424, w: 2128 })
        );
        assert_eq!("512".parse::<FrameSize>(), Ok(FrameSize { h: 512, w: 512 }));
        assert!("0x5".parse::<FrameSize>().is_err());
        assert!("ax5".parse::<FrameSize>().is_err());
    }

    #[test]
    fn smaller_frames_are_crops_of_larger_ones() {
        let big = frame(40, 70);
        let small = frame(16, 24);
        assert_eq!(
            small,
            big.slice(pgrf_raw::ndarray::s![.., ..16, ..24]).to_owned()
        );
        assert!(big.iter().all(|v| (0.0..=1.0).contains(v)));
        // The value bench/enhance_torch.py's numpy `frame(2, 3)[1, 1, 2]` gives.
        assert_eq!(frame(2, 3)[[1, 1, 2]] as f64, 0.6646702885627747);
        assert_eq!(parse_levels("none").unwrap(), Vec::<usize>::new());
        assert_eq!(parse_levels("2,3").unwrap(), vec![2, 3]);
    }
}
