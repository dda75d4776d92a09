//! `pgrf train denoiser|flow`: every setting can come from a TOML file
//! (`--config`, flat keys named like the flags with underscores) and any flag
//! overrides the file. Progress bar, Ctrl-C (checkpoint and exit), and a JSON
//! summary line for scripts. The flags are `pgrf_nn::TrainConfig`'s own
//! (`pgrf_nn::flags`), the recipe is `pgrf_app::train::run`.

use anyhow::Result;
use clap::Args;

use pgrf_nn::flags::TrainFlags;
use pgrf_nn::train::Trained;
use pgrf_nn::Method;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

#[derive(Args, Debug)]
pub struct TrainArgs {
    /// What to train: spc (the SID U-Net denoiser; also `denoiser`) or pgrf
    /// (the flow model's SR3 velocity field; also `flow`).
    pub method: Method,
    /// TOML file of settings (keys as the flags, with underscores); flags override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub settings: TrainFlags,
    /// Continue from the checkpoint (same settings; --steps may grow).
    #[arg(long)]
    pub resume: bool,
    /// Print one JSON summary line at the end.
    #[arg(long)]
    pub json: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Print the merged configuration as TOML (a `--config` file) and exit.
    #[arg(long)]
    pub print_config: bool,
}

pub fn run(a: &TrainArgs, g: &crate::Globals) -> Result<()> {
    let kernels = g.kernels;
    let mut config = a.settings.merge(a.config.as_deref(), a.method)?;
    config.kernels = kernels;
    config.darktable_profiles = g.darktable.map(Into::into);
    if a.print_config {
        print!("{}", config.to_toml());
        return Ok(());
    }
    let started = Arc::new(AtomicBool::new(false));
    let stop = stop_on_ctrl_c(started.clone());
    let progress = Steps {
        bar: crate::progress::Bar::new("train", config.steps, "steps", a.quiet),
        started,
    };
    let warn = |w: &str| eprintln!("pgrf: warning: {w}");
    let trained = pgrf_app::train::run(&config, a.method, a.resume, &progress, &stop, &warn)?;
    report(a, &trained);
    if trained.outcome.interrupted {
        eprintln!(
            "interrupted at step {}: checkpoint {} and weights {} written; continue with --resume",
            trained.outcome.end_step,
            trained.outputs.checkpoint.display(),
            trained.outputs.weights.display()
        );
        std::process::exit(130);
    }
    Ok(())
}

/// The training bar, which also tells the Ctrl-C handler when the steps
/// have started.
struct Steps {
    bar: crate::progress::Bar,
    started: Arc<AtomicBool>,
}

impl pgrf_core::Progress for Steps {
    fn start(&self, len: u64, what: &str) {
        self.started.store(true, Ordering::SeqCst);
        self.bar.start(len, what);
    }
    fn advance(&self, n: u64) {
        self.bar.advance(n);
    }
    fn set_position(&self, done: u64) {
        self.bar.set_position(done);
    }
    fn message(&self, msg: &str) {
        self.bar.message(msg);
    }
    fn note(&self, line: &str) {
        self.bar.note(line);
    }
    fn finish(&self) {
        self.bar.finish();
    }
}

/// The flag a first Ctrl-C sets once the steps have `started` (the run
/// checkpoints and stops after the current step); before that, Ctrl-C ends
/// the process at once, nothing written. A second Ctrl-C kills at once, but
/// only a second request: one that comes a second or more after the first.
/// `timeout -s INT` and other supervisors signal both the process and its
/// process group, so one request can arrive twice within microseconds, and
/// it must still save.
fn stop_on_ctrl_c(started: Arc<AtomicBool>) -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let first: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
    let _ = ctrlc::set_handler(move || {
        if !started.load(Ordering::SeqCst) {
            std::process::exit(130);
        }
        let t0 = *first.get_or_init(std::time::Instant::now);
        if flag.swap(true, Ordering::SeqCst) && t0.elapsed().as_secs_f64() >= 1.0 {
            std::process::exit(130);
        }
    });
    stop
}

fn report(a: &TrainArgs, t: &Trained) {
    let o = &t.outcome;
    if o.already_finished && !a.quiet {
        eprintln!(
            "already finished: {} is at step {} of --steps {}; {} left as it was (a larger --steps trains on)",
            t.outputs.checkpoint.display(),
            o.end_step,
            o.end_step,
            t.outputs.weights.display()
        );
    }
    let val = o
        .val_psnr
        .map(|p| format!(", validation PSNR {p:.2} dB"))
        .unwrap_or_default();
    let input = o
        .val_input_psnr
        .map(|p| format!(" (noisy input {p:.2} dB)"))
        .unwrap_or_default();
    if !a.quiet && !o.already_finished {
        eprintln!(
            "steps {}..{}: final loss {:.5}{val}{input}, {:.2} images/s, {:.1} s; wrote {}",
            o.start_step,
            o.end_step,
            o.final_loss,
            o.images_per_s,
            o.seconds,
            t.outputs.weights.display()
        );
    }
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "method": t.method,
                "steps": o.end_step,
                "steps_this_run": o.end_step - o.start_step,
                "final_loss": o.final_loss,
                "val_psnr": o.val_psnr,
                "val_input_psnr": o.val_input_psnr,
                "images_per_s": o.images_per_s,
                "seconds": o.seconds,
                "interrupted": o.interrupted,
                "already_finished": o.already_finished,
                "output": t.outputs.weights,
                "checkpoint": t.outputs.checkpoint,
            })
        );
    }
}
