//! `pgrf synth`'s recipe: a clean RAW frame in, a simulated low-light
//! capture of the same scene out, with the input's size, CFA and levels:
//! by default the dark capture the camera would record (un-amplified, the
//! exposure divided by the ratio), so that `pgrf enhance --ratio R` restores
//! it; brightened, multiplied back by the ratio and clipped, as a network is
//! fed it. The camera's profile sets the noise, a per-pixel calibration file
//! (checked against the frame) replaces its maps. Here because it needs the
//! calibration; the caller reads the frame and writes the result.

use crate::mix::{CalibrationFile, FrameCheck, MixError};
use pgrf_noise::pair::{ExposureSpec, PairSpec, RatioSpec};
use pgrf_noise::profile::DarkCurrent;
use pgrf_noise::{CameraProfile, Components, DarkLaw, ModelKind, NoiseError};
use pgrf_raw::{pack_normalized, unpack_normalized, RawError, RawFrame};
use std::path::{Path, PathBuf};

/// How to simulate the capture (`pgrf synth`'s flags).
#[derive(Clone, Debug)]
pub struct SynthConfig {
    /// Camera profile: built-in name, darktable:"MAKER MODEL", dng:FILE or
    /// a JSON file.
    pub profile: String,
    /// Exposure ratio (None: drawn from U(100, 300) by the seed).
    pub ratio: Option<f32>,
    /// ISO (None: the profile's only ISO, else the frame's, else
    /// parameters drawn from the profile's ELD distribution).
    pub iso: Option<u32>,
    /// Noise model.
    pub model: ModelKind,
    /// The PGRF model's components, e.g. "P,G,H,Q,F,A".
    pub components: String,
    /// The "noD" ablation: global instead of per-pixel calibration.
    pub global: bool,
    /// ELD model with Gaussian instead of Tukey-lambda read noise.
    pub gaussian_read: bool,
    /// Exposure time of the capture, seconds (None: the frame's divided by
    /// the ratio, else drawn).
    pub exposure_time: Option<f32>,
    /// Dark-current rate replacing the profile's, electrons per sqrt(s) or s.
    pub dark_rate: Option<f64>,
    /// Time law of the dark signal.
    pub dark_law: DarkLaw,
    /// Per-pixel calibration file, replacing the profile's maps, gain and
    /// row noise.
    pub calib: Option<PathBuf>,
    /// Apply a calibration of another camera or ISO anyway.
    pub force: bool,
    /// Seed: the same frame, settings and seed give the same capture.
    pub seed: u64,
    /// Write the capture brightened by the ratio instead of dark.
    pub brightened: bool,
    /// darktable's noiseprofiles.json for a `darktable:` profile (None:
    /// darktable's install is searched).
    pub darktable: Option<PathBuf>,
    /// Masked (optical-black) columns to simulate left of the frame, as a
    /// camera's readout has them (0: none; even): dark pixels with the
    /// capture's offset and read and row noise, which `pgrf enhance` reads
    /// the black level from ([`pgrf_raw::masked`]).
    pub masked_columns: usize,
    /// Draw the read, row and quantisation noise from the calibration's
    /// noise bank (its bias frames' residuals, [`pgrf_noise::bank`])
    /// instead of the parametric model (needs `calib`, PGRF model).
    pub noise_bank: bool,
}

/// Most masked columns `--masked-columns` takes (Canon's readouts have
/// about 150).
pub const MAX_MASKED_COLUMNS: usize = 1024;

/// The simulated capture and what it was made with.
#[derive(Clone, Debug)]
pub struct Synthesized {
    /// The capture as a frame of the input's size, CFA and levels, its ISO,
    /// exposure and (P-G model, dark) NoiseProfile set.
    pub frame: RawFrame,
    /// What it was made with.
    pub info: CaptureInfo,
}

impl Synthesized {
    /// What was made, on one line (`pgrf synth` prints it after the
    /// output's name): the form in parentheses, then the model, conditions, the noise drawn, the
    /// seed, and the masked columns' level when there are any.
    pub fn summary(&self, c: &SynthConfig) -> String {
        let i = &self.info;
        let components = match c.model {
            ModelKind::Pgrf => {
                format!(" [{}{}]", i.components, if c.global { ", noD" } else { "" })
            }
            _ => String::new(),
        };
        let conditions = i
            .iso
            .map(|v| format!("ISO {v}"))
            .unwrap_or_else(|| "parameters drawn from the ELD distribution".into());
        let masked = match &self.frame.masked {
            Some(m) => format!(
                "; {} masked columns, black {} DN (metadata {})",
                m.strip.as_ref().map_or(0, |s| s.columns),
                pgrf_raw::masked::levels_text(m.level),
                pgrf_raw::masked::levels_text(self.frame.black)
            ),
            None => String::new(),
        };
        let noise = match c.noise_bank {
            true => {
                "read, row and quantisation noise from the calibration's noise bank".to_string()
            }
            false => format!("read {:.3} DN, row {:.3} DN", i.read_dn, i.row_dn),
        };
        format!(
            "({}): model {:?}{components}, ratio {:.1}, exposure {:.4} s, {conditions}, K {:.4} DN/e-, {noise}, seed {}{masked}",
            if c.brightened { "brightened by the ratio" } else { "dark capture" },
            c.model,
            i.ratio,
            i.exposure_s,
            i.k,
            c.seed
        )
    }
}

/// What a simulated capture was made with.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureInfo {
    /// The exposure ratio used.
    pub ratio: f32,
    /// The capture's exposure time, seconds.
    pub exposure_s: f32,
    /// The ISO, when one was set (else parameters were drawn).
    pub iso: Option<u32>,
    /// The terms the model drew ([`ModelKind::components`]: the PGRF
    /// model's are those asked for).
    pub components: Components,
    /// K, the system gain, DN per electron.
    pub k: f64,
    /// The read noise's scale in DN (Tukey-lambda's for ELD's default).
    pub read_dn: f64,
    /// The row noise's sigma in DN; 0 when the model drew none.
    pub row_dn: f64,
}

/// Why no capture could be made.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// A setting out of its range; the message names the flag and value.
    #[error("{message}")]
    BadSetting {
        /// The flag, e.g. `--ratio`.
        flag: &'static str,
        /// The whole message.
        message: String,
    },
    /// The profile, the components or the noise model refused.
    #[error(transparent)]
    Noise(#[from] NoiseError),
    /// The frame could not be packed or unpacked.
    #[error(transparent)]
    Raw(#[from] RawError),
    /// The calibration file could not be used.
    #[error(transparent)]
    Calibration(#[from] MixError),
    /// Synthesis itself failed on the frame `path`.
    #[error("{}: {cause}", path.display())]
    Synthesis {
        /// The clean frame's file.
        path: PathBuf,
        /// Why (in the message only: one-line reports print the chain of
        /// sources, which would say it twice).
        cause: NoiseError,
    },
}

fn bad(flag: &'static str, message: String) -> SynthError {
    SynthError::BadSetting { flag, message }
}

/// Refuse numeric settings no frame can make right (a negative dark rate,
/// a ratio outside [`pgrf_noise::pair::RATIO_RANGE`], a negative exposure):
/// before any work, the frame not yet read.
pub fn check(c: &SynthConfig) -> Result<(), SynthError> {
    if let Some(rate) = c.dark_rate {
        if !(rate.is_finite() && rate >= 0.0) {
            return Err(bad(
                "--dark-rate",
                format!("--dark-rate must be >= 0 electrons, got {rate}"),
            ));
        }
    }
    if let Some(r) = c.ratio {
        pgrf_noise::pair::ratio_in_range("--ratio", r)
            .map_err(|e| bad("--ratio", e.to_string()))?;
    }
    if !c.masked_columns.is_multiple_of(2) || c.masked_columns > MAX_MASKED_COLUMNS {
        return Err(bad(
            "--masked-columns",
            format!(
                "--masked-columns must be even (the CFA phase holds across the strip) and at most {MAX_MASKED_COLUMNS}, got {}",
                c.masked_columns
            ),
        ));
    }
    if c.noise_bank && c.model != ModelKind::Pgrf {
        return Err(bad(
            "--noise-bank",
            pgrf_noise::bank::needs_pgrf_model("--model"),
        ));
    }
    if c.masked_columns > 0 && c.calib.is_some() {
        return Err(bad(
            "--masked-columns",
            "--masked-columns cannot be used with --calib: a calibration's per-pixel maps cover the visible pixels only".into(),
        ));
    }
    if let Some(t) = c.exposure_time {
        if !(t.is_finite() && t >= 0.0) {
            return Err(bad(
                "--exposure-time",
                format!("--exposure-time must be >= 0 seconds, got {t}"),
            ));
        }
    }
    Ok(())
}

/// The profile `c` names with its dark current replaced when `c` says,
/// after checking the numeric settings ([`check`]).
pub fn load_profile(c: &SynthConfig) -> Result<CameraProfile, SynthError> {
    check(c)?;
    let mut profile = CameraProfile::load(&c.profile, c.darktable.as_deref())?;
    with_dark_rate(&mut profile, c);
    Ok(profile)
}

/// Replace `profile`'s dark current by `c`'s rate and law, when `c` sets a rate.
pub fn with_dark_rate(profile: &mut CameraProfile, c: &SynthConfig) {
    if let Some(rate) = c.dark_rate {
        profile.dark_current = Some(DarkCurrent {
            law: c.dark_law,
            rate,
        });
    }
}

/// What a capture depends on besides the packed clean image and the
/// settings: facts of the clean frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CleanFacts {
    /// Each packed plane's sensor-row parity (the CFA's, for row noise).
    pub plane_rows: [usize; 4],
    /// The clean frame's ISO, used when the settings and the profile set none.
    pub iso: Option<u32>,
    /// The clean frame's exposure time, seconds: the capture's is it divided
    /// by the ratio unless the settings give one.
    pub exposure_s: Option<f64>,
}

impl CleanFacts {
    /// The facts of a decoded frame.
    pub fn of(frame: &RawFrame) -> CleanFacts {
        CleanFacts {
            plane_rows: frame.cfa.offsets().map(|(r, _)| r),
            iso: frame.iso,
            exposure_s: frame.exposure_s,
        }
    }
}

/// One simulated capture, packed `(4, H/2, W/2)` and normalised like the
/// clean image, with what it was made with: the one recipe behind `pgrf
/// synth` and the Python package's `pgrf.synth`, so both give the same
/// numbers for the same seed.
#[derive(Clone, Debug)]
pub struct PackedCapture {
    /// The noisy image amplified by the ratio (as a network is fed it, not
    /// clipped); [`PackedCapture::dark`] and [`PackedCapture::brightened`]
    /// are its two recorded forms.
    pub noisy: ndarray::Array3<f32>,
    /// What it was made with.
    pub info: CaptureInfo,
    /// The dark capture's DNG NoiseProfile (DNG 1.3, tag 51041), one pair
    /// for every colour plane ([`PackedCapture::stamp`] writes it per
    /// plane, as the tag's ColorPlanes): variance = S x + O of the
    /// normalised signal x, with
    /// S = K / range and O = (sigma_read^2 + sigma_row^2) / range^2 of the
    /// parameters drawn (range: the profile's, on which they were drawn and
    /// normalised). That is the level the networks are conditioned on in
    /// training, so `pgrf enhance` finds the noise the capture was made
    /// with instead of estimating it. The ELD and pgrf models' heavy tails
    /// and per-pixel maps are beyond one pair; cameras write the same
    /// summary of theirs. Always set (an Option for frames that carry
    /// none).
    pub noise_profile: Option<Vec<[f64; 2]>>,
}

impl PackedCapture {
    /// What the camera records: un-amplified, clipped at white, the read
    /// noise around black kept ([`pgrf_noise::capture::recorded`]).
    pub fn dark(&self) -> ndarray::Array3<f32> {
        pgrf_noise::capture::recorded(&self.noisy, self.info.ratio)
    }

    /// Multiplied back by the ratio and clipped to [0, 1], as a network is fed it.
    pub fn brightened(&self) -> ndarray::Array3<f32> {
        ndarray::Zip::from(&self.noisy).par_map_collect(|&v| v.clamp(0.0, 1.0))
    }

    /// Both recorded forms, ([`PackedCapture::dark`],
    /// [`PackedCapture::brightened`]), the brightened one made in place of
    /// `noisy`, which is left empty: for callers done with the capture's
    /// pixels (one frame-sized copy fewer; `pgrf.synth`).
    pub fn take_forms(&mut self) -> (ndarray::Array3<f32>, ndarray::Array3<f32>) {
        let dark = self.dark();
        let mut bright = std::mem::take(&mut self.noisy);
        bright.par_mapv_inplace(|v| v.clamp(0.0, 1.0));
        (dark, bright)
    }

    /// Set the capture's ISO, exposure and NoiseProfile (the last only for
    /// the dark form: a brightened frame's noise is not its own; one pair
    /// per colour plane, 3 or 1 for a monochrome frame) on `frame`, a frame
    /// of the capture's pixels.
    pub fn stamp(&self, frame: &mut RawFrame, brightened: bool) {
        if let Some(iso) = self.info.iso {
            frame.iso = Some(iso);
        }
        frame.exposure_s = Some(self.info.exposure_s as f64);
        let planes = if frame.mono { 1 } else { 3 };
        frame.noise_profile = match (&self.noise_profile, brightened) {
            (Some(np), false) if np.len() == 1 => Some(vec![np[0]; planes]),
            (np, false) => np.clone(),
            (_, true) => None,
        };
    }
}

/// Simulate the low-light capture of the packed clean image `clean`
/// (normalised, R, G1, B, G2) with `profile` (dark current already set, see
/// [`load_profile`]) and, for the PGRF model, a per-pixel `calibration`
/// already checked against the frame; `c`'s profile, calibration file and
/// `force` are the caller's and not read here. `label` names the image in
/// errors.
pub fn synthesize_packed(
    clean: ndarray::ArrayView3<f32>,
    facts: &CleanFacts,
    profile: CameraProfile,
    calibration: Option<&CalibrationFile>,
    c: &SynthConfig,
    label: &Path,
) -> Result<PackedCapture, SynthError> {
    check(c)?;
    let components = Components::parse(&c.components)?;
    let only_iso = profile.only_iso();
    let mut spec = PairSpec::new(profile, c.model);
    spec.components = components;
    spec.global = c.global;
    spec.tukey = !c.gaussian_read;
    spec.iso = c.iso.or(only_iso).or(facts.iso);
    spec.ratio = match c.ratio {
        Some(r) => RatioSpec::Fixed(r),
        None => RatioSpec::default(),
    };
    // The ratio must be known to derive the exposure from the file's.
    let (ratio, _) = spec.conditions(c.seed)?;
    spec.ratio = RatioSpec::Fixed(ratio);
    spec.exposure = match (c.exposure_time, facts.exposure_s) {
        (Some(t), _) => ExposureSpec::Fixed(t),
        (None, Some(t)) => ExposureSpec::Fixed((t / ratio as f64) as f32),
        (None, None) => ExposureSpec::default(),
    };
    crate::mix::apply_calibration(calibration, c.noise_bank, &mut spec)?;
    let pair = spec
        .synthesize_noisy(clean, facts.plane_rows, c.seed)
        .map_err(|cause| SynthError::Synthesis {
            path: label.to_path_buf(),
            cause,
        })?;
    let p = &pair.params;
    // The noise was drawn on the profile's scale and normalised by it.
    let range = spec.dn_range();
    Ok(PackedCapture {
        noise_profile: Some(vec![[
            p.k / range,
            (p.sigma_gauss.powi(2) + row_dn(c, components, p).powi(2)) / range.powi(2),
        ]]),
        info: CaptureInfo {
            ratio: pair.ratio,
            exposure_s: pair.exposure_s,
            iso: spec.iso,
            components: c.model.components(components),
            k: p.k,
            read_dn: if c.model == ModelKind::Eld && !c.gaussian_read {
                p.sigma_tukey
            } else {
                p.sigma_gauss
            },
            row_dn: row_dn(c, components, p),
        },
        noisy: pair.noisy,
    })
}

/// The row noise (DN) a capture of `c`'s model with `components` drew:
/// the parameters' own, or none when the model leaves it out.
fn row_dn(c: &SynthConfig, components: Components, p: &pgrf_noise::CaptureParams) -> f64 {
    if c.model.components(components).row() {
        p.sigma_row
    } else {
        0.0
    }
}

/// Simulate the low-light capture of the clean frame `frame` (read from
/// `path`, named in errors) as `c` says.
pub fn synthesize(
    frame: &RawFrame,
    path: &Path,
    c: &SynthConfig,
) -> Result<Synthesized, SynthError> {
    let profile = load_profile(c)?;
    Components::parse(&c.components)?;
    let clean = pack_normalized(frame, true)?;
    let calibration = match &c.calib {
        Some(cal) => {
            // The ISO the capture will have decides the calibration check.
            let iso = c.iso.or(profile.only_iso()).or(frame.iso);
            let check = FrameCheck {
                frame,
                force: c.force,
            };
            Some(CalibrationFile::load(cal, Some(check), iso)?)
        }
        None => None,
    };
    // The masked columns are dark pixels of the same readout: synthesised
    // with the scene (zero signal), so they share its offset and row noise.
    let m = c.masked_columns / 2;
    let clean = if m > 0 {
        let zeros = ndarray::Array3::<f32>::zeros((4, clean.dim().1, m));
        ndarray::concatenate(ndarray::Axis(2), &[zeros.view(), clean.view()])
            .expect("same planes and rows")
    } else {
        clean
    };
    let made = synthesize_packed(
        clean.view(),
        &CleanFacts::of(frame),
        profile,
        calibration.as_ref(),
        c,
        path,
    )?;
    let noisy = if c.brightened {
        made.brightened()
    } else {
        made.dark()
    };
    let (strip, visible) = noisy.view().split_at(ndarray::Axis(2), m);
    let mut out = unpack_normalized(visible, frame)?;
    if m > 0 {
        out.masked = masked_strip(strip, frame)?;
    }
    made.stamp(&mut out, c.brightened);
    Ok(Synthesized {
        frame: out,
        info: made.info,
    })
}

/// The synthesised masked columns (packed `(4, H/2, columns/2)`) as the
/// frame's masked strip, in DN of `frame`'s levels, with their level.
fn masked_strip(
    strip: ndarray::ArrayView3<f32>,
    frame: &RawFrame,
) -> Result<Option<pgrf_raw::masked::Masked>, SynthError> {
    let columns = 2 * strip.dim().2;
    let mut template = RawFrame::from_mosaic(
        columns,
        frame.height,
        vec![0; columns * frame.height],
        frame.cfa,
        frame.black,
        frame.white,
    )?;
    template.mono = frame.mono;
    let values = unpack_normalized(strip, &template)?.mosaic;
    Ok(pgrf_raw::masked::Masked::of_strip(
        pgrf_raw::masked::MaskedStrip { columns, values },
        frame.height,
        frame.cfa,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat monochrome frame through the Poisson-Gaussian model comes out
    /// monochrome, one plane of the input's size, with the noise the physics
    /// gives: L DN above black at ratio r is a dark capture of mean
    /// mu = L / r DN and variance K mu + sigma^2 + 1/12 (shot, read, the
    /// rounding to whole DN). The frame's scale is the profile's, so DN
    /// carry over unscaled. 128 x 128 pixels: the mean's standard error is
    /// about 0.15 DN (tolerance 5 SE), the variance's 1.1 % (tolerance 6 %).
    #[test]
    fn a_flat_monochrome_frame_gets_the_noise_the_physics_gives() {
        let range = CameraProfile::built_in("sony-a7s2").unwrap().dn_range();
        let (w, h, black, level, ratio) = (128, 128, 512.0f32, 2000.0f64, 10.0f32);
        let white = (black as f64 + range) as u32;
        let clean = vec![(black as f64 + level) as u16; w * h];
        let frame = RawFrame::from_mono(w, h, clean, black, white).unwrap();
        let c = SynthConfig {
            profile: "sony-a7s2".into(),
            ratio: Some(ratio),
            iso: Some(1600),
            model: ModelKind::PoissonGaussian,
            components: "P,G".into(),
            global: false,
            gaussian_read: true,
            exposure_time: Some(0.01),
            dark_rate: None,
            dark_law: DarkLaw::Sqrt,
            calib: None,
            force: false,
            seed: 7,
            brightened: false,
            masked_columns: 0,
            darktable: None,
            noise_bank: false,
        };
        let made = synthesize(&frame, Path::new("flat.dng"), &c).unwrap();
        let out = &made.frame;
        assert!(out.mono);
        assert_eq!((out.width, out.height), (w, h));
        let stats = pgrf_raw::stats::plane_stats(out).unwrap();
        assert_eq!(stats.len(), 1);
        let n = (w * h) as f64;
        let dn: Vec<f64> = out
            .mosaic
            .iter()
            .map(|&v| v as f64 - black as f64)
            .collect();
        let mean = dn.iter().sum::<f64>() / n;
        let var = dn.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let mu = level / ratio as f64;
        let want = made.info.k * mu + made.info.read_dn.powi(2) + 1.0 / 12.0;
        let se = (want / n).sqrt();
        assert!((mean - mu).abs() < 5.0 * se, "mean {mean} DN vs {mu}");
        assert!(
            (var / want - 1.0).abs() < 0.06,
            "variance {var} DN^2 vs {want} (K {}, read {})",
            made.info.k,
            made.info.read_dn
        );
        // Seeded: the same seed gives the same frame.
        let again = synthesize(&frame, Path::new("flat.dng"), &c).unwrap();
        assert_eq!(again.frame.mosaic, out.mosaic);
    }
}
