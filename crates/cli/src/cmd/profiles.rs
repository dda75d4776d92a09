//! `pgrf profiles`: the camera profiles `--profile` accepts (built in, and
//! darktable's cameras) and what one of them holds.

use anyhow::{bail, Result};
use clap::{Args, Subcommand};
use pgrf_noise::darktable::NoiseProfiles;
use pgrf_noise::pg_profile;
use pgrf_noise::CameraProfile;
use std::path::Path;

#[derive(Args, Debug)]
pub struct ProfilesArgs {
    #[command(subcommand)]
    pub action: Action,
}

#[derive(Subcommand, Debug)]
pub enum Action {
    /// List the built-in profiles (and, with --darktable, the cameras of darktable's noiseprofiles.json: maker, model, measured ISOs).
    List(ListArgs),
    /// Print what a profile holds: K and read noise per ISO on its DN scale, its source and limits.
    Show(ShowArgs),
}

#[derive(Args, Debug)]
pub struct ListArgs {
    /// Also list darktable's cameras (from --darktable-profiles PATH, else darktable's install).
    #[arg(long)]
    pub darktable: bool,
}

#[derive(Args, Debug)]
pub struct ShowArgs {
    /// What --profile takes: a built-in name, darktable:"MAKER MODEL", dng:FILE.dng or a profile JSON file.
    pub name: String,
    /// Also print the parameters synthesis uses at this ISO (interpolated as it interpolates).
    #[arg(long)]
    pub iso: Option<u32>,
}

pub fn run(a: &ProfilesArgs, g: &crate::Globals) -> Result<()> {
    match &a.action {
        Action::List(l) => list(l, g.darktable),
        Action::Show(s) => show(s, g.darktable),
    }
}

fn list(a: &ListArgs, darktable: Option<&Path>) -> Result<()> {
    // Read darktable's file first: a missing one is the only error, before any output.
    let db = if a.darktable {
        Some(NoiseProfiles::open(darktable)?)
    } else {
        None
    };
    let builtins = pgrf_noise::catalog::built_in_views();
    let width = builtins
        .iter()
        .map(|(_, v)| v.make.chars().count() + v.model.chars().count() + 1)
        .max()
        .unwrap_or(0);
    println!("built-in profiles (--profile NAME):");
    for (name, v) in &builtins {
        let isos = match (v.rows.first(), v.rows.last()) {
            (Some(lo), Some(hi)) => format!("ISO {}..{} ({} ISOs)", lo.iso, hi.iso, v.rows.len()),
            _ if v.k_per_iso.is_some() => format!(
                "no ISO table: K {:.4}..{:.4} DN/e-, ISO {:.0}..{:.0} at K = {} x ISO",
                v.k_range.0,
                v.k_range.1,
                v.k_range.0 / v.k_per_iso.unwrap_or(1.0),
                v.k_range.1 / v.k_per_iso.unwrap_or(1.0),
                v.k_per_iso.unwrap_or(1.0)
            ),
            _ => format!(
                "no ISO table: K {:.4}..{:.4} DN/e- drawn as ELD draws it (omit --iso)",
                v.k_range.0, v.k_range.1
            ),
        };
        let camera = format!("{} {}", v.make, v.model);
        println!("  {name:<14} {camera:<width$}  {isos}");
    }
    println!(
        "also: dng:FILE.dng (a DNG's NoiseProfile tag), darktable:\"MAKER MODEL\" (darktable's noiseprofiles.json), a profile JSON file"
    );
    let Some(db) = db else {
        println!("darktable's cameras: pgrf profiles list --darktable");
        return Ok(());
    };
    println!(
        "darktable cameras in {} (format version {}, {} cameras; --profile darktable:\"MAKER MODEL\"):",
        db.path.display(),
        db.version,
        db.cameras.len()
    );
    let width = db
        .cameras
        .iter()
        .map(|c| c.name().chars().count())
        .max()
        .unwrap_or(0);
    for c in &db.cameras {
        let isos: Vec<String> = c.isos().iter().map(|i| i.to_string()).collect();
        let isos = if isos.is_empty() {
            "every entry marked skip".to_string()
        } else {
            format!("ISO {}", isos.join(" "))
        };
        println!("  {:<width$}  {isos}", c.name());
    }
    Ok(())
}

fn show(a: &ShowArgs, darktable: Option<&Path>) -> Result<()> {
    let profile = CameraProfile::load(&a.name, darktable)?;
    // What synthesis uses at --iso, before any output: a refusal is the only output.
    let at_iso = a.iso.map(|iso| profile.params_at_iso(iso)).transpose()?;
    let v = pg_profile::view(&profile);
    println!("profile   {}", v.name);
    println!("camera    {} {}", v.make, v.model);
    println!("source    {}", v.source);
    println!(
        "scale     DN on white - black = {} DN; black {}",
        v.dn_range,
        v.black
            .map(|b| format!("{b} DN"))
            .unwrap_or_else(|| "not known (nothing clipped below it)".into())
    );
    if let Some(camera) = a.name.strip_prefix("darktable:") {
        show_darktable(camera, darktable)?;
    } else {
        for line in v.parameter_lines() {
            println!("{line}");
        }
    }
    match &profile.dark_current {
        Some(d) => println!(
            "dark      {} e- per {} (law {:?})",
            d.rate,
            match d.law {
                pgrf_noise::DarkLaw::Sqrt => "sqrt(s)",
                pgrf_noise::DarkLaw::Linear => "s",
            },
            d.law
        ),
        None => println!("dark      no dark current measured (give --dark-rate, or --calib)"),
    }
    if let (Some(iso), Some(p)) = (a.iso, at_iso) {
        println!(
            "at ISO {iso}: K {:.5} DN/e-, read sigma {:.4} DN (Gaussian; Tukey scale {:.4} DN), row sigma {:.4} DN",
            p.k, p.sigma_gauss, p.sigma_tukey, p.sigma_row
        );
    }
    Ok(())
}

/// The measured ISOs of a darktable camera: darktable's numbers and pgrf's.
fn show_darktable(camera: &str, darktable: Option<&Path>) -> Result<()> {
    let db = NoiseProfiles::open(darktable)?;
    let cam = db.find(camera)?;
    if cam.measured().is_empty() {
        bail!("darktable:{camera}: every entry is marked skip");
    }
    for line in cam.measured_lines() {
        println!("{line}");
    }
    Ok(())
}
