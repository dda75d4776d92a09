//! `pgrf enhance`: dark noisy RAW photos in, clean linear DNGs (and sRGB
//! previews) out, with either network, at full resolution in bounded memory;
//! many files as one batch, or as one shard of a cluster's batch
//! (`pgrf_app::enhance::batch`).

use crate::input::InputArgs;
use crate::progress::Bar;
use anyhow::{Context, Result};
use clap::Args;
use indicatif::MultiProgress;
use pgrf_app::enhance::batch::{run_batch, BatchEvents, BatchFailure, Record, Status};
use pgrf_app::enhance::flags::EnhanceFlags;
use pgrf_app::enhance::{BoxError, FileReport, Job};
use pgrf_nn::infer::Restore;
use std::cell::Cell;
use std::path::Path;

#[derive(Args, Debug)]
pub struct EnhanceArgs {
    #[command(flatten)]
    pub enhance: EnhanceFlags,
    #[command(flatten)]
    pub input: InputArgs,
}

pub fn run(a: &EnhanceArgs, g: &crate::Globals) -> Result<()> {
    let kernels = g.kernels;
    let e = &a.enhance;
    let batch = e.batch()?;
    e.device.check_available().map_err(anyhow::Error::msg)?;
    let mut cfg = e.config()?;
    // A black level the user gives is theirs, whatever the file's masked
    // pixels say.
    cfg.masked_black = a.input.black.is_none();
    cfg.tiling.kernels = kernels;
    cfg.darktable = g.darktable.map(Into::into);
    let model = e.model();
    let restorer = pgrf_app::builtin::load_model(&model, e.sampler(), e.device)
        .with_context(|| format!("--model {}", model.display()))?;
    if let (Some(shard), 0) = (batch.shard, batch.selected_count()) {
        if !e.quiet {
            eprintln!(
                "shard {shard}: nothing to do ({} inputs in all, none fall to this shard)",
                batch.jobs.len()
            );
        }
        return Ok(());
    }
    let single = batch.jobs.len() == 1;
    let view = View::new(
        e,
        restorer.as_ref(),
        kernels,
        (batch.selected_count(), single),
    );
    let open = |p: &Path| a.input.open(p).map_err(BoxError::from);
    let outcome = run_batch(&cfg, restorer.as_ref(), &batch, &open, &view)?;
    match outcome.failure(batch.jobs.len()) {
        None => Ok(()),
        Some(BatchFailure::One(err)) => Err(err.into()),
        Some(BatchFailure::Some(partial)) => Err(partial.into()),
    }
}

/// What the user sees of a batch: the model's notes before the first file
/// is restored, a bar over the files above each file's bar over tiles, a
/// line per file, and with `--json` one JSON line per file on stdout.
struct View<'a> {
    flags: &'a EnhanceFlags,
    restorer: &'a dyn Restore,
    kernels: pgrf_nn::ops::Kernels,
    multi: MultiProgress,
    files: Bar,
    noted: Cell<bool>,
    /// One input in all: its failure is the command's one error line.
    single: bool,
}

impl<'a> View<'a> {
    fn new(
        flags: &'a EnhanceFlags,
        restorer: &'a dyn Restore,
        kernels: pgrf_nn::ops::Kernels,
        (count, single): (usize, bool),
    ) -> View<'a> {
        let multi = MultiProgress::new();
        let files = Bar::within(&multi, "batch", count as u64, "files", flags.quiet);
        View {
            flags,
            restorer,
            kernels,
            multi,
            files,
            noted: Cell::new(flags.quiet),
            single,
        }
    }
}

impl BatchEvents for View<'_> {
    type Tiles = Bar;

    fn files(&self) -> &dyn pgrf_core::Progress {
        &self.files
    }

    fn tiles(&self, index: usize, count: usize, job: &Job) -> Bar {
        if !self.noted.replace(true) {
            for line in self.flags.notes(self.restorer, self.kernels) {
                self.files.println(&line);
            }
        }
        let name = (job.input.file_name())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let prefix = format!("[{}/{count}] {name}", index + 1);
        Bar::within(&self.multi, prefix, 0, "tiles", self.flags.quiet)
    }

    fn finished(&self, record: &Record, report: Option<&FileReport>) {
        if record.status == Status::Failed && self.single {
            return;
        }
        let line = match (record.status, report) {
            (Status::Done, Some(r)) => r.line(),
            (Status::Skipped, _) => {
                let png = (record.png.as_ref())
                    .map(|p| format!(" and {p}"))
                    .unwrap_or_default();
                format!(
                    "kept {}{png} (there already, reading back whole)",
                    record.output
                )
            }
            _ => format!(
                "failed {}: {}",
                record.input,
                record.error.as_deref().unwrap_or_default()
            ),
        };
        self.files.println(&line);
        if self.flags.json {
            let json = match report {
                Some(r) => serde_json::to_string(r),
                None => serde_json::to_string(record),
            };
            println!("{}", json.unwrap_or_default());
        }
    }
}
