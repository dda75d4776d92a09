//! The noise parameters of any input frame, and where they came from: what
//! a noise-aware network is told ([`find_noise`]). The sources, in order of
//! trust:
//!
//! 1. a calibration of this camera (`--calib FILE`; the caller reads it,
//!    this crate sits below the calibration crate);
//! 2. the user's numbers (`--noise K=..,read=..[,row=..]`, [`NoiseFlag`]);
//! 3. the file's own DNG NoiseProfile tag (the camera's or the converter's
//!    statement of S x + O);
//! 4. darktable's measured profile of the camera (EXIF maker and model) at
//!    the frame's ISO, where darktable's noiseprofiles.json is found;
//! 5. a built-in profile of the camera at the frame's ISO;
//! 6. otherwise a blind estimate from the frame's own pixels
//!    ([`crate::estimate`]).
//!
//! Every value is in DN on the frame's own scale (white - black); profiles
//! on another scale are converted.

use crate::error::{NoiseError, Result};
use crate::profile::CameraProfile;
use pgrf_core::parse::ParseError;
use pgrf_raw::RawFrame;
use std::fmt;
use std::path::{Path, PathBuf};

/// A frame's noise: gain, read and row noise in DN on its own scale.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameNoise {
    /// System gain K, DN per electron.
    pub k: f64,
    /// Read noise standard deviation, DN (everything signal-independent
    /// but row noise).
    pub read: f64,
    /// Row noise standard deviation, DN (0 where the source does not say).
    pub row: f64,
    /// Where the numbers came from.
    pub source: NoiseSource,
}

/// Where a frame's noise parameters came from.
#[derive(Clone, Debug, PartialEq)]
pub enum NoiseSource {
    /// A calibration file of the camera.
    Calibration(PathBuf),
    /// The user's `--noise` flag.
    Flag,
    /// The file's DNG NoiseProfile tag.
    DngTag,
    /// darktable's profile of the camera at the frame's ISO.
    Darktable {
        /// The camera as darktable names it.
        camera: String,
        /// The ISO.
        iso: u32,
    },
    /// A built-in profile at the frame's ISO.
    BuiltIn {
        /// The profile's name.
        name: String,
        /// The ISO.
        iso: u32,
    },
    /// Estimated from the frame's pixels.
    Estimate {
        /// 8 x 8 blocks the fit used.
        blocks: usize,
    },
    /// The frame shows no signal-dependent noise (a clean, well-exposed
    /// frame, or one already denoised): the smallest level the estimate
    /// resolves ([`resolution_floor`]).
    Floor {
        /// 8 x 8 blocks the fit used.
        blocks: usize,
    },
}

impl fmt::Display for NoiseSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NoiseSource::Calibration(p) => write!(f, "calibration {}", p.display()),
            NoiseSource::Flag => f.write_str("--noise"),
            NoiseSource::DngTag => f.write_str("the file's DNG NoiseProfile tag"),
            NoiseSource::Darktable { camera, iso } => {
                write!(f, "darktable's profile of the {camera} at ISO {iso}")
            }
            NoiseSource::BuiltIn { name, iso } => {
                write!(f, "built-in profile {name} at ISO {iso}")
            }
            NoiseSource::Estimate { blocks } => {
                write!(f, "estimated from the frame ({blocks} flat blocks)")
            }
            NoiseSource::Floor { blocks } => write!(
                f,
                "no signal-dependent noise in the frame ({blocks} flat blocks): the smallest level the estimate resolves, 1 DN rounding"
            ),
        }
    }
}

impl fmt::Display for FrameNoise {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "K {:.4} DN/e-, read {:.3} DN", self.k, self.read)?;
        if self.row > 0.0 {
            write!(f, ", row {:.3} DN", self.row)?;
        }
        write!(f, " ({})", self.source)
    }
}

/// The user's noise parameters: `K=GAIN,read=SIGMA[,row=SIGMA]` (DN per
/// electron, DN), on the input file's DN scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseFlag {
    /// K, DN per electron.
    pub k: f64,
    /// Read noise, DN.
    pub read: f64,
    /// Row noise, DN.
    pub row: f64,
}

impl std::str::FromStr for NoiseFlag {
    type Err = ParseError;

    fn from_str(text: &str) -> std::result::Result<NoiseFlag, ParseError> {
        let (mut k, mut read, mut row) = (None, None, 0.0);
        for item in text.split(',') {
            let Some((key, value)) = item.split_once('=') else {
                return Err(ParseError::malformed(
                    item,
                    format!("{item:?}: expected KEY=VALUE (K=.., read=.., row=..)"),
                ));
            };
            let v: f64 = value
                .trim()
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| {
                    ParseError::malformed(item, format!("{item:?}: expected a non-negative number"))
                })?;
            match key.trim().to_ascii_lowercase().as_str() {
                "k" => k = Some(v),
                "read" => read = Some(v),
                "row" => row = v,
                other => {
                    return Err(ParseError::unknown_name(
                        key,
                        format!("unknown key {other:?} (K, read, row)"),
                    ))
                }
            }
        }
        match (k, read) {
            (Some(k), Some(read)) if k > 0.0 => Ok(NoiseFlag { k, read, row }),
            (Some(_), Some(_)) => Err(ParseError::out_of_range(text, "K must be positive")),
            _ => Err(ParseError::malformed(
                text,
                "give at least K=.. and read=..",
            )),
        }
    }
}

/// What the caller already knows: a calibration (path, K, read, row in
/// DN) and the user's flag.
#[derive(Clone, Debug, Default)]
pub struct KnownNoise {
    /// A calibration of the camera: its file, K, read and row noise (DN).
    pub calibration: Option<(PathBuf, f64, f64, f64)>,
    /// The user's `--noise`.
    pub flag: Option<NoiseFlag>,
    /// darktable's noiseprofiles.json when the caller names it (else its
    /// install is searched).
    pub darktable: Option<PathBuf>,
}

/// white - black of `frame`, DN (mean black of its planes): the scale
/// of every DN value of [`FrameNoise`].
pub fn range_of(frame: &RawFrame) -> f64 {
    frame.white as f64 - frame.black.iter().map(|&b| b as f64).sum::<f64>() / 4.0
}

/// The frame's DNG NoiseProfile, averaged over planes, in DN.
fn from_dng_tag(frame: &RawFrame, range: f64) -> Option<(f64, f64)> {
    let pairs = frame.noise_profile.as_ref()?;
    if pairs.is_empty() {
        return None;
    }
    let n = pairs.len() as f64;
    let s = pairs.iter().map(|p| p[0]).sum::<f64>() / n;
    let o = pairs.iter().map(|p| p[1]).sum::<f64>() / n;
    (s > 0.0 && o >= 0.0).then(|| (s * range, o.sqrt() * range))
}

/// `profile`'s K, read and row noise at `iso`, converted to a scale of
/// `range` DN.
fn at_iso(profile: &CameraProfile, iso: u32, range: f64) -> Option<(f64, f64, f64)> {
    let p = profile.params_at_iso(iso).ok()?;
    let scale = range / profile.dn_range;
    Some((p.k * scale, p.sigma_gauss * scale, p.sigma_row * scale))
}

/// darktable's profile of the frame's camera at its ISO, if darktable's
/// file is found and names the camera.
fn from_darktable(
    frame: &RawFrame,
    iso: u32,
    range: f64,
    file: Option<&Path>,
) -> Option<(FrameNoise, String)> {
    let profiles = crate::darktable::NoiseProfiles::open(file).ok()?;
    let query = format!("{} {}", frame.make.trim(), frame.model.trim());
    let camera = profiles.find(&query).ok()?.name();
    let profile = profiles.profile(&query).ok()?;
    let (k, read, row) = at_iso(&profile, iso, range)?;
    Some((
        FrameNoise {
            k,
            read,
            row,
            source: NoiseSource::Darktable {
                camera: camera.clone(),
                iso,
            },
        },
        camera,
    ))
}

/// The built-in profile whose camera is the frame's (maker and model,
/// ignoring case), at its ISO.
fn from_built_in(frame: &RawFrame, iso: u32, range: f64) -> Option<FrameNoise> {
    let model = frame.model.trim().to_ascii_lowercase();
    if model.is_empty() {
        return None;
    }
    crate::profile::built_in_names()
        .into_iter()
        .find_map(|name| {
            let p = CameraProfile::built_in(name)?;
            let same = p.model.to_ascii_lowercase() == model
                && frame.make.to_ascii_lowercase().contains(
                    &p.make
                        .to_ascii_lowercase()
                        .split_whitespace()
                        .next()?
                        .to_string(),
                );
            if !same {
                return None;
            }
            let (k, read, row) = at_iso(&p, iso, range)?;
            Some(FrameNoise {
                k,
                read,
                row,
                source: NoiseSource::BuiltIn {
                    name: name.to_string(),
                    iso,
                },
            })
        })
}

/// What an estimate that fails adds: nothing else knew the camera either,
/// and how to tell pgrf.
const NO_SOURCE: &str = "no calibration, --noise, NoiseProfile or profile of this camera either: give --noise K=..,read=.. (or --calib)";

/// The frame's noise from the first source that has it (module
/// documentation).
pub fn find_noise(frame: &RawFrame, known: &KnownNoise) -> Result<FrameNoise> {
    if let Some((path, k, read, row)) = &known.calibration {
        return Ok(FrameNoise {
            k: *k,
            read: *read,
            row: *row,
            source: NoiseSource::Calibration(path.clone()),
        });
    }
    if let Some(f) = known.flag {
        return Ok(FrameNoise {
            k: f.k,
            read: f.read,
            row: f.row,
            source: NoiseSource::Flag,
        });
    }
    let range = range_of(frame);
    if !(range.is_finite() && range > 0.0) {
        return Err(NoiseError::Estimate(format!(
            "white {} is not above the black level",
            frame.white
        )));
    }
    if let Some((k, read)) = from_dng_tag(frame, range) {
        return Ok(FrameNoise {
            k,
            read,
            row: 0.0,
            source: NoiseSource::DngTag,
        });
    }
    if let Some(iso) = frame.iso {
        if let Some((noise, _)) = from_darktable(frame, iso, range, known.darktable.as_deref()) {
            return Ok(noise);
        }
        if let Some(noise) = from_built_in(frame, iso, range) {
            return Ok(noise);
        }
    }
    let packed =
        pgrf_raw::pack_normalized(frame, false).map_err(|e| NoiseError::Estimate(e.to_string()))?;
    // Nothing else knows this camera: say how to tell pgrf when the frame
    // cannot tell it either.
    let fit = crate::estimate::fit(packed.view()).map_err(|e| match e {
        NoiseError::Estimate(m) => NoiseError::Estimate(format!("{m}; {NO_SOURCE}")),
        e => e,
    })?;
    let (k, read) = fit.in_dn(range);
    // Below the floor's gain (none at all, or rounding error of none) the
    // fit has found no signal-dependent noise.
    if !(k.is_finite() && read.is_finite() && k / range >= MIN_SIGNAL_GAIN) {
        let (k, read) = resolution_floor(range);
        return Ok(FrameNoise {
            k,
            read,
            row: 0.0,
            source: NoiseSource::Floor { blocks: fit.blocks },
        });
    }
    Ok(FrameNoise {
        k,
        read,
        row: 0.0,
        source: NoiseSource::Estimate { blocks: fit.blocks },
    })
}

/// The smallest signal-dependent variance per unit of normalised signal
/// (K / range, at ratio 1) a noise level may state: 10^-8, a deviation of
/// 10^-4 of white at white, 600x below the quietest built-in camera's
/// (A7S2 ISO 100: 6e-6). Below it the networks' k-sigma domain (scale
/// 0.01 / gain) loses the image in f32, so they refuse such levels.
pub const MIN_SIGNAL_GAIN: f64 = 1e-8;

/// The quietest noise the blind estimate's answer can stand for, on a
/// scale of `range` DN, as (K, read): the rounding of the samples to whole
/// DN (variance 1/12 DN²) as the read noise, and the smallest gain a noise
/// level may state ([`MIN_SIGNAL_GAIN`]; the gain whose shot noise equals
/// the rounding at white, 1 / (12 range), is below it for any real
/// range). A frame that shows no signal-dependent noise (a clean,
/// well-exposed photo) is restored as that quiet: nearly unchanged, instead
/// of refused.
pub fn resolution_floor(range: f64) -> (f64, f64) {
    let rounding: f64 = 1.0 / 12.0;
    let k = (rounding / range).max(MIN_SIGNAL_GAIN * range);
    (k, rounding.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_core::parse::ParseErrorKind;
    use pgrf_raw::Cfa;

    fn frame() -> RawFrame {
        let mut f = RawFrame::from_mosaic(64, 48, vec![600; 64 * 48], Cfa::Rggb, [512.0; 4], 16383)
            .unwrap();
        f.iso = Some(1600);
        f.make = "SONY".into();
        f.model = "ILCE-7SM2".into();
        f
    }

    /// The floor: rounding's sqrt(1/12) DN of read noise and the smallest
    /// gain a level may state, on the frame's scale; a noise-free frame
    /// gets it (not an error) and says so.
    #[test]
    fn a_frame_without_noise_gets_the_floor() {
        let (k, read) = resolution_floor(15871.0);
        assert!((read - (1.0f64 / 12.0).sqrt()).abs() < 1e-12);
        assert!((k / 15871.0 - MIN_SIGNAL_GAIN).abs() < 1e-20, "{k}");
        // A flat frame of constant values, no camera pgrf knows.
        let mut f = RawFrame::from_mosaic(
            192,
            192,
            (0..192 * 192).map(|i| 600 + (i % 192) as u16 * 4).collect(),
            Cfa::Rggb,
            [512.0; 4],
            16383,
        )
        .unwrap();
        f.make = "Nobody".into();
        let n = find_noise(&f, &KnownNoise::default()).unwrap();
        assert!(matches!(n.source, NoiseSource::Floor { .. }), "{n}");
        assert_eq!((n.k, n.read), resolution_floor(16383.0 - 512.0));
        assert!(n
            .to_string()
            .contains("smallest level the estimate resolves"));
    }

    #[test]
    fn the_flag_reads_k_read_and_row() {
        let f: NoiseFlag = "K=1.5,read=3.2,row=0.4".parse().unwrap();
        assert_eq!(
            f,
            NoiseFlag {
                k: 1.5,
                read: 3.2,
                row: 0.4
            }
        );
        let f: NoiseFlag = "k=2, read=1".parse().unwrap();
        assert_eq!((f.k, f.read, f.row), (2.0, 1.0, 0.0));
        for bad in [
            "K=1.5",
            "read=2",
            "K=0,read=1",
            "K=-1,read=1",
            "K=1,read=x",
            "K=1,read=1,gain=2",
            "K",
        ] {
            assert!(bad.parse::<NoiseFlag>().is_err(), "{bad}");
        }
        let e = "K=0,read=1".parse::<NoiseFlag>().unwrap_err();
        assert_eq!(e.kind(), ParseErrorKind::OutOfRange);
        assert_eq!(e.to_string(), "K must be positive");
        let e = "K=1,read=1,gain=2".parse::<NoiseFlag>().unwrap_err();
        assert_eq!((e.kind(), e.input()), (ParseErrorKind::UnknownName, "gain"));
    }

    /// Calibration, then the flag, then the DNG tag, then a built-in
    /// profile of the camera, each named as the source.
    #[test]
    fn the_sources_are_taken_in_order() {
        let mut f = frame();
        f.noise_profile = Some(vec![[2e-4, 4e-6]]);
        let flag = NoiseFlag {
            k: 1.0,
            read: 2.0,
            row: 0.0,
        };
        let calibration = Some((PathBuf::from("cam.safetensors"), 1.5, 3.0, 0.5));
        let both = KnownNoise {
            calibration: calibration.clone(),
            flag: Some(flag),
            darktable: None,
        };
        let n = find_noise(&f, &both).unwrap();
        assert_eq!(n.source, NoiseSource::Calibration("cam.safetensors".into()));
        assert_eq!((n.k, n.read, n.row), (1.5, 3.0, 0.5));
        let n = find_noise(
            &f,
            &KnownNoise {
                calibration: None,
                flag: Some(flag),
                darktable: None,
            },
        )
        .unwrap();
        assert_eq!(n.source, NoiseSource::Flag);
        let n = find_noise(&f, &KnownNoise::default()).unwrap();
        assert_eq!(n.source, NoiseSource::DngTag);
        // K = S (white - black), read = sqrt(O) (white - black).
        assert!((n.k - 2e-4 * 15871.0).abs() < 1e-9, "{}", n.k);
        assert!((n.read - 2e-3 * 15871.0).abs() < 1e-6, "{}", n.read);
        // Without the tag: the built-in A7S2 profile at ISO 1600 (darktable's
        // file is not installed on the test machines; if it is, it names the
        // camera too).
        f.noise_profile = None;
        let n = find_noise(&f, &KnownNoise::default()).unwrap();
        match &n.source {
            NoiseSource::BuiltIn { name, iso } => {
                assert_eq!((name.as_str(), *iso), ("sony-a7s2", 1600));
                let want = CameraProfile::built_in("sony-a7s2")
                    .unwrap()
                    .params_at_iso(1600)
                    .unwrap();
                assert!(
                    (n.k - want.k).abs() < 0.02 * want.k,
                    "{} vs {}",
                    n.k,
                    want.k
                );
            }
            NoiseSource::Darktable { iso, .. } => assert_eq!(*iso, 1600),
            other => panic!("expected a profile, got {other}"),
        }
        assert!(n.to_string().contains("ISO 1600"), "{n}");
    }

    /// A camera nothing knows: the frame's own pixels (too small and flat
    /// here, so the estimate says why it cannot be made).
    #[test]
    fn an_unknown_camera_falls_back_to_the_estimate() {
        let mut f = frame();
        f.make = "Nobody".into();
        f.model = "Camera 1".into();
        let e = find_noise(&f, &KnownNoise::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("blind noise estimate"), "{e}");
    }
}
