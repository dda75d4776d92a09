//! Reading a folder of frames into per-exposure streaming statistics.
//!
//! Frames are decoded on worker threads while the main thread accumulates,
//! through a channel of capacity two, so memory holds a few frames however
//! long the stack (flats: one more per exposure, the first of a pair).
//! Every frame must agree with the first in size, CFA, ISO and (within an
//! exposure group) exposure; the first that does not is named in the error,
//! and nothing is written.

use crate::error::{CalibError, FrameField, Result};
use crate::stats::PixelStats;
use pgrf_raw::{decode_file, pack_u16, Cfa, LevelOverrides, RawFrame, RowOrder};
use std::path::{Path, PathBuf};

/// What every frame of a calibration must share.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameKey {
    /// Frame width in pixels.
    pub width: usize,
    /// Frame height in pixels.
    pub height: usize,
    pub(crate) cfa: Cfa,
    /// A monochrome sensor ([`RawFrame::mono`]): `cfa` only orders the
    /// sub-lattices, and the record says "mono".
    pub(crate) mono: bool,
    /// The frames are FITS files: masters are written as FITS.
    pub fits: bool,
    /// The order the frames' rows are stored in ([`RawFrame::row_order`]):
    /// the masters keep it and say so.
    pub row_order: RowOrder,
    /// The FITS frames' XBINNING x YBINNING, when they state it: the
    /// masters keep it, and lights are checked against it.
    pub binning: Option<(u32, u32)>,
    pub(crate) iso: Option<u32>,
    /// Black level in DN of the planes R, G1, B, G2.
    pub black: [f32; 4],
    pub(crate) white: u32,
    pub(crate) make: String,
    pub(crate) model: String,
}

impl FrameKey {
    pub(crate) fn of(f: &RawFrame) -> FrameKey {
        FrameKey {
            width: f.width,
            height: f.height,
            cfa: f.cfa,
            mono: f.mono,
            fits: f.fits.is_some(),
            row_order: f.row_order(),
            binning: f.fits.as_ref().and_then(|h| h.binning),
            iso: f.iso,
            black: f.black,
            white: f.white,
            make: f.make.clone(),
            model: f.model.clone(),
        }
    }

    /// The filter layout as the record names it: "mono" or the CFA's name.
    pub(crate) fn layout(&self) -> &'static str {
        if self.mono {
            "mono"
        } else {
            self.cfa.name()
        }
    }

    /// Why `other` cannot join a stack described by `self`: what differs,
    /// the stack's value and `other`'s.
    fn mismatch(&self, other: &FrameKey) -> Option<(FrameField, String, String)> {
        if (self.width, self.height) != (other.width, other.height) {
            let size = |k: &FrameKey| format!("{}x{}", k.width, k.height);
            return Some((FrameField::Size, size(self), size(other)));
        }
        if (self.cfa, self.mono) != (other.cfa, other.mono) {
            return Some((FrameField::Cfa, self.layout().into(), other.layout().into()));
        }
        if self.row_order != other.row_order {
            return Some((
                FrameField::RowOrder,
                self.row_order.keyword().into(),
                other.row_order.keyword().into(),
            ));
        }
        if self.binning != other.binning {
            return Some((
                FrameField::Binning,
                binning_name(self.binning),
                binning_name(other.binning),
            ));
        }
        if self.iso != other.iso {
            let s = |i: Option<u32>| {
                i.map(|v| format!("ISO {v}"))
                    .unwrap_or_else(|| "no ISO".into())
            };
            return Some((FrameField::Iso, s(self.iso), s(other.iso)));
        }
        if (self.make.as_str(), self.model.as_str()) != (other.make.as_str(), other.model.as_str())
        {
            let camera = |k: &FrameKey| format!("{} {}", k.make, k.model);
            return Some((FrameField::Camera, camera(self), camera(other)));
        }
        None
    }
}

/// A binning as messages name it: "2x2", or "none stated".
pub(crate) fn binning_name(b: Option<(u32, u32)>) -> String {
    match b {
        Some((x, y)) => format!("{x}x{y}"),
        None => "none stated".into(),
    }
}

/// Frames of one exposure time.
#[derive(Clone, Debug)]
pub(crate) struct Group {
    pub(crate) exposure_s: f64,
    pub(crate) stats: PixelStats,
    pub(crate) files: Vec<PathBuf>,
    /// Each frame's spatial mean, DN (black included), in file order.
    pub(crate) frame_means: Vec<f64>,
    /// Each frame's noise proxy ([`frame_noise`]), DN.
    pub(crate) frame_noise: Vec<f64>,
    /// Frames 1 and 2, 3 and 4, ... of the group: the temporal variance of
    /// each pair ([`pair_variance`]), DN^2.
    pub(crate) pair_vars: Vec<f64>,
    /// The first frame of a pair, waiting for its second (flats only).
    held: Option<Vec<u16>>,
}

/// A frame's noise, from itself alone: the standard deviation of the
/// differences of horizontally neighbouring pixels of a plane over sqrt(2),
/// DN. The fixed pattern's part of it is the same in every frame, so across
/// a stack it moves with the temporal noise only: a frame read with more
/// noise than the others stands out. `pw`: the packed planes' width.
pub(crate) fn frame_noise(data: &[u16], pw: usize) -> f64 {
    let (mut s, mut ss, mut n) = (0.0f64, 0.0f64, 0usize);
    for row in data.chunks_exact(pw) {
        for w in row.windows(2) {
            let d = w[1] as f64 - w[0] as f64;
            s += d;
            ss += d * d;
            n += 1;
        }
    }
    if n < 2 {
        return 0.0;
    }
    let m = s / n as f64;
    ((ss / n as f64 - m * m).max(0.0) / 2.0).sqrt()
}

/// A frame whose mean or noise stands out from its exposure's frames.
#[derive(Clone, Debug, PartialEq)]
pub struct OddFrame {
    /// The frame's file.
    pub file: PathBuf,
    /// What stands out, with its robust z-score, for one line.
    pub why: String,
}

/// How far (in robust standard deviations) a frame's mean or noise may lie
/// from its stack's median before it is named: 5, so that among a thousand
/// well-behaved frames none is (a normal's 5-sigma tail is 6e-7).
pub const ODD_Z: f64 = 5.0;

/// The median of `x` and its values' robust z-scores: (x - median) /
/// (1.4826 MAD), the MAD floored at 1e-9 of the median's size so that
/// identical values do not divide by zero.
pub(crate) fn robust_z(x: &[f64]) -> (f64, Vec<f64>) {
    let (med, sd) = pgrf_core::stats::median_and_robust_sd(&mut x.to_vec());
    let scale = sd.max(1e-9 * med.abs().max(1.0));
    (med, x.iter().map(|a| (a - med) / scale).collect())
}

impl Stack {
    /// The frames whose mean or noise lies more than [`ODD_Z`] robust
    /// standard deviations from the rest of their exposure (groups of four
    /// frames or more; with fewer a median says little). A bias frame
    /// read 4 DN above the others, or one with twice the read noise, is
    /// named; a flat lamp's slow drift is not (its frames spread evenly).
    pub fn odd_frames(&self, kind: &str) -> Vec<OddFrame> {
        let mut odd: std::collections::BTreeMap<PathBuf, Vec<String>> = Default::default();
        for g in self.groups.iter().filter(|g| g.files.len() >= 4) {
            for (what, values) in [("mean", &g.frame_means), ("noise", &g.frame_noise)] {
                let (med, z) = robust_z(values);
                for (i, z) in z.into_iter().enumerate() {
                    if z.abs() > ODD_Z {
                        odd.entry(g.files[i].clone()).or_default().push(format!(
                            "{what} {:.2} DN against the {} s frames' median {med:.2} (robust z {z:.1})",
                            values[i], g.exposure_s
                        ));
                    }
                }
            }
        }
        odd.into_iter()
            .map(|(file, why)| OddFrame {
                why: format!("{kind} frame {}: {}", file.display(), why.join("; ")),
                file,
            })
            .collect()
    }
}

/// EMVA 1288's temporal variance from two frames A and B of the same scene:
/// half the spatial variance of A - B, where the spatial mean of A - B is
/// removed, so a change of the light (or of the offset) between the two
/// frames, which moves every pixel alike, does not count as noise, while a
/// per-pixel temporal variance over a stack adds the light's drift to
/// every pixel's noise. DN^2.
pub(crate) fn pair_variance(a: &[u16], b: &[u16]) -> f64 {
    let n = a.len() as f64;
    let (s, ss) = a.iter().zip(b).fold((0.0f64, 0.0f64), |(s, ss), (&x, &y)| {
        let d = x as f64 - y as f64;
        (s + d, ss + d * d)
    });
    let m = s / n;
    (ss / n - m * m) * n / (n - 1.0) / 2.0
}

/// A decoded stack: groups by exposure, sorted by exposure time.
#[derive(Clone, Debug)]
pub struct Stack {
    /// What all its frames share (size, CFA, ISO, levels, camera).
    pub key: FrameKey,
    pub(crate) groups: Vec<Group>,
    /// Temporal samples of a sparse grid of pixels (one series per tapped
    /// pixel, first exposure group only), kept for the per-pixel normality check.
    pub(crate) tap: Vec<Vec<f32>>,
    /// The capture temperature of every frame that records one, degrees C.
    pub temperatures: Vec<(PathBuf, f32)>,
    /// The first frames' centre crops for the noise bank
    /// (`bank::bank_crop`), read with [`ReadOptions::with_bank`].
    pub(crate) bank_crops: Vec<ndarray::Array3<u16>>,
}

/// Options for reading one stack.
pub struct ReadOptions<'a> {
    /// "bias", "dark" or "flat", for messages.
    pub kind: &'a str,
    /// Frames must match this (e.g. the bias stack's key) when given.
    pub expect: Option<&'a FrameKey>,
    /// All frames must share one exposure time (bias).
    pub single_exposure: bool,
    /// Exposure time must be in the metadata (dark, flat).
    pub need_exposure: bool,
    /// Frames each exposure needs: 2 where a per-pixel variance is taken
    /// (bias, flat), 1 where only the mean is (a dark ladder of one frame
    /// per exposure time is how people shoot them).
    pub per_exposure: usize,
    /// How many pixels to keep temporal samples of (0 for none).
    pub tap_pixels: usize,
    /// Pair the frames of each exposure for `pair_variance` (bias and
    /// flats: one more frame held per exposure while its pair is read).
    pub pairs: bool,
    /// Called once per frame accumulated.
    pub progress: &'a dyn pgrf_core::Progress,
    /// Keep the first frames' centre crops for the noise bank.
    pub bank: bool,
}

impl<'a> ReadOptions<'a> {
    /// A bias stack: one exposure, none needed, at least two frames;
    /// `pairs` for the pair variance, `tap_pixels` pixels tapped.
    pub fn bias(tap_pixels: usize, pairs: bool, progress: &'a dyn pgrf_core::Progress) -> Self {
        ReadOptions {
            kind: "bias",
            expect: None,
            single_exposure: true,
            need_exposure: false,
            per_exposure: 2,
            tap_pixels,
            pairs,
            progress,
            bank: false,
        }
    }

    /// These options, also keeping the crops the noise bank is made of
    /// (the calibration's `noise_bank`) as the frames are decoded.
    pub fn with_bank(self) -> Self {
        ReadOptions { bank: true, ..self }
    }

    /// A flat or dark stack read after the bias: several exposures, each
    /// frame matching the bias frames' key `expect`.
    pub fn after_bias(
        kind: &'a str,
        expect: &'a FrameKey,
        per_exposure: usize,
        pairs: bool,
        progress: &'a dyn pgrf_core::Progress,
    ) -> Self {
        ReadOptions {
            kind,
            expect: Some(expect),
            single_exposure: false,
            need_exposure: true,
            per_exposure,
            tap_pixels: 0,
            pairs,
            progress,
            bank: false,
        }
    }
}

/// Decode and accumulate `files`.
pub fn read_stack(files: &[PathBuf], opt: &ReadOptions) -> Result<Stack> {
    if files.len() < 2 && opt.per_exposure >= 2 {
        return Err(CalibError::TooFewFrames {
            stack: opt.kind.into(),
            count: files.len(),
            needed: 2,
        });
    }
    let (tx, rx) = std::sync::mpsc::sync_channel::<Result<(usize, RawFrame)>>(2);
    let next = std::sync::atomic::AtomicUsize::new(0);
    std::thread::scope(|scope| -> Result<Stack> {
        // Decoders take files in index order from a shared counter, so a
        // frame is never more than about `threads` places ahead of the next
        // one to accumulate; the reader below restores file order, which
        // makes the sums (and so the calibration's bytes) independent of
        // thread timing while memory stays at a few frames.
        let threads = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(2)
            .min(files.len());
        for _ in 0..threads {
            let tx = tx.clone();
            let next = &next;
            scope.spawn(move || loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if i >= files.len() {
                    break;
                }
                let r = decode_file(&files[i], &LevelOverrides::default())
                    .map(|fr| (i, fr))
                    .map_err(Into::into);
                let failed = r.is_err();
                // A closed channel means the reader stopped on an error: stop too.
                if tx.send(r).is_err() || failed {
                    break;
                }
            });
        }
        drop(tx);
        let mut acc = Accumulator::new(opt);
        for msg in in_file_order(rx) {
            let (i, frame) = msg?;
            acc.add(&files[i], &frame)?;
        }
        acc.finish()
    })
}

/// The decoded frames in file order: frames that arrive early wait until
/// those before them are in. Owns the receiver, so an early error return
/// drops it and unblocks the decoders before their scope joins them.
fn in_file_order(
    rx: std::sync::mpsc::Receiver<Result<(usize, RawFrame)>>,
) -> impl Iterator<Item = Result<(usize, RawFrame)>> {
    let mut pending = std::collections::BTreeMap::new();
    let mut want = 0usize;
    std::iter::from_fn(move || loop {
        if let Some(frame) = pending.remove(&want) {
            want += 1;
            return Some(Ok((want - 1, frame)));
        }
        match rx.recv() {
            Ok(Ok((i, frame))) => {
                pending.insert(i, frame);
            }
            Ok(Err(e)) => return Some(Err(e)),
            Err(_) => return None,
        }
    })
}

/// A stack being read: the frames' shared key, one group per exposure,
/// the tapped pixels' values and the frames' temperatures.
struct Accumulator<'o, 'a> {
    opt: &'o ReadOptions<'a>,
    key: Option<FrameKey>,
    groups: Vec<Group>,
    tap_index: Vec<usize>,
    tap: Vec<Vec<f32>>,
    temperatures: Vec<(PathBuf, f32)>,
    bank_crops: Vec<ndarray::Array3<u16>>,
}

impl<'o, 'a> Accumulator<'o, 'a> {
    fn new(opt: &'o ReadOptions<'a>) -> Self {
        Accumulator {
            opt,
            key: opt.expect.cloned(),
            groups: Vec::new(),
            tap_index: Vec::new(),
            tap: Vec::new(),
            temperatures: Vec::new(),
            bank_crops: Vec::new(),
        }
    }

    /// Check `frame` (read from `file`) against the stack and add it to
    /// its exposure's group.
    fn add(&mut self, file: &Path, frame: &RawFrame) -> Result<()> {
        let opt = self.opt;
        let k = FrameKey::of(frame);
        match &self.key {
            Some(want) => {
                if let Some((what, expected, found)) = want.mismatch(&k) {
                    return Err(CalibError::MismatchedFrame {
                        file: file.to_path_buf(),
                        stack: opt.kind.into(),
                        what,
                        expected,
                        found,
                    });
                }
            }
            None => self.key = Some(k),
        }
        if let Some(c) = frame.temperature_c {
            self.temperatures.push((file.to_path_buf(), c));
        }
        if opt.need_exposure && frame.exposure_s.is_none() {
            return Err(CalibError::NoExposure {
                file: file.to_path_buf(),
                stack: opt.kind.into(),
            });
        }
        let t = frame.exposure_s.unwrap_or(0.0);
        let packed = pack_u16(frame)?;
        let (ph, pw) = (packed.shape()[1], packed.shape()[2]);
        let slot = self.slot(file, t, || {
            PixelStats::new(ph, pw, frame.cfa.offsets().map(|(r, _)| r))
        })?;
        if opt.bank && slot == 0 && self.bank_crops.len() < pgrf_noise::bank::MAX_BANK_FRAMES {
            self.bank_crops.push(crate::bank::bank_crop(packed.view()));
        }
        let data = packed.as_slice().expect("standard layout");
        self.tap_pixels(slot, data);
        let g = &mut self.groups[slot];
        g.stats.push(data);
        g.files.push(file.to_path_buf());
        g.frame_means
            .push(data.iter().map(|&v| v as f64).sum::<f64>() / data.len() as f64);
        g.frame_noise.push(frame_noise(data, pw));
        if opt.pairs {
            match g.held.take() {
                Some(first) => g.pair_vars.push(pair_variance(&first, data)),
                None => g.held = Some(data.to_vec()),
            }
        }
        opt.progress.advance(1);
        Ok(())
    }

    /// The group of exposure `t`, a new one (with `stats`) if none has it
    /// yet; a second exposure in a single-exposure stack is refused.
    fn slot(&mut self, file: &Path, t: f64, stats: impl FnOnce() -> PixelStats) -> Result<usize> {
        let found = self
            .groups
            .iter()
            .position(|g| (g.exposure_s - t).abs() <= 1e-6 * t.max(1e-9));
        if let Some(s) = found {
            return Ok(s);
        }
        if self.opt.single_exposure && !self.groups.is_empty() {
            return Err(CalibError::MixedExposure {
                file: file.to_path_buf(),
                stack: self.opt.kind.into(),
                expected: self.groups[0].exposure_s,
                found: t,
            });
        }
        self.groups.push(Group {
            exposure_s: t,
            stats: stats(),
            files: Vec::new(),
            frame_means: Vec::new(),
            frame_noise: Vec::new(),
            pair_vars: Vec::new(),
            held: None,
        });
        Ok(self.groups.len() - 1)
    }

    /// Record the tapped pixels of a frame of the first exposure (chosen,
    /// evenly spaced, at the first frame).
    fn tap_pixels(&mut self, slot: usize, data: &[u16]) {
        let n = self.opt.tap_pixels;
        if n > 0 && self.tap_index.is_empty() {
            let stride = (data.len() / n).max(1);
            self.tap_index = (0..data.len()).step_by(stride).take(n).collect();
            self.tap = vec![Vec::new(); self.tap_index.len()];
        }
        if slot == 0 {
            for (t, &ix) in self.tap.iter_mut().zip(&self.tap_index) {
                t.push(data[ix] as f32);
            }
        }
    }

    /// The stack, every exposure with its frames, in exposure order.
    fn finish(mut self) -> Result<Stack> {
        let opt = self.opt;
        for g in &self.groups {
            if g.files.len() < opt.per_exposure {
                return Err(CalibError::TooFewAtExposure {
                    stack: opt.kind.into(),
                    exposure_s: g.exposure_s,
                    file: g.files[0].clone(),
                    needed: opt.per_exposure,
                });
            }
        }
        for g in &mut self.groups {
            g.held = None;
        }
        self.groups
            .sort_by(|a, b| a.exposure_s.total_cmp(&b.exposure_s));
        Ok(Stack {
            key: self.key.ok_or_else(|| CalibError::EmptyStack {
                stack: opt.kind.into(),
            })?,
            groups: self.groups,
            tap: self.tap,
            temperatures: self.temperatures,
            bank_crops: self.bank_crops,
        })
    }
}
