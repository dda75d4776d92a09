//! `pgrf info`: what pgrf reads from a RAW file.

use crate::input::InputArgs;
use anyhow::Result;
use clap::Args;
use pgrf_noise::lookup::{find_noise, KnownNoise};
use pgrf_raw::stats::{plane_stats, PlaneStats};
use pgrf_raw::RawFrame;
use serde::Serialize;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// RAW file (ARW, NEF, CR2, CR3, RAF, DNG, ...) or headerless dump.
    pub file: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub input: InputArgs,
}

#[derive(Serialize)]
struct Info<'a> {
    file: String,
    make: &'a str,
    model: &'a str,
    width: usize,
    height: usize,
    cfa: String,
    /// One black level for a monochrome frame whose planes share it, else
    /// the four of R, G1, B, G2 (or the sub-lattices').
    black: Vec<f32>,
    white: u32,
    bits: u32,
    wb: Option<[f32; 3]>,
    color_matrices: &'a [pgrf_raw::ColorMatrix],
    iso: Option<u32>,
    exposure_s: Option<f64>,
    temperature_c: Option<f32>,
    /// The DNG NoiseProfile's (S, O) pairs, when the file has one.
    noise_profile: Option<&'a [[f64; 2]]>,
    /// What a noise-aware model would be told of the frame's noise
    /// (`pgrf_noise::lookup`): K, read and row noise in DN and the source,
    /// or why none was found.
    noise_parameters: serde_json::Value,
    /// FITS header fields beyond the common ones (FITS input only).
    fits: Option<&'a pgrf_raw::FitsHeader>,
    orientation: u16,
    visible_origin: [usize; 2],
    sensor_size: [usize; 2],
    planes: Vec<PlaneStats>,
}

pub fn run(a: &InfoArgs) -> Result<()> {
    let f = a.input.open(&a.file)?;
    let info = info(a, &f)?;
    if a.json {
        println!("{}", serde_json::to_string(&info)?);
        return Ok(());
    }
    print_header(&f, &info);
    print_levels(a, &f);
    print_colour(&f);
    println!("plane       min     max     mean      saturated");
    for s in &info.planes {
        println!(
            "  {:<8}{:<8}{:<8}{:<10.2}{:.4}%",
            s.plane,
            s.min,
            s.max,
            s.mean,
            100.0 * s.saturated
        );
    }
    Ok(())
}

/// What `--json` prints of `f`.
fn info<'a>(a: &InfoArgs, f: &'a RawFrame) -> Result<Info<'a>> {
    Ok(Info {
        file: a.file.display().to_string(),
        make: &f.make,
        model: &f.model,
        width: f.width,
        height: f.height,
        cfa: f.layout().to_string(),
        black: blacks(f),
        white: f.white,
        bits: f.bits,
        wb: f.wb,
        color_matrices: &f.color_matrices,
        iso: f.iso,
        exposure_s: f.exposure_s,
        temperature_c: f.temperature_c,
        noise_profile: f.noise_profile.as_deref(),
        noise_parameters: match find_noise(f, &KnownNoise::default()) {
            Ok(n) => serde_json::json!({
                "K": n.k, "read": n.read, "row": n.row, "source": n.source.to_string()
            }),
            Err(e) => serde_json::json!({ "error": e.to_string() }),
        },
        fits: f.fits.as_ref(),
        orientation: f.orientation,
        visible_origin: [f.sensor_origin.0, f.sensor_origin.1],
        sensor_size: [f.sensor_size.0, f.sensor_size.1],
        planes: plane_stats(f)?,
    })
}

/// The file, camera, geometry and layout (and a FITS file's header).
fn print_header(f: &RawFrame, info: &Info) {
    println!("file        {}", info.file);
    let camera = [info.make, info.model]
        .into_iter()
        .filter(|s| !s.is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    println!("camera      {}", or_dash(&camera));
    println!(
        "visible     {} x {} (at row {}, col {} of a {} x {} readout)",
        info.width,
        info.height,
        f.sensor_origin.0,
        f.sensor_origin.1,
        f.sensor_size.1,
        f.sensor_size.0
    );
    if f.mono {
        println!(
            "cfa         none (monochrome sensor: one plane of {} x {})",
            info.width, info.height
        );
    } else {
        println!("cfa         {}", info.cfa);
    }
    if let Some(h) = &f.fits {
        println!(
            "fits        BITPIX {}{}",
            h.bitpix,
            h.conversion
                .as_ref()
                .map(|c| format!(" ({c})"))
                .unwrap_or_default()
        );
        if let Some(g) = h.egain_e_per_adu {
            println!("egain       {g} e-/ADU (header; K = {:.4} DN/e-)", 1.0 / g);
        }
        if let Some(g) = h.gain_setting {
            println!("gain        {g} (the driver's gain setting)");
        }
        if let Some(d) = &h.date_obs {
            println!("date-obs    {d}");
        }
        if let Some((x, y)) = h.binning {
            println!("binning     {x}x{y} (XBINNING x YBINNING)");
        }
        println!(
            "row order   {}",
            match h.row_order {
                Some(r) => format!("{} (ROWORDER)", r.keyword()),
                None => "BOTTOM-UP (no ROWORDER: the FITS convention)".into(),
            }
        );
    } else {
        println!("orientation {} (EXIF)", f.orientation);
    }
}

/// Levels, ISO, exposure, temperature and the DNG noise profile.
fn print_levels(a: &InfoArgs, f: &RawFrame) {
    let opt = |v: Option<String>| v.unwrap_or_else(|| "unknown".into());
    let black = match blacks(f)[..] {
        [one] => one.to_string(),
        _ => (f.plane_names().iter().zip(f.black))
            .map(|(n, b)| format!("{n} {b}"))
            .collect::<Vec<_>>()
            .join(" "),
    };
    println!(
        "black       {black} DN{}",
        if f.fits.is_some() && a.input.black.is_none() {
            " (FITS records no black level: a bias stack measures it, --black sets one)"
        } else {
            ""
        }
    );
    println!("white       {} DN ({} bits)", f.white, f.bits);
    println!("iso         {}", opt(f.iso.map(|v| v.to_string())));
    println!("exposure    {}", opt(f.exposure_s.map(format_exposure)));
    if let Some(t) = f.temperature_c {
        println!("temperature {t:.2} °C");
    }
    if let Some(np) = &f.noise_profile {
        let pairs: Vec<String> = np
            .iter()
            .map(|[s, o]| format!("S {s:.4e} O {o:.4e}"))
            .collect();
        println!(
            "noise       DNG NoiseProfile: {} (variance S x + O, x in [0, 1])",
            pairs.join("; ")
        );
    }
    match find_noise(f, &KnownNoise::default()) {
        Ok(n) => println!("noise-aware models would use: {n}"),
        Err(e) => println!("noise-aware models would use: nothing found ({e})"),
    }
}

/// White balance and colour matrices.
fn print_colour(f: &RawFrame) {
    let opt = |v: Option<String>| v.unwrap_or_else(|| "unknown".into());
    if !f.mono {
        println!(
            "wb          {}",
            opt(f
                .wb
                .map(|w| format!("R {:.4}  G 1  B {:.4} (multipliers)", w[0], w[2])))
        );
        if f.color_matrices.is_empty() {
            println!("matrix      none");
        }
    }
    for cm in &f.color_matrices {
        println!(
            "matrix      XYZ->camera ({}): {:?}",
            cm.illuminant, cm.xyz_to_cam
        );
    }
}

/// The black levels to show: one for a monochrome frame (one signal, one
/// level) unless overrides gave its sub-lattices different ones.
fn blacks(f: &RawFrame) -> Vec<f32> {
    if f.mono && f.black.iter().all(|&b| b == f.black[0]) {
        vec![f.black[0]]
    } else {
        f.black.to_vec()
    }
}

fn or_dash(s: &str) -> &str {
    if s.is_empty() {
        "-"
    } else {
        s
    }
}

fn format_exposure(t: f64) -> String {
    if t < 1.0 {
        format!("1/{:.0} s ({t:.6} s)", 1.0 / t)
    } else {
        format!("{t} s")
    }
}
