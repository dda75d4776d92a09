//! `pgrf enhance`: dark noisy RAW photos in, clean linear DNGs (and sRGB
//! previews) out, with either network, at full resolution in bounded memory.

use crate::input::InputArgs;
use crate::progress::Bar;
use anyhow::{bail, Context, Result};
use clap::Args;
use pgrf_nn::infer::enhance::flags::EnhanceFlags;
use pgrf_nn::infer::enhance::{enhance_file, BoxError, EnhanceConfig, FileReport, Job};
use pgrf_nn::infer::Restore;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct EnhanceArgs {
    #[command(flatten)]
    pub enhance: EnhanceFlags,
    #[command(flatten)]
    pub input: InputArgs,
}

pub fn run(a: &EnhanceArgs) -> Result<()> {
    let e = &a.enhance;
    let jobs = e.jobs()?;
    e.device.check_available().map_err(anyhow::Error::msg)?;
    let cfg = e.config()?;
    let restorer = crate::shipped::load_model(&e.model, e.sampler(), e.device)
        .with_context(|| format!("--model {}", e.model.display()))?;
    let header = std::cell::Cell::new(e.quiet);
    let print_header = || {
        if !header.replace(true) {
            for line in e.notes(restorer.as_ref()) {
                eprintln!("{line}");
            }
        }
    };
    let mut failed: Vec<PathBuf> = Vec::new();
    let n = jobs.len();
    for (i, job) in jobs.iter().enumerate() {
        match enhance_one(a, &cfg, job, restorer.as_ref(), (i, n), &print_header) {
            Ok(report) => {
                if e.json {
                    println!("{}", serde_json::to_string(&report)?);
                }
            }
            Err(err) => {
                let msg = format!("{err:#}").replace('\n', " ");
                if n == 1 {
                    bail!(msg);
                }
                if !e.quiet {
                    eprintln!("skipped {}: {msg}", job.input.display());
                }
                if e.json {
                    println!(
                        "{}",
                        serde_json::json!({"input": job.input.display().to_string(), "error": msg})
                    );
                }
                failed.push(job.input.clone());
            }
        }
    }
    if !failed.is_empty() {
        let list: Vec<String> = failed.iter().map(|p| p.display().to_string()).collect();
        bail!(
            "{} of {n} files could not be enhanced: {}",
            failed.len(),
            list.join(", ")
        );
    }
    Ok(())
}

/// Enhance file number `index` of `count` and say what was written.
fn enhance_one(
    a: &EnhanceArgs,
    cfg: &EnhanceConfig,
    job: &Job,
    restorer: &dyn Restore,
    (index, count): (usize, usize),
    print_header: &dyn Fn(),
) -> Result<FileReport> {
    let name = job
        .input
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let quiet = a.enhance.quiet;
    let open = |p: &std::path::Path| a.input.open(p).map_err(BoxError::from);
    let start = || {
        print_header();
        Bar::new(format!("[{}/{count}] {name}", index + 1), 0, "tiles", quiet)
    };
    let r = enhance_file(cfg, restorer, job, open, start)?;
    if !quiet {
        eprintln!("{}", r.line());
    }
    Ok(r)
}
