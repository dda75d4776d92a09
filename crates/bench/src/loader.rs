//! `pgrf-bench loader`: crops per second of `pgrf train`'s data loader on
//! its own (decoded sources, crop, unprocessing of photos, augmentation,
//! noise synthesis), to hold against the crops per second the optimiser
//! consumes (`pgrf-bench train` at the same batch and crop size): the
//! loader must not be what a run waits for.

use anyhow::{ensure, Result};
use clap::Args;
use pgrf_nn::data::build::sources;
use pgrf_nn::data::loader_rate;
use pgrf_nn::TrainConfig;
use pgrf_noise::pair::PairSpec;
use pgrf_noise::CameraProfile;
use std::sync::Arc;
use std::time::Instant;

/// Flags of `pgrf-bench loader`.
#[derive(Args, Debug)]
pub struct LoaderArgs {
    /// Training data, as `pgrf train --data` takes it.
    #[arg(long, default_value = "procedural")]
    pub data: String,
    /// Side of the packed crops.
    #[arg(long, default_value_t = 64)]
    pub patch: usize,
    /// Crops per batch.
    #[arg(long, default_value_t = 4)]
    pub batch: usize,
    /// Worker threads (pgrf train's default is 2).
    #[arg(long, default_value_t = 2)]
    pub workers: usize,
    /// Timed batches.
    #[arg(long, default_value_t = 100)]
    pub batches: u64,
    /// Print one JSON line.
    #[arg(long)]
    pub json: bool,
}

/// Build the sources as `pgrf train` does (timed apart: decoding every
/// file once), then time the loader.
pub fn run(a: &LoaderArgs) -> Result<()> {
    ensure!(
        a.batches > 0 && a.batch > 0,
        "--batches and --batch must be at least 1"
    );
    let config = TrainConfig {
        data: a.data.clone(),
        patch: a.patch,
        val_pairs: 0,
        ..TrainConfig::default()
    };
    config.validate()?;
    let t = Instant::now();
    let built = sources(&config)?;
    let open_s = t.elapsed().as_secs_f64();
    let mut spec = PairSpec::new(
        CameraProfile::load(&config.profile, config.darktable_profiles.as_deref())?,
        config.noise,
    );
    spec.ratio = config.ratio_draw.spec(config.ratio_min, config.ratio_max);
    let what = built.train.describe();
    let rate = loader_rate(
        Arc::new(built.train),
        Arc::new(spec.into()),
        a.patch,
        a.batch,
        a.workers,
        a.batches,
    )?;
    if a.json {
        println!(
            "{}",
            serde_json::json!({"data": what, "patch": a.patch, "batch": a.batch,
                "workers": a.workers, "batches": a.batches, "open_s": open_s,
                "crops_per_s": rate})
        );
    } else {
        println!(
            "{what}: opened in {open_s:.1} s; {rate:.1} crops/s ({}x{} packed, batch {}, {} workers, {} batches)",
            a.patch, a.patch, a.batch, a.workers, a.batches
        );
    }
    Ok(())
}
