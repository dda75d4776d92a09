//! darktable's camera noise profiles (`noiseprofiles.json`) as pgrf
//! profiles: `--profile darktable:"MAKER MODEL"`.
//!
//! Facts from darktable's source (release 4.2.1; the paths are the
//! darktable repository's), and what pgrf makes of them.
//!
//! # The file (src/common/noiseprofiles.c, data/noiseprofiles.schema)
//!
//! - A JSON object: `"version"` (an integer; darktable's
//!   `DT_NOISE_PROFILE_VERSION` is 0 and it refuses any other) and
//!   `"noiseprofiles"`, an array of makers `{"maker": "Canon", "models":
//!   [...]}`; each model is `{"comment": "...", "model": "EOS 550D",
//!   "profiles": [...]}`, each profile `{"name": "Canon EOS 550D iso 3200",
//!   "iso": 3200, "a": [r, g, b], "b": [r, g, b]}` with an optional `"skip":
//!   true`. darktable's `dt_noiseprofile_verify` refuses the whole file when
//!   a maker lacks `maker` or `models`, a model lacks `model` or `profiles`,
//!   or a profile lacks `name`, `iso`, `a` or `b` or has an `a` or `b` of
//!   other than 3 values; pgrf refuses the same, naming the entry.
//! - `dt_noiseprofile_get_matching` leaves out the entries marked `"skip":
//!   true` and sorts the rest by ISO. It takes the first maker whose `maker`
//!   string occurs in the image's (normalised) maker name, case-sensitively,
//!   and in it the model whose `model` equals the image's exactly. pgrf
//!   matches the name a user types: "MAKER MODEL" (or MODEL alone when the
//!   model already begins with the maker, as "Canon PowerShot SX160 IS"
//!   does), ignoring case and repeated spaces; a miss names the three
//!   closest cameras (edit distance).
//! - ISO (src/iop/denoiseprofile.c, `reload_defaults` and
//!   `dt_iop_denoiseprofile_get_auto_profile`): the entry at the image's
//!   ISO, else a and b interpolated linearly in ISO between the nearest
//!   measured ISOs below and above (`dt_noiseprofile_interpolate`: t = (iso -
//!   iso1) / (iso2 - iso1)). Outside the measured ISOs darktable does not
//!   extrapolate but falls back to its "generic poissonian" profile; pgrf
//!   refuses such an ISO, naming the range. Where the file has several
//!   entries at one ISO (19 cameras in 4.2.1's file) darktable uses one of
//!   them, which depends on list order; pgrf averages them.
//!
//! # What a and b measure (tools/noise/darktable-gen-noiseprofile, profiling-shot.xmp, noiseprofile.c)
//!
//! - The profiling shot is exported by `darktable-cli` with
//!   `profiling-shot.xmp` to a PFM: rawprepare ((raw - black) / (white -
//!   black) per CFA position: black 0, white 1), temperature with
//!   coefficients 1, 1, 1 (no white balance), the default demosaic, colorin
//!   and colorout both "linear Rec709" (a round trip that keeps camera RGB);
//!   sharpening, base curve and highlight reconstruction off. So the signal
//!   x is the demosaiced camera red, green or blue of the raw normalised to
//!   [0, 1], without white balance: none enters the numbers (denoiseprofile
//!   multiplies them by the image's white balance when it applies them).
//! - `darktable-noiseprofile` (noiseprofile.c) takes one level of a Haar
//!   transform, bins the pairs (LL, |HH|) of each channel by LL (the mean of
//!   2 x 2 pixels: x) into 300 bins over [0, 1], and estimates the noise of
//!   a bin as median |HH| / 0.6745. gnuplot fits var = a x + b to the
//!   squared estimates, weighted by the bin counts squared, over x up to
//!   0.35 (red), 0.8 (green), 0.5 (blue). `a[0..2]` and `b[0..2]` are red, green
//!   and blue. A negative green slope stops the profiling; a negative red or
//!   blue one is written as 0; b is the line's intercept, unconstrained
//!   (771 of the 6555 entries in use in 4.2.1's file have a green b < 0).
//! - a x + b is therefore the variance of HH = (x00 - x01 - x10 + x11) / 4
//!   of a demosaiced image, not that of a photosite: for independent pixels
//!   it would be a quarter of it, and demosaicing correlates neighbouring
//!   pixels and lowers it further. Measured with darktable 4.2.1's own chain
//!   (`darktable-cli` with `profiling-shot.xmp`, `darktable-noiseprofile`,
//!   the same weighted fit) on synthetic 14-bit raws with known photosite
//!   noise S x + O (S from 3.2e-5 to 1.9e-3, O from 6.4e-8 to 2.5e-5): S =
//!   F a for green, with F = 12.5..12.7 after PPG on grey raws and
//!   12.9..13.3 with red and blue photosites at 0.4..0.5 of green (a raw's
//!   usual balance; all four CFA phases), 21.0..22.2 after RCD, 10.2..10.4
//!   after AMaZE (grey), whatever the noise level. b scales by about the same
//!   factor where the read noise is large enough for the intercept to
//!   resolve it (O / b = 7.8..12.5 after PPG), and is dominated by the fit's
//!   error where it is not.
//!
//! # pgrf's profile
//!
//! - S = [`VARIANCE_FACTOR`] `a[1]` and O = [`VARIANCE_FACTOR`] max(`b[1]`, 0),
//!   with `a[1]`, `b[1]` at the ISO as darktable interpolates them. The green
//!   channel is the one darktable's denoiseprofile uses ("only use green
//!   channel + wb for now") and the one fitted over the widest range; a
//!   photosite's noise has one gain whatever its colour (the spread of `a[0..2]`
//!   comes from demosaicing), and pgrf's models have one gain. The factor is
//!   PPG's: PPG was darktable's default demosaic while most of the file was
//!   measured, and 12.9 the middle of its range (4.2.1 defaults to RCD: for
//!   a profile measured after RCD, pgrf's variance is about 22 / 12.9 = 1.7
//!   times too low).
//! - b < 0: the fit resolved no read noise at that ISO; pgrf uses 0 there and
//!   says so in the profile's source.
//! - The DN scale: darktable's numbers are normalised, and synthesis draws
//!   normalised noise, whose variance is S x + O whatever the scale. pgrf
//!   states the profile on a nominal 14-bit scale, [`DN_RANGE`] = 16383
//!   (K = S x 16383 DN/e-, sigma = sqrt(O) x 16383 DN), with no black level
//!   (nothing is clipped below black); the scale sets only the 1-DN
//!   quantisation step of the ELD and pgrf models and the numbers shown.
//! - pgrf's per-ISO tables interpolate linearly in log ISO; to follow
//!   darktable's rule the profile's table holds the measured ISOs and, between
//!   them, integer ISOs at most 0.5 % apart computed by darktable's rule, so
//!   that K at any ISO is darktable's to a few parts in a million.
//! - What the file holds is all there is: Poisson-Gaussian noise only, no row
//!   noise, no fixed pattern, no heavy-tailed (Tukey) read noise, no dark
//!   current.

use crate::error::{NoiseError, Result};
use crate::pg_profile::{poisson_gaussian_table, PgRow};
use crate::profile::CameraProfile;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Photosite variance over darktable's green a (and b): the factor by which
/// darktable's profiling chain (Haar HH of a PPG-demosaiced image) lowers
/// the variance, measured with darktable 4.2.1 at 12.5..13.3 (module
/// documentation).
pub const VARIANCE_FACTOR: f64 = 12.9;

/// The nominal scale (white - black, DN) pgrf states darktable's normalised
/// numbers on: 14 bits.
pub const DN_RANGE: f64 = 16383.0;

/// darktable's file format version (`DT_NOISE_PROFILE_VERSION`).
pub const FORMAT_VERSION: i64 = 0;

/// Neighbouring ISOs of the interpolation table are at most this ratio apart.
const GRID_STEP: f64 = 1.005;

/// Where darktable installs `noiseprofiles.json` (its data directory),
/// in the order searched: `$XDG_DATA_DIRS`, the Linux prefixes /usr and
/// /usr/local, Flatpak (inside the sandbox, system-wide and per user) and
/// Snap; on macOS the application bundle, Homebrew and MacPorts; on
/// Windows the installer's folder under Program Files.
pub fn standard_locations() -> Vec<PathBuf> {
    const FILE: &str = "darktable/noiseprofiles.json";
    let mut dirs: Vec<PathBuf> = Vec::new();
    if let Some(x) = std::env::var_os("XDG_DATA_DIRS") {
        dirs.extend(std::env::split_paths(&x).filter(|p| p.is_absolute()));
    }
    if cfg!(target_os = "windows") {
        let pf = std::env::var_os("ProgramFiles")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(r"C:\Program Files"));
        dirs.push(pf.join("darktable").join("share"));
    } else if cfg!(target_os = "macos") {
        dirs.push("/Applications/darktable.app/Contents/Resources/share".into());
        dirs.push("/opt/homebrew/share".into());
        dirs.push("/usr/local/share".into());
        dirs.push("/opt/local/share".into());
    } else {
        dirs.push("/usr/share".into());
        dirs.push("/usr/local/share".into());
        dirs.push("/app/share".into());
        let flatpak = "app/org.darktable.Darktable/current/active/files/share";
        dirs.push(Path::new("/var/lib/flatpak").join(flatpak));
        if let Some(home) = std::env::var_os("HOME") {
            dirs.push(Path::new(&home).join(".local/share/flatpak").join(flatpak));
        }
        dirs.push("/snap/darktable/current/usr/share".into());
    }
    let mut out: Vec<PathBuf> = Vec::new();
    for d in dirs {
        let f = d.join(FILE);
        if !out.contains(&f) {
            out.push(f);
        }
    }
    out
}

/// The file to read: `file` when the caller names one (the CLI's
/// `--darktable-profiles`), else the first of [`standard_locations`] that
/// exists.
pub fn locate(file: Option<&Path>) -> Result<PathBuf> {
    match file {
        Some(p) => Ok(p.to_path_buf()),
        None => locate_in(&standard_locations()),
    }
}

/// The first of `candidates` that is a file, or an error naming them all.
pub fn locate_in(candidates: &[PathBuf]) -> Result<PathBuf> {
    candidates
        .iter()
        .find(|p| p.is_file())
        .cloned()
        .ok_or_else(|| {
            let looked: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
            NoiseError::Profile {
                name: "darktable".into(),
                reason: format!(
                    "darktable's noiseprofiles.json was not found (looked in {}); install darktable or name the file with --darktable-profiles PATH",
                    looked.join(", ")
                ),
            }
        })
}

/// One entry of a camera's `profiles` array.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// Its `name` ("Canon EOS 550D iso 3200").
    pub name: String,
    /// The ISO it was measured at.
    pub iso: u32,
    /// Variance slopes (red, green, blue), per unit of normalised signal.
    pub a: [f64; 3],
    /// Variance intercepts (red, green, blue).
    pub b: [f64; 3],
    /// Marked `"skip": true`: darktable leaves it out, and so does pgrf.
    pub skip: bool,
}

/// One camera of the file.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// The maker's string (`"Canon"`).
    pub maker: String,
    /// The model's string (`"EOS 550D"`).
    pub model: String,
    /// Its `comment` (who measured it), if any.
    pub comment: Option<String>,
    /// Every entry, skipped ones included, in file order.
    pub entries: Vec<Entry>,
}

/// darktable's measurement at one ISO, green channel: the entries at that
/// ISO that are not skipped, averaged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measured {
    /// The ISO.
    pub iso: u32,
    /// Green a, variance per unit of normalised signal (darktable's scale).
    pub a: f64,
    /// Green b, variance without signal (darktable's scale; may be < 0).
    pub b: f64,
    /// How many entries were averaged (1 unless the file repeats the ISO).
    pub entries: usize,
}

impl Measured {
    /// pgrf's photosite noise (S, O) for this measurement: both times
    /// [`VARIANCE_FACTOR`], O at least 0.
    pub fn photosite(&self) -> (f64, f64) {
        (VARIANCE_FACTOR * self.a, VARIANCE_FACTOR * self.b.max(0.0))
    }

    /// K in DN/e- and read sigma in DN on [`DN_RANGE`].
    pub fn gain_and_read(&self) -> (f64, f64) {
        let (s, o) = self.photosite();
        (s * DN_RANGE, o.sqrt() * DN_RANGE)
    }
}

impl Camera {
    /// The name pgrf knows it by: "MAKER MODEL", or MODEL when it already
    /// begins with the maker.
    pub fn name(&self) -> String {
        let (maker, model) = (normalise(&self.maker), normalise(&self.model));
        if model == maker || model.starts_with(&format!("{maker} ")) {
            collapse(&self.model)
        } else {
            format!("{} {}", collapse(&self.maker), collapse(&self.model))
        }
    }

    /// Whether `query` names this camera (ignoring case and repeated spaces).
    fn answers_to(&self, query: &str) -> bool {
        let q = normalise(query);
        let (maker, model) = (normalise(&self.maker), normalise(&self.model));
        q == format!("{maker} {model}")
            || (q == model && (model == maker || model.starts_with(&format!("{maker} "))))
    }

    /// The ISOs of the entries in use (not skipped), sorted, each once.
    pub fn isos(&self) -> Vec<u32> {
        let mut v: Vec<u32> = self
            .entries
            .iter()
            .filter(|e| !e.skip)
            .map(|e| e.iso)
            .collect();
        v.sort_unstable();
        v.dedup();
        v
    }

    /// The green measurements in use, one per ISO (repeated ISOs averaged),
    /// sorted by ISO.
    pub fn measured(&self) -> Vec<Measured> {
        let mut out: Vec<Measured> = Vec::new();
        for iso in self.isos() {
            let at: Vec<&Entry> = self
                .entries
                .iter()
                .filter(|e| !e.skip && e.iso == iso)
                .collect();
            let n = at.len() as f64;
            out.push(Measured {
                iso,
                a: at.iter().map(|e| e.a[1]).sum::<f64>() / n,
                b: at.iter().map(|e| e.b[1]).sum::<f64>() / n,
                entries: at.len(),
            });
        }
        out
    }
}

/// A parsed `noiseprofiles.json`.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseProfiles {
    /// The file it was read from.
    pub path: PathBuf,
    /// Its format version (0).
    pub version: i64,
    /// Every camera, in file order.
    pub cameras: Vec<Camera>,
}

impl NoiseProfiles {
    /// Read and check the file darktable reads: [`locate`].
    pub fn open(file: Option<&Path>) -> Result<NoiseProfiles> {
        Self::read(&locate(file)?)
    }

    /// Read and check `path`.
    pub fn read(path: &Path) -> Result<NoiseProfiles> {
        let text = std::fs::read_to_string(path).map_err(|e| NoiseError::Profile {
            name: "darktable".into(),
            reason: format!("cannot read {}: {e}", path.display()),
        })?;
        Self::parse(&text, path)
    }

    /// Parse and check `text`, darktable's format; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<NoiseProfiles> {
        let bad = |reason: String| NoiseError::Profile {
            name: "darktable".into(),
            reason: format!("{}: {reason}", path.display()),
        };
        let root: Value = serde_json::from_str(text).map_err(|e| {
            bad(format!(
                "not darktable's noiseprofiles.json (invalid JSON: {e})"
            ))
        })?;
        let version = root
            .get("version")
            .ok_or_else(|| bad("no \"version\": not darktable's noiseprofiles.json".into()))?
            .as_i64()
            .ok_or_else(|| bad("\"version\" is not an integer".into()))?;
        if version != FORMAT_VERSION {
            return Err(bad(format!(
                "format version {version}; pgrf reads darktable's format version {FORMAT_VERSION}"
            )));
        }
        let makers = root
            .get("noiseprofiles")
            .and_then(Value::as_array)
            .ok_or_else(|| bad("\"noiseprofiles\" is missing or not an array".into()))?;
        let mut cameras = Vec::new();
        for (i, m) in makers.iter().enumerate() {
            let maker = str_member(m, "maker")
                .map_err(|r| bad(format!("maker {} of {}: {r}", i + 1, makers.len())))?;
            let models = m.get("models").and_then(Value::as_array).ok_or_else(|| {
                bad(format!(
                    "maker \"{maker}\": `models` is missing or not an array"
                ))
            })?;
            for (j, md) in models.iter().enumerate() {
                let model = str_member(md, "model").map_err(|r| {
                    bad(format!(
                        "maker \"{maker}\", model {} of {}: {r}",
                        j + 1,
                        models.len()
                    ))
                })?;
                let comment = md.get("comment").and_then(Value::as_str).map(String::from);
                let at = format!("{maker} {model}");
                let profiles = md
                    .get("profiles")
                    .and_then(Value::as_array)
                    .ok_or_else(|| bad(format!("{at}: `profiles` is missing or not an array")))?;
                let mut entries = Vec::with_capacity(profiles.len());
                for (k, p) in profiles.iter().enumerate() {
                    let entry = parse_entry(p).map_err(|r| {
                        let name = p
                            .get("name")
                            .and_then(Value::as_str)
                            .map(|n| format!(" (\"{n}\")"))
                            .unwrap_or_default();
                        bad(format!(
                            "{at}, entry {} of {}{name}: {r}",
                            k + 1,
                            profiles.len()
                        ))
                    })?;
                    entries.push(entry);
                }
                cameras.push(Camera {
                    maker: maker.clone(),
                    model,
                    comment,
                    entries,
                });
            }
        }
        Ok(NoiseProfiles {
            path: path.to_path_buf(),
            version,
            cameras,
        })
    }

    /// The camera `query` names ("MAKER MODEL", case-insensitive), or an
    /// error naming the three closest.
    pub fn find(&self, query: &str) -> Result<&Camera> {
        let query = unquote(query);
        if let Some(c) = self.cameras.iter().find(|c| c.answers_to(query)) {
            return Ok(c);
        }
        let q = normalise(query);
        let mut scored: Vec<(usize, String)> = self
            .cameras
            .iter()
            .map(|c| {
                let n = c.name();
                (edit_distance(&q, &normalise(&n)), n)
            })
            .collect();
        scored.sort();
        scored.dedup_by(|x, y| x.1 == y.1);
        let closest: Vec<String> = scored
            .iter()
            .take(3)
            .map(|(_, n)| format!("\"{n}\""))
            .collect();
        Err(NoiseError::Profile {
            name: format!("darktable:{query}"),
            reason: format!(
                "no such camera in {} (closest: {}; `pgrf profiles list --darktable` lists all {})",
                self.path.display(),
                if closest.is_empty() {
                    "none, the file has no cameras".into()
                } else {
                    closest.join(", ")
                },
                self.cameras.len()
            ),
        })
    }

    /// pgrf's profile of the camera `query` names (module documentation).
    pub fn profile(&self, query: &str) -> Result<CameraProfile> {
        let cam = self.find(query)?;
        let name = format!("darktable:{}", cam.name());
        let bad = |reason: String| NoiseError::Profile {
            name: name.clone(),
            reason,
        };
        let measured = cam.measured();
        if measured.is_empty() {
            return Err(bad(format!(
                "every entry of it in {} is marked \"skip\"",
                self.path.display()
            )));
        }
        for m in &measured {
            if !(m.a.is_finite() && m.a > 0.0) {
                return Err(bad(format!(
                    "green a = {} at ISO {} in {}: the variance must grow with the signal (a > 0; darktable's profiling tool refuses a negative green slope)",
                    m.a,
                    m.iso,
                    self.path.display()
                )));
            }
            if !m.b.is_finite() {
                return Err(bad(format!(
                    "green b = {} at ISO {} in {} is not a number",
                    m.b,
                    m.iso,
                    self.path.display()
                )));
            }
        }
        let rows: Vec<PgRow> = grid(&measured)
            .into_iter()
            .map(|iso| {
                let m = interpolate(&measured, iso);
                let (s, o) = m.photosite();
                PgRow { iso, s, o }
            })
            .collect();
        let isos: Vec<String> = measured.iter().map(|m| m.iso.to_string()).collect();
        let notes = fit_notes(&measured);
        let comment = cam
            .comment
            .as_deref()
            .map(|c| format!(", \"{c}\""))
            .unwrap_or_default();
        let source = format!(
            "darktable noiseprofiles.json ({}, format version {}): {}{comment}, measured at ISO {}; photosite variance = {VARIANCE_FACTOR} x darktable's green a x + b (the variance its profiling chain, Haar HH of a PPG-demosaiced image, leaves), interpolated linearly in ISO as darktable does; normalised numbers stated on a nominal 14-bit scale (white - black = {DN_RANGE} DN, black not known); Poisson-Gaussian only: no row noise, no fixed pattern, no heavy-tailed (Tukey) read noise, no dark current{}",
            self.path.display(),
            self.version,
            cam.name(),
            isos.join(", "),
            notes.iter().map(|n| format!("; {n}")).collect::<String>()
        );
        poisson_gaussian_table(
            &name,
            &collapse(&cam.maker),
            &collapse(&cam.model),
            &rows,
            DN_RANGE,
            None,
            source,
        )
    }
}

impl Camera {
    /// The measured ISOs, darktable's numbers and pgrf's, as `pgrf profiles
    /// show darktable:CAMERA` prints them: a heading, column names, a row
    /// per ISO.
    pub fn measured_lines(&self) -> Vec<String> {
        let mut lines = vec![
            format!(
                "table     measured ISOs (between them a and b are linear in ISO, as darktable interpolates); S = {VARIANCE_FACTOR} a, O = {VARIANCE_FACTOR} max(b, 0), K = S x {DN_RANGE}, sigma = sqrt(O) x {DN_RANGE}"
            ),
            format!(
                "  {:>7}  {:>12}  {:>12}  {:>11}  {:>14}",
                "ISO", "a (green)", "b (green)", "K (DN/e-)", "read sigma (DN)"
            ),
        ];
        for m in &self.measured() {
            let (k, sigma) = m.gain_and_read();
            let mut notes = Vec::new();
            if m.b < 0.0 {
                notes.push("b < 0: no read noise resolved".to_string());
            }
            if m.entries > 1 {
                notes.push(format!("{} entries averaged", m.entries));
            }
            lines.push(format!(
                "  {:>7}  {:>12.5e}  {:>12.5e}  {:>11.5}  {:>14.4}{}",
                m.iso,
                m.a,
                m.b,
                k,
                sigma,
                if notes.is_empty() {
                    String::new()
                } else {
                    format!("  ({})", notes.join("; "))
                }
            ));
        }
        lines
    }
}

/// What a profile's source says of its fits: ISOs whose read noise came out
/// negative (used as 0) and ISOs whose entries were averaged.
fn fit_notes(measured: &[Measured]) -> Vec<String> {
    let mut notes = Vec::new();
    let no_read: Vec<String> = measured
        .iter()
        .filter(|m| m.b < 0.0)
        .map(|m| m.iso.to_string())
        .collect();
    if !no_read.is_empty() {
        notes.push(format!(
            "b < 0 at ISO {}: the fit resolved no read noise there, pgrf uses 0",
            no_read.join(", ")
        ));
    }
    let repeated: Vec<String> = measured
        .iter()
        .filter(|m| m.entries > 1)
        .map(|m| format!("{} ({}x)", m.iso, m.entries))
        .collect();
    if !repeated.is_empty() {
        notes.push(format!(
            "entries at one ISO averaged: ISO {}",
            repeated.join(", ")
        ));
    }
    notes
}

/// `--profile darktable:SPEC`: the camera SPEC names in the file [`locate`]
/// finds (`file`, else darktable's install).
pub fn load(spec: &str, file: Option<&Path>) -> Result<CameraProfile> {
    NoiseProfiles::open(file)?.profile(spec)
}

/// A camera pgrf measured (`pgrf calibrate`), as one entry of darktable's
/// `noiseprofiles.json`: the inverse of [`Measured::photosite`].
///
/// darktable's a and b are the variance its profiling chain leaves (Haar HH
/// of a PPG-demosaiced image), [`VARIANCE_FACTOR`] times lower than a
/// photosite's, so the entry holds a = S / 12.9 and b = O / 12.9 for each of
/// red, green and blue: a photosite's noise has one gain whatever its colour,
/// and darktable's profiled denoise reads the green values only ("only use
/// green channel + wb for now", src/iop/denoiseprofile.c). Reading the entry
/// back with `--profile darktable:` gives S and O again.
#[derive(Clone, Debug, PartialEq)]
pub struct Export {
    /// The maker as darktable names it (rawspeed's clean name, which is
    /// rawler's: "Sony", "Canon").
    pub maker: String,
    /// The model as darktable names it ("ILCE-7SM2", "EOS 550D").
    pub model: String,
    /// The ISO the camera was measured at.
    pub iso: u32,
    /// Photosite variance per unit of normalised signal (the DNG
    /// NoiseProfile's S).
    pub s: f64,
    /// Photosite variance without signal (the DNG NoiseProfile's O).
    pub o: f64,
    /// The model's `comment`: who measured it, and how.
    pub comment: String,
}

impl Export {
    /// The entry's `name`, darktable's style: "Sony ILCE-7SM2 iso 1600".
    pub fn entry_name(&self) -> String {
        format!(
            "{} {} iso {}",
            collapse(&self.maker),
            collapse(&self.model),
            self.iso
        )
    }

    fn check(&self) -> Result<()> {
        let bad = |reason: String| NoiseError::Profile {
            name: "darktable export".into(),
            reason,
        };
        if collapse(&self.maker).is_empty() || collapse(&self.model).is_empty() {
            return Err(bad(format!(
                "the frames name no camera (maker \"{}\", model \"{}\"): darktable finds an entry by maker and model",
                self.maker, self.model
            )));
        }
        if self.iso == 0 {
            return Err(bad("no ISO: darktable finds an entry by ISO".into()));
        }
        if !(self.s.is_finite() && self.s > 0.0 && self.o.is_finite() && self.o >= 0.0) {
            return Err(bad(format!(
                "noise S = {}, O = {}: darktable needs S > 0 and O >= 0",
                self.s, self.o
            )));
        }
        Ok(())
    }

    /// The entry as darktable writes one (`name`, `iso`, `a`, `b`).
    fn entry(&self) -> Value {
        let (a, b) = (self.s / VARIANCE_FACTOR, self.o / VARIANCE_FACTOR);
        serde_json::json!({
            "name": self.entry_name(),
            "iso": self.iso,
            "a": [a, a, a],
            "b": [b, b, b],
        })
    }

    /// A whole `noiseprofiles.json` (format version 0) holding this entry
    /// alone: what darktable's `--noiseprofiles FILE` option reads.
    pub fn file(&self) -> Result<String> {
        self.merge_into(None, Path::new("(new file)"))
            .map(|(text, _)| text)
    }

    /// `existing` (the text of a darktable `noiseprofiles.json`, checked as
    /// darktable checks it; None: a new file) with this entry added: under
    /// the maker and model with exactly these names (added where missing),
    /// replacing the entries of that camera at this ISO; everything else is
    /// kept as it was. Returns the new text and how many entries were
    /// replaced.
    pub fn merge_into(&self, existing: Option<&str>, path: &Path) -> Result<(String, usize)> {
        self.check()?;
        let mut root = match existing {
            None => serde_json::json!({"version": FORMAT_VERSION, "noiseprofiles": []}),
            Some(text) => {
                NoiseProfiles::parse(text, path)?;
                serde_json::from_str(text).expect("checked by parse")
            }
        };
        let (maker, model) = (collapse(&self.maker), collapse(&self.model));
        let makers = root["noiseprofiles"]
            .as_array_mut()
            .expect("checked by parse");
        let maker_entry = find_or_add(makers, "maker", &maker, "models");
        let models = maker_entry["models"]
            .as_array_mut()
            .expect("checked by parse");
        let entry = find_or_add(models, "model", &model, "profiles");
        entry["comment"] = Value::String(self.comment.clone());
        let profiles = entry["profiles"].as_array_mut().expect("checked by parse");
        let before = profiles.len();
        profiles.retain(|p| p["iso"].as_f64() != Some(self.iso as f64));
        let replaced = before - profiles.len();
        let at = profiles
            .iter()
            .position(|p| p["iso"].as_f64().is_some_and(|i| i > self.iso as f64))
            .unwrap_or(profiles.len());
        profiles.insert(at, self.entry());
        let mut text = serde_json::to_string_pretty(&root).expect("JSON values serialise");
        text.push('\n');
        Ok((text, replaced))
    }
}

/// The object of `list` whose `key` is `name`, added as `{key: name,
/// children: []}` at the end when there is none (a maker's `models`, a
/// model's `profiles`).
fn find_or_add<'a>(
    list: &'a mut Vec<Value>,
    key: &str,
    name: &str,
    children: &str,
) -> &'a mut Value {
    let i = match list.iter().position(|v| v[key] == name) {
        Some(i) => i,
        None => {
            list.push(serde_json::json!({ key: name, children: [] }));
            list.len() - 1
        }
    };
    &mut list[i]
}

/// darktable's measurement at `iso` inside the measured range: the entry
/// there, else a and b linear in ISO between the neighbours
/// (`dt_noiseprofile_interpolate`).
fn interpolate(measured: &[Measured], iso: u32) -> Measured {
    let j = measured
        .iter()
        .position(|m| m.iso >= iso)
        .expect("inside the measured range");
    if measured[j].iso == iso || j == 0 {
        return measured[j];
    }
    let (p, q) = (&measured[j - 1], &measured[j]);
    let t = (iso - p.iso) as f64 / (q.iso - p.iso) as f64;
    Measured {
        iso,
        a: (1.0 - t) * p.a + t * q.a,
        b: (1.0 - t) * p.b + t * q.b,
        entries: 1,
    }
}

/// The ISOs of the profile's table: every measured ISO and, between two,
/// integer ISOs at most [`GRID_STEP`] apart (every integer where that step
/// is less than 1).
fn grid(measured: &[Measured]) -> Vec<u32> {
    let mut out = vec![measured[0].iso];
    for w in measured.windows(2) {
        let (lo, hi) = (w[0].iso, w[1].iso);
        let mut cur = lo;
        loop {
            let next = ((cur as f64 * GRID_STEP).floor() as u32).max(cur + 1);
            if next >= hi {
                break;
            }
            out.push(next);
            cur = next;
        }
        out.push(hi);
    }
    out
}

/// A member of darktable's JSON that is missing or of the wrong type: the
/// maker, model or entry holding it says where.
#[derive(Debug, thiserror::Error)]
enum MemberFault {
    /// Not a JSON object.
    #[error("not an object")]
    NotObject,
    /// A member that is absent.
    #[error("missing `{0}`")]
    Missing(&'static str),
    /// A member that is not a string.
    #[error("`{0}` is not a string")]
    NotString(&'static str),
    /// An ISO that is not a positive integer.
    #[error("`iso` must be a positive integer, got {0}")]
    Iso(Value),
    /// A coefficient list that is not an array.
    #[error("`{0}` is not an array")]
    NotArray(&'static str),
    /// A coefficient list without one value per colour.
    #[error("`{key}` has {count} values, darktable needs 3 (red, green, blue)")]
    Count {
        /// `a` or `b`.
        key: &'static str,
        /// How many it has.
        count: usize,
    },
    /// A coefficient that is not a number.
    #[error("`{key}[{index}]` is not a number: {value}")]
    NotNumber {
        /// `a` or `b`.
        key: &'static str,
        /// Its place in the list.
        index: usize,
        /// The value.
        value: Value,
    },
    /// A `skip` that is not a boolean.
    #[error("`skip` is not true or false: {0}")]
    Skip(Value),
}

/// One entry's fields, checked as darktable's verification checks them,
/// plus numbers where numbers belong.
fn parse_entry(p: &Value) -> std::result::Result<Entry, MemberFault> {
    if !p.is_object() {
        return Err(MemberFault::NotObject);
    }
    let name = str_member(p, "name")?;
    let iso_v = p.get("iso").ok_or(MemberFault::Missing("iso"))?;
    let iso = iso_v
        .as_f64()
        .filter(|v| v.fract() == 0.0 && *v >= 1.0 && *v <= u32::MAX as f64)
        .map(|v| v as u32)
        .ok_or_else(|| MemberFault::Iso(iso_v.clone()))?;
    let a = triple(p, "a")?;
    let b = triple(p, "b")?;
    let skip = match p.get("skip") {
        None => false,
        Some(v) => v.as_bool().ok_or_else(|| MemberFault::Skip(v.clone()))?,
    };
    Ok(Entry {
        name,
        iso,
        a,
        b,
        skip,
    })
}

/// An entry's coefficients `key` (`a` or `b`): one number per colour.
fn triple(p: &Value, key: &'static str) -> std::result::Result<[f64; 3], MemberFault> {
    let v = p
        .get(key)
        .ok_or(MemberFault::Missing(key))?
        .as_array()
        .ok_or(MemberFault::NotArray(key))?;
    if v.len() != 3 {
        return Err(MemberFault::Count {
            key,
            count: v.len(),
        });
    }
    let mut out = [0.0; 3];
    for (index, x) in v.iter().enumerate() {
        out[index] = x.as_f64().ok_or_else(|| MemberFault::NotNumber {
            key,
            index,
            value: x.clone(),
        })?;
    }
    Ok(out)
}

fn str_member(v: &Value, key: &'static str) -> std::result::Result<String, MemberFault> {
    v.get(key)
        .ok_or(MemberFault::Missing(key))?
        .as_str()
        .map(String::from)
        .ok_or(MemberFault::NotString(key))
}

/// `s` without one pair of surrounding quotes (a name quoted twice over).
fn unquote(s: &str) -> &str {
    let t = s.trim();
    for q in ['"', '\''] {
        if let Some(inner) = t.strip_prefix(q).and_then(|x| x.strip_suffix(q)) {
            return inner;
        }
    }
    t
}

/// Words joined by single spaces.
fn collapse(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Words joined by single spaces, lower case: what names are compared by.
fn normalise(s: &str) -> String {
    collapse(s).to_lowercase()
}

/// Levenshtein distance over characters.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, &cb) in b.iter().enumerate() {
            cur[j + 1] = (prev[j] + usize::from(ca != cb))
                .min(prev[j + 1] + 1)
                .min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(iso: u32, a: f64, b: f64) -> Measured {
        Measured {
            iso,
            a,
            b,
            entries: 1,
        }
    }

    #[test]
    fn the_grid_holds_every_measured_iso_and_steps_of_at_most_half_a_percent() {
        let ms = [m(50, 1.0, 0.0), m(100, 2.0, 0.0), m(204800, 3.0, 0.0)];
        let g = grid(&ms);
        assert_eq!(g[0], 50);
        assert!(g.contains(&100) && *g.last().unwrap() == 204800);
        // Every integer from 50 to 200 (a 0.5 % step is less than 1 there).
        assert!((50..=200).all(|i| g.contains(&i)));
        for w in g.windows(2) {
            assert!(w[1] > w[0]);
            assert!(w[1] as f64 / w[0] as f64 <= GRID_STEP || w[1] == w[0] + 1);
        }
        assert!(g.len() < 2000, "{}", g.len());
    }

    #[test]
    fn interpolation_is_darktables_linear_rule() {
        let ms = [m(100, 1e-5, -1e-7), m(400, 4e-5, 3e-7)];
        let x = interpolate(&ms, 200);
        assert!((x.a - 2e-5).abs() < 1e-18 && (x.b - (-1e-7 + 4e-7 / 3.0)).abs() < 1e-18);
        assert_eq!(interpolate(&ms, 400), ms[1]);
    }

    #[test]
    fn names_and_distances() {
        assert_eq!(edit_distance("eos 550d", "eos 500d"), 1);
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(unquote("\"Canon EOS 550D\""), "Canon EOS 550D");
        let c = Camera {
            maker: "Canon".into(),
            model: "Canon PowerShot  SX160 IS".into(),
            comment: None,
            entries: vec![],
        };
        assert_eq!(c.name(), "Canon PowerShot SX160 IS");
        assert!(c.answers_to("canon powershot sx160 is"));
        assert!(c.answers_to("Canon Canon PowerShot SX160 IS"));
    }
}
