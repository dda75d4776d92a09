//! A virtual sensor: the PGRF model run forward with known per-pixel truth,
//! producing the bias, dark and flat-field stacks a user would capture. It is
//! how calibration is tested end to end: every estimate can be compared with
//! the map that generated the frames.
//!
//! Per pixel x (packed layout), a frame with `e` photo-electrons of light and
//! exposure t is, in DN (each random term drawn by the noise model's own
//! function: `photon_shot`, `dark_shot`, `read_noise`, `row_noise`):
//!
//!   black + bias(x) + K prnu(x) Poisson(e) + K Poisson(d(x) g(t) + c(t)) (1 + n_fp(x))
//!         + N(0, sigma_r(x)) + row(frame, sensor row) + o(frame),   rounded and clipped to 0..white,
//!
//! with o(frame) a whole-frame offset drift (`SensorSpec::frame_offset_sigma`)
//! and c(t) the dark offset (`SensorSpec::dark_offset`, reached within a
//! fraction of a second). Rounding to integers is the quantisation. Hot pixels have a dark rate far
//! above the rest. Optionally d(x) doubles every `SensorSpec::dark_doubling_c` degrees
//! (from [`DARK_REFERENCE_C`]), the read noise is Tukey-lambda instead of N(0, sigma_r(x))
//! (`SensorSpec::read_tukey_lambda`), and random telegraph pixels add +- half their
//! jump, drawn per frame (`SensorSpec::rts_fraction`).

use crate::error::{NoiseError, Result};
use crate::model::{dark_shot, photon_shot, read_noise, row_noise, ReadDist};
use crate::profile::{CameraProfile, DarkLaw};
use ndarray::Array3;
use pgrf_core::seed::{open01, seeded_map, stream, Domain};
use pgrf_raw::{Cfa, RawFrame};
use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;

/// Time constant of the virtual sensor's dark offset, s.
pub const DARK_OFFSET_TAU_S: f64 = 0.05;

/// The temperature at which a virtual sensor with a doubling temperature
/// has its `dark_rate`, degrees C.
pub const DARK_REFERENCE_C: f32 = 0.0;

/// Design of a virtual sensor. The gain, read and row noise of the presets are
/// the published A7S2 numbers (PMN: K = 9.563e-4 x ISO; sigma_read, sigma_row
/// at the ISO); the per-pixel spreads (DSNU, PRNU, read-noise spread, dark
/// current, hot pixels) are not published for that camera and are the virtual
/// sensor's own design values, chosen in the range EMVA 1288 data sheets of
/// similar CMOS sensors report.
#[derive(Clone, Debug)]
pub struct SensorSpec {
    pub(crate) name: String,
    /// Frame width in pixels (even, at least 4).
    pub width: usize,
    /// Frame height in pixels (even, at least 4).
    pub height: usize,
    pub(crate) cfa: Cfa,
    /// A monochrome sensor (no colour filter, as astronomy CCDs): frames
    /// come out monochrome ([`RawFrame::mono`]); the noise is the same.
    pub mono: bool,
    pub(crate) black: f32,
    pub(crate) white: u32,
    /// ISO written into every frame's EXIF (the presets' noise is that ISO's).
    pub iso: u32,
    /// Mean system gain, DN per electron.
    pub k: f32,
    /// PRNU: relative standard deviation of the per-pixel gain.
    pub(crate) prnu: f32,
    /// DSNU: standard deviation of the per-pixel offset, DN.
    pub(crate) dsnu: f32,
    /// Median source-follower sigma, DN, and the log-normal spread around it.
    pub(crate) read_sigma: f32,
    pub(crate) read_spread: f32,
    /// Row-noise standard deviation sigma_H, DN.
    pub row_sigma: f32,
    /// Mean dark rate, electrons per sqrt(s) (sqrt law) or per s (linear law).
    pub dark_rate: f32,
    /// Relative spread of the per-pixel dark rate around `dark_rate`.
    pub(crate) dark_spread: f32,
    /// How the dark signal grows with exposure time.
    pub dark_law: DarkLaw,
    /// Dark charge every exposed frame has on top of the law, electrons
    /// (the offset c of y = a g(t) + c, as CCDs show): it builds up over
    /// the first [`DARK_OFFSET_TAU_S`] of an exposure (amp glow and
    /// clock-induced charge at the start of a readout cycle), so a bias
    /// frame of 1/8000 s has none of it and a dark of a second all of it.
    pub dark_offset: f32,
    /// Temperature the frames are taken at, degrees C, written into each
    /// frame's metadata (None: not recorded, as most cameras).
    pub temperature_c: Option<f32>,
    /// Light lost towards the corners of a flat (lens vignetting or an uneven
    /// lamp): the light falls off as 1 - v r^2, r the distance from the
    /// centre over the half-diagonal. A flat's shading, not the sensor's
    /// PRNU; EMVA 1288's high-pass non-uniformity leaves it out.
    pub vignetting: f32,
    /// Standard deviation of a whole-frame offset drawn anew for every
    /// frame, DN: the offset drift of a sensor's readout (or its cooling)
    /// from frame to frame, which moves every row alike and is not row noise.
    pub frame_offset_sigma: f32,
    /// Temperature rise that doubles the dark current, degrees C (0: the
    /// dark current does not depend on temperature): `dark_rate` holds at
    /// [`DARK_REFERENCE_C`], and a frame taken at `temperature_c` has
    /// 2^((temperature - reference) / doubling) times it.
    pub dark_doubling_c: f32,
    /// Read noise with heavy tails: Tukey-lambda of this lambda (ELD's
    /// read-noise law; negative is heavier than Gaussian) at each pixel's
    /// sigma_r as its scale, instead of a Gaussian (None).
    pub read_tukey_lambda: Option<f32>,
    /// Share of random telegraph pixels: pixels whose level jumps between
    /// two states from frame to frame (each frame draws the state), as
    /// traps in a source follower make them.
    pub rts_fraction: f32,
    /// The jump between a random telegraph pixel's two states, DN (the
    /// pixel reads +- half of it around its mean).
    pub rts_amplitude: f32,
    /// Standard deviation of N_FP.
    pub(crate) n_fp: f32,
    /// Share of hot pixels and their dark rate multiplier.
    pub(crate) hot_fraction: f32,
    pub(crate) hot_factor: f32,
    /// Seed of the sensor itself (its maps); frames have their own seeds.
    pub(crate) seed: u64,
}

impl SensorSpec {
    /// White level minus black level, DN: the signal range a frame holds
    /// before it clips (what flat-field levels must stay inside).
    pub fn dn_range(&self) -> f32 {
        self.white as f32 - self.black
    }

    /// `a7s2-iso<N>`: an A7S2-like sensor at ISO N (any ISO of the PMN table).
    pub fn preset(name: &str) -> Result<SensorSpec> {
        let iso: u32 = name
            .strip_prefix("a7s2-iso")
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| NoiseError::UnknownPreset { name: name.into() })?;
        let profile = CameraProfile::built_in("sony-a7s2").expect("built-in");
        let p = profile.params_at_iso(iso)?;
        Ok(SensorSpec {
            name: name.to_string(),
            width: 1024,
            height: 768,
            cfa: Cfa::Rggb,
            mono: false,
            black: profile.black.unwrap_or(512.0) as f32,
            white: (profile.black.unwrap_or(512.0) + profile.dn_range) as u32,
            iso,
            k: p.k as f32,
            prnu: 0.01,
            dsnu: 1.5,
            read_sigma: p.sigma_gauss as f32,
            read_spread: 0.25,
            row_sigma: p.sigma_row as f32,
            dark_rate: 1.0,
            dark_spread: 0.3,
            dark_law: DarkLaw::Sqrt,
            dark_offset: 0.0,
            frame_offset_sigma: 0.0,
            vignetting: 0.0,
            temperature_c: None,
            dark_doubling_c: 0.0,
            read_tukey_lambda: None,
            rts_fraction: 0.0,
            rts_amplitude: 0.0,
            n_fp: 0.05,
            hot_fraction: 1e-4,
            hot_factor: 50.0,
            seed: 2026,
        })
    }
}

/// The sensor's ground truth, packed `(4, H/2, W/2)`.
#[derive(Clone, Debug)]
pub struct VirtualSensor {
    /// The design the maps were drawn from.
    pub spec: SensorSpec,
    /// Per-pixel gain K prnu(x), DN per electron.
    pub(crate) gain: Array3<f32>,
    /// Fixed-pattern offset, DN.
    pub bias: Array3<f32>,
    /// Source-follower read-noise standard deviation sigma_r, DN.
    pub sigma_read: Array3<f32>,
    /// Dark rate d(x), electrons per sqrt(s) or per s (`spec.dark_law`);
    /// hot pixels included.
    pub dark_rate: Array3<f32>,
    pub(crate) n_fp: Array3<f32>,
    /// 1 where the pixel is hot.
    pub hot: Array3<f32>,
    /// The jump of each random telegraph pixel, DN (0 elsewhere).
    pub rts: Array3<f32>,
}

impl VirtualSensor {
    /// Draw the sensor's per-pixel truth from `spec` (deterministic in its
    /// seed); refuses sizes that are odd or below 4 x 4.
    pub fn new(spec: SensorSpec) -> Result<VirtualSensor> {
        if spec.width < 4 || spec.height < 4 || spec.width % 2 == 1 || spec.height % 2 == 1 {
            return Err(NoiseError::SensorSize {
                width: spec.width,
                height: spec.height,
            });
        }
        let (ph, pw) = (spec.height / 2, spec.width / 2);
        let s = spec.seed;
        let gn = |r: &mut pgrf_core::seed::BlockRng| r.sample::<f32, _>(StandardNormal);
        let (k, prnu, dsnu) = (spec.k, spec.prnu, spec.dsnu);
        let (rs, rsp) = (spec.read_sigma, spec.read_spread);
        let (dr, dsp) = (spec.dark_rate, spec.dark_spread);
        let nfp = spec.n_fp;
        let hot = seeded_map(s, 6, ph, pw, |r| {
            (open01(r) < spec.hot_fraction as f64) as u8 as f32
        });
        let mut dark_rate = seeded_map(s, 4, ph, pw, move |r| {
            dr * (dsp * gn(r) - 0.5 * dsp * dsp).exp()
        });
        ndarray::Zip::from(&mut dark_rate)
            .and(&hot)
            .for_each(|d, &h| {
                if h > 0.0 {
                    *d *= spec.hot_factor;
                }
            });
        Ok(VirtualSensor {
            gain: seeded_map(s, 1, ph, pw, move |r| k * (1.0 + prnu * gn(r))),
            bias: seeded_map(s, 2, ph, pw, move |r| dsnu * gn(r)),
            sigma_read: seeded_map(s, 3, ph, pw, move |r| rs * (rsp * gn(r)).exp()),
            dark_rate,
            n_fp: seeded_map(s, 5, ph, pw, move |r| (nfp * gn(r)).max(-0.9)),
            hot,
            rts: seeded_map(s, 7, ph, pw, move |r| {
                (open01(r) < spec.rts_fraction as f64) as u8 as f32 * spec.rts_amplitude
            }),
            spec,
        })
    }

    /// How many times its `dark_rate` the sensor's dark current is at its
    /// temperature: 2^((temperature - [`DARK_REFERENCE_C`]) / doubling), 1
    /// without a doubling temperature or a temperature.
    pub fn dark_temperature_factor(&self) -> f64 {
        match (self.spec.temperature_c, self.spec.dark_doubling_c) {
            (Some(t), d) if d > 0.0 => 2f64.powf(((t - DARK_REFERENCE_C) / d) as f64),
            _ => 1.0,
        }
    }

    /// One frame: `electrons` of uniform light (0 for bias/dark) at exposure
    /// `t` seconds. Deterministic in `seed`.
    pub fn frame(&self, electrons: f32, t: f32, seed: u64) -> Result<RawFrame> {
        let sp = &self.spec;
        let (ph, pw) = (sp.height / 2, sp.width / 2);
        let plane_rows = sp.cfa.offsets().map(|(r, _)| r);
        let mut rows = row_noise(seed, sp.height, sp.row_sigma, 1);
        if sp.frame_offset_sigma > 0.0 {
            let mut r = stream(seed, Domain::Params, 0x0ff5e7, 0);
            let o = sp.frame_offset_sigma * r.sample::<f32, _>(StandardNormal);
            rows.iter_mut().for_each(|v| *v += o);
        }
        let g = sp.dark_law.electrons(1.0, t as f64) * self.dark_temperature_factor();
        let offset = sp.dark_offset as f64 * (1.0 - (-(t as f64) / DARK_OFFSET_TAU_S).exp());
        let white = sp.white as f32;
        let (cy, cx) = (sp.height as f64 / 2.0, sp.width as f64 / 2.0);
        let r2 = cy * cy + cx * cx;
        let mut packed = Array3::<u16>::zeros((4, ph, pw));
        let gain = self.gain.as_slice().expect("standard");
        let bias = self.bias.as_slice().expect("standard");
        let sig = self.sigma_read.as_slice().expect("standard");
        let dark = self.dark_rate.as_slice().expect("standard");
        let nfp = self.n_fp.as_slice().expect("standard");
        let rts = self.rts.as_slice().expect("standard");
        let read = match sp.read_tukey_lambda {
            Some(lambda) => ReadDist::Tukey { lambda },
            None => ReadDist::Gaussian,
        };
        packed
            .as_slice_mut()
            .expect("standard")
            .par_chunks_mut(pw)
            .enumerate()
            .for_each(|(block, dst)| {
                let plane = block / ph;
                let i = block % ph;
                let mut rng = stream(seed, Domain::Pixel, plane as u64, i as u64);
                let row = rows[2 * i + plane_rows[plane]];
                for (j, d) in dst.iter_mut().enumerate() {
                    let x = block * pw + j;
                    let mut v = sp.black + bias[x] + row;
                    if electrons > 0.0 {
                        let light = if sp.vignetting > 0.0 {
                            // Packed (i, j) sits at sensor (2i, 2j) + the plane's offset.
                            let (y, xx) = (2.0 * i as f64 - cy, 2.0 * j as f64 - cx);
                            1.0 - sp.vignetting as f64 * (y * y + xx * xx) / r2
                        } else {
                            1.0
                        };
                        v += photon_shot(&mut rng, gain[x], electrons as f64 * light);
                    }
                    let de = dark[x] as f64 * g + offset;
                    if de > 0.0 {
                        v += dark_shot(&mut rng, sp.k, de, Some(nfp[x]));
                    }
                    v += read_noise(&mut rng, sig[x], read);
                    if rts[x] > 0.0 {
                        v += rts[x] * ((open01(&mut rng) < 0.5) as u8 as f32 - 0.5);
                    }
                    *d = v.round().clamp(0.0, white) as u16;
                }
            });
        let mut f = self.unpacked(&packed)?;
        f.iso = Some(sp.iso);
        f.exposure_s = Some(t as f64);
        f.temperature_c = sp.temperature_c;
        f.make = "pgrf".into();
        f.model = format!("virtual sensor {}", sp.name);
        Ok(f)
    }

    /// Packed DN `packed` as a frame of the sensor's size, layout and
    /// levels.
    fn unpacked(&self, packed: &Array3<u16>) -> Result<RawFrame> {
        let sp = &self.spec;
        let frame = |r: pgrf_raw::Result<RawFrame>| r.map_err(|error| NoiseError::Frame { error });
        let mosaic = vec![0; sp.width * sp.height];
        let template = match sp.mono {
            true => frame(RawFrame::from_mono(
                sp.width, sp.height, mosaic, sp.black, sp.white,
            ))?,
            false => frame(RawFrame::from_mosaic(
                sp.width,
                sp.height,
                mosaic,
                sp.cfa,
                [sp.black; 4],
                sp.white,
            ))?,
        };
        frame(pgrf_raw::unpack_u16(packed.view(), &template))
    }

    /// Ground truth as named maps, for a maps file.
    pub fn truth_maps(&self) -> Vec<(&'static str, &Array3<f32>)> {
        vec![
            ("gain", &self.gain),
            ("bias", &self.bias),
            ("sigma_read", &self.sigma_read),
            ("dark_rate", &self.dark_rate),
            ("n_fp", &self.n_fp),
            ("hot", &self.hot),
        ]
    }

    /// Scalar truth (what a global calibration should find), as JSON.
    pub fn truth_meta(&self) -> serde_json::Value {
        let sp = &self.spec;
        let median = |a: &Array3<f32>| pgrf_core::stats::median_finite(a) as f32;
        serde_json::json!({
            "kind": "virtual-sensor-truth",
            "preset": sp.name,
            "width": sp.width, "height": sp.height, "cfa": if sp.mono { "mono" } else { sp.cfa.name() },
            "black": sp.black, "white": sp.white, "iso": sp.iso,
            "K": sp.k, "prnu": sp.prnu, "dsnu": sp.dsnu,
            "read_sigma_median": median(&self.sigma_read),
            "row_sigma": sp.row_sigma,
            "dark_rate_mean": self.dark_rate.mean().unwrap_or(0.0),
            "dark_law": match sp.dark_law { DarkLaw::Sqrt => "sqrt", DarkLaw::Linear => "linear" },
            "dark_offset_e": sp.dark_offset,
            "frame_offset_sigma": sp.frame_offset_sigma,
            "vignetting": sp.vignetting,
            "n_fp_sigma": sp.n_fp,
            "hot_pixels": self.hot.iter().filter(|&&h| h > 0.0).count(),
            "units": "gain DN/e-; bias, sigma_read DN; dark_rate e- per sqrt(s) (sqrt law) or per s (linear law); maps packed (4, H/2, W/2) R,G1,B,G2",
            "pgrf_version": env!("CARGO_PKG_VERSION"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> VirtualSensor {
        let mut s = SensorSpec::preset("a7s2-iso1600").unwrap();
        s.width = 64;
        s.height = 48;
        VirtualSensor::new(s).unwrap()
    }

    #[test]
    fn preset_uses_the_published_a7s2_numbers() {
        let s = SensorSpec::preset("a7s2-iso1600").unwrap();
        assert!((s.k - 9.563e-4 * 1600.0).abs() < 1e-5);
        assert!((s.read_sigma - 6.29925).abs() < 1e-5);
        assert!((s.row_sigma - 0.988786).abs() < 1e-5);
        assert_eq!((s.black, s.white), (512.0, 16383));
        assert!(SensorSpec::preset("d850-iso100").is_err());
        assert!(SensorSpec::preset("a7s2-iso10").is_err());
    }

    #[test]
    fn frames_are_deterministic_and_at_the_right_level() {
        let v = small();
        let a = v.frame(1000.0, 0.01, 5).unwrap();
        assert_eq!(a.mosaic, v.frame(1000.0, 0.01, 5).unwrap().mosaic);
        assert_ne!(a.mosaic, v.frame(1000.0, 0.01, 6).unwrap().mosaic);
        let mean = a.mosaic.iter().map(|&x| x as f64).sum::<f64>() / a.mosaic.len() as f64;
        // black + K * 1000 e- (+ small dark and offsets).
        assert!((mean - (512.0 + 1530.08)).abs() < 10.0, "{mean}");
        assert_eq!(a.iso, Some(1600));
        assert_eq!(a.exposure_s, Some(0.01f32 as f64));
    }
}
