//! `pgrf info`: what pgrf reads from a RAW file.

use crate::input::InputArgs;
use anyhow::Result;
use clap::Args;
use pgrf_noise::describe::FrameInfo;
use pgrf_raw::RawFrame;
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

pub fn run(a: &InfoArgs, g: &crate::Globals) -> Result<()> {
    let f = a.input.open(&a.file)?;
    let info = FrameInfo::of(&a.file, &f, g.darktable)?;
    if a.json {
        println!("{}", serde_json::to_string(&info)?);
        return Ok(());
    }
    print_header(&f, &info);
    print_levels(a, &f, &info);
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

/// The file, camera, geometry and layout (and a FITS file's header).
fn print_header(f: &RawFrame, info: &FrameInfo) {
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
        for (label, v) in [
            ("imagetyp", &h.image_type),
            ("date-obs", &h.date_obs),
            ("object", &h.object),
            ("filter", &h.filter),
        ] {
            if let Some(v) = v {
                println!("{label:<11} {v}");
            }
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
fn print_levels(a: &InfoArgs, f: &RawFrame, info: &FrameInfo) {
    let opt = |v: Option<String>| v.unwrap_or_else(|| "unknown".into());
    let black = match info.black[..] {
        [one] => one.to_string(),
        _ => f.plane_levels(f.black),
    };
    let note = match (&f.fits, &a.input.black) {
        // Floats (pgrf's reduced lights and masters): stored above black.
        (Some(h), None) if h.conversion.is_some() => " (FITS records no black level)",
        (Some(_), None) => {
            " (FITS records no black level: a bias stack measures it, --black sets one)"
        }
        _ => "",
    };
    println!("black       {black} DN{note}");
    if let Some(m) = &f.masked {
        let level = f.plane_levels(m.level.map(|v| (v * 100.0).round() / 100.0));
        let (on, n) = (m.source.describe(), m.pixels);
        println!("masked      {level} DN measured on {on} ({n} px per plane; enhance subtracts it uncalibrated)");
    }
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
    match &info.noise {
        Ok(n) => println!("noise-aware models would use: {n}"),
        Err(e @ pgrf_noise::NoiseError::NotAPhoto { .. }) => {
            println!("noise-aware models would use: nothing stated: {e}")
        }
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
