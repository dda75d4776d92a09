//! `pgrf synth`: a clean RAW in, a simulated low-light capture of the same
//! scene out (as a DNG with the input's size, CFA and levels): by default
//! the dark capture the camera would record (un-amplified, EXIF exposure
//! divided by the ratio), so that `pgrf enhance --ratio R` restores it;
//! `--brightened` writes it multiplied back by the ratio instead.

use crate::input::InputArgs;
use anyhow::{bail, Context, Result};
use clap::Args;
use pgrf_calib::Calibration;
use pgrf_noise::pair::{ExposureSpec, PairSpec, RatioSpec};
use pgrf_noise::profile::DarkCurrent;
use pgrf_noise::{CameraProfile, Components, DarkLaw, ModelKind};
use pgrf_raw::{
    pack_normalized, render_preview, unpack_normalized, write_dng, DngOptions, PreviewOptions,
};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Clean (long-exposure) RAW file or headerless dump.
    pub clean: PathBuf,
    /// Camera profile: a built-in name (sony-a7s2, nikon-d850, canon-eos70d,
    /// canon-eos700d, canon-eos5d4), darktable:"MAKER MODEL", dng:FILE.dng or a JSON file.
    #[arg(long)]
    pub profile: String,
    /// Exposure ratio (the capture is this many times darker). Default: drawn from U(100, 300) by the seed.
    #[arg(long)]
    pub ratio: Option<f32>,
    /// ISO of the simulated capture. Default: the file's ISO; if it has none,
    /// parameters are drawn from the profile's ELD distribution.
    #[arg(long)]
    pub iso: Option<u32>,
    /// Noise model: pg (Poisson-Gaussian), eld, pgrf.
    #[arg(long, default_value = "pgrf")]
    pub model: ModelKind,
    /// PGRF components: any of P (photon shot), G (read), H (row), Q (quantisation), F (fixed pattern), A (dark current).
    #[arg(long, default_value = "P,G,H,Q,F,A")]
    pub components: String,
    /// The "noD" ablation: global instead of per-pixel calibration.
    #[arg(long)]
    pub global: bool,
    /// ELD model with Gaussian instead of Tukey-lambda read noise.
    #[arg(long)]
    pub gaussian_read: bool,
    /// Exposure time of the simulated capture in seconds (drives dark current).
    /// Default: the file's exposure divided by the ratio, else drawn from 1/30..1 s.
    #[arg(long)]
    pub exposure_time: Option<f32>,
    /// Dark-current rate in electrons per sqrt(s) (sqrt law) or per s (linear
    /// law), replacing the profile's (the built-in profiles have no measured one).
    #[arg(long)]
    pub dark_rate: Option<f64>,
    /// Time law of the dark signal: sqrt (the paper's fit) or linear.
    #[arg(long, default_value = "sqrt")]
    pub dark_law: DarkLaw,
    /// Per-pixel calibration file (from `pgrf calibrate`) for the PGRF model:
    /// its maps, gain and row noise replace the profile's.
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// Apply a calibration of another camera or ISO anyway.
    #[arg(long)]
    pub force: bool,
    /// Random seed: same arguments and seed give byte-identical output.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output DNG.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write an sRGB preview of the result.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Exposure gain for the PNG preview [default: the ratio for the dark
    /// capture, so the preview shows the scene at the clean frame's
    /// brightness; 1 with --brightened].
    #[arg(long)]
    pub png_gain: Option<f32>,
    /// Write the capture brightened: multiplied back by the ratio and
    /// clipped to black..white, as a network is fed it (what `pgrf synth`
    /// wrote before). Without it the output is the dark capture the camera
    /// would record, for `pgrf enhance --ratio R`.
    #[arg(long)]
    pub brightened: bool,
    #[command(flatten)]
    pub input: InputArgs,
}

pub fn run(a: &SynthArgs) -> Result<()> {
    let mut outputs = vec![("-o", a.output.as_path())];
    if let Some(p) = &a.png {
        outputs.push(("--png", p.as_path()));
    }
    let mut inputs = vec![a.clean.as_path(), std::path::Path::new(&a.profile)];
    inputs.extend(a.calib.as_deref());
    crate::output::check_outputs(&outputs, &inputs)?;
    if let Some(g) = a.png_gain {
        if !(g.is_finite() && g > 0.0) {
            bail!("--png-gain must be a positive number, got {g}");
        }
    }
    let mut profile = CameraProfile::load(&a.profile)?;
    if let Some(rate) = a.dark_rate {
        if !(rate.is_finite() && rate >= 0.0) {
            bail!("--dark-rate must be >= 0 electrons, got {rate}");
        }
        profile.dark_current = Some(DarkCurrent {
            law: a.dark_law,
            rate,
        });
    }
    if let Some(r) = a.ratio {
        if !(r.is_finite() && r > 0.0) {
            bail!("--ratio must be a positive number, got {r}");
        }
    }
    if let Some(t) = a.exposure_time {
        if !(t.is_finite() && t >= 0.0) {
            bail!("--exposure-time must be >= 0 seconds, got {t}");
        }
    }
    let components = Components::parse(&a.components)?;
    let frame = a.input.open(&a.clean)?;
    let clean = pack_normalized(&frame, true)?;

    let only_iso = profile.only_iso();
    let mut spec = PairSpec::new(profile, a.model);
    spec.components = components;
    spec.global = a.global;
    spec.tukey = !a.gaussian_read;
    spec.iso = a.iso.or(only_iso).or(frame.iso);
    spec.ratio = match a.ratio {
        Some(r) => RatioSpec::Fixed(r),
        None => RatioSpec::default(),
    };
    // The ratio must be known to derive the exposure from the file's.
    let (ratio, _) = spec.conditions(a.seed)?;
    spec.ratio = RatioSpec::Fixed(ratio);
    spec.exposure = match (a.exposure_time, frame.exposure_s) {
        (Some(t), _) => ExposureSpec::Fixed(t),
        (None, Some(t)) => ExposureSpec::Fixed((t / ratio as f64) as f32),
        (None, None) => ExposureSpec::default(),
    };
    if let Some(path) = &a.calib {
        let cal = Calibration::load(path)?;
        cal.check_matches(&frame.make, &frame.model, spec.iso, a.force)
            .and_then(|()| cal.check_layout(&frame))
            .with_context(|| format!("{}", path.display()))?;
        let (ph, pw) = frame.packed_dims();
        if (cal.meta.height / 2, cal.meta.width / 2) != (ph, pw) {
            bail!(
                "{}: calibration is {}x{}, the clean frame {}x{}",
                path.display(),
                cal.meta.width,
                cal.meta.height,
                frame.width,
                frame.height
            );
        }
        cal.apply_to(&mut spec)
            .with_context(|| format!("--calib {}", path.display()))?;
    }
    let plane_rows = frame.cfa.offsets().map(|(r, _)| r);
    let pair = spec
        .synthesize(clean.view(), plane_rows, a.seed)
        .with_context(|| format!("{}", a.clean.display()))?;

    let noisy = if a.brightened {
        pair.noisy.mapv(|v| v.clamp(0.0, 1.0))
    } else {
        pgrf_noise::capture::recorded(&pair.noisy, pair.ratio)
    };
    let mut out = unpack_normalized(noisy.view(), &frame)?;
    if let Some(iso) = spec.iso {
        out.iso = Some(iso);
    }
    out.exposure_s = Some(pair.exposure_s as f64);
    // The NoiseProfile of the capture written: exact for the P-G model
    // (variance K x + sigma^2 in DN, normalised by the range; a brightened
    // frame's is the ratio's square times the dark one's at the dark
    // signal). The ELD and pgrf models add row noise, heavy tails and per-pixel
    // maps that one (S, O) pair cannot state, so their DNGs carry none rather
    // than a wrong one; nor does the clean frame's own tag survive.
    out.noise_profile = (a.model == ModelKind::PoissonGaussian && !a.brightened).then(|| {
        // The noise was drawn on the profile's scale and normalised by it.
        let range = spec.dn_range();
        let p = &pair.params;
        vec![[p.k / range, (p.sigma_gauss / range).powi(2)]]
    });
    write_dng(&out, &a.output, &DngOptions::default())?;
    let p = &pair.params;
    eprintln!(
        "wrote {} ({}): model {:?}{}, ratio {:.1}, exposure {:.4} s, {}, K {:.4} DN/e-, read {:.3} DN, row {:.3} DN, seed {}",
        a.output.display(),
        if a.brightened { "brightened by the ratio" } else { "dark capture" },
        a.model,
        if a.model == ModelKind::Pgrf { format!(" [{}{}]", components, if a.global { ", noD" } else { "" }) } else { String::new() },
        pair.ratio,
        pair.exposure_s,
        spec.iso.map(|i| format!("ISO {i}")).unwrap_or_else(|| "parameters drawn from the ELD distribution".into()),
        p.k,
        if a.model == ModelKind::Eld && !a.gaussian_read { p.sigma_tukey } else { p.sigma_gauss },
        p.sigma_row,
        a.seed
    );
    if let Some(png) = &a.png {
        let prev = render_preview(
            &out,
            &PreviewOptions {
                gain: a
                    .png_gain
                    .unwrap_or(if a.brightened { 1.0 } else { pair.ratio }),
                ..Default::default()
            },
        )?;
        prev.write_png(png, 8)?;
        eprintln!("wrote {}", png.display());
    }
    Ok(())
}
