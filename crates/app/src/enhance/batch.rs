//! `pgrf enhance` over many files, as a cluster runs it: the planned jobs
//! ([`super::jobs::plan_jobs`], every output checked on the whole list)
//! cut into shards that need no coordination (`--shard I/N` takes every
//! N-th file of the sorted list), files whose results already read back
//! whole left alone (`--skip-existing`, so a killed or preempted shard is
//! simply started again), one manifest line per file (`--manifest`), and
//! one file's failure never stopping the others.
//!
//! Memory is one frame's, whatever the batch's size: a file's frame and
//! result are dropped before the next is opened, and what is kept per file
//! is a failure's error at most.

use super::{enhance_file, BoxError, EnhanceConfig, EnhanceError, FileReport, Job};
use pgrf_core::exit::PartialFailure;
use pgrf_core::Progress;
use pgrf_nn::infer::Restore;
use pgrf_nn::NnError;
use pgrf_raw::{decode_bytes, png_size, LevelOverrides, RawFrame};
use serde::Serialize;
use std::fmt;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `--shard I/N`: this run takes the files at positions `I`, `I + N`,
/// `I + 2N`, ... of the sorted, deduplicated input list (0-based, `I < N`).
/// Every shard computes the same list and the same plan, so N runs started
/// with the same arguments cover every file exactly once without talking
/// to each other (a Slurm array, a Kubernetes Indexed Job).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This shard, 0..count.
    pub index: usize,
    /// How many shards there are, at least 1.
    pub count: usize,
}

impl Shard {
    /// Whether the file at `position` of the sorted list is this shard's.
    pub fn takes(&self, position: usize) -> bool {
        position % self.count == self.index
    }
}

impl std::str::FromStr for Shard {
    type Err = pgrf_core::parse::ParseError;
    /// `I/N` with `0 <= I < N`; the message says what is wrong (the caller
    /// names the flag).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let parsed = s
            .split_once('/')
            .and_then(|(i, n)| Some((i.trim().parse().ok()?, n.trim().parse().ok()?)));
        let Some((index, count)) = parsed else {
            return Err(pgrf_core::parse::ParseError::malformed(
                s,
                format!("--shard {s}: expected I/N, two whole numbers (shard I of N, counted from 0), e.g. 0/8"),
            ));
        };
        if count == 0 {
            return Err(pgrf_core::parse::ParseError::out_of_range(
                s,
                format!("--shard {s}: N must be at least 1"),
            ));
        }
        if index >= count {
            return Err(pgrf_core::parse::ParseError::out_of_range(
                s,
                format!(
                    "--shard {s}: I counts from 0 and must be below N (0/{count} .. {}/{count})",
                    count - 1
                ),
            ));
        }
        Ok(Shard { index, count })
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// A planned batch and how to run it.
#[derive(Clone, Debug)]
pub struct Batch {
    /// Every input's job, in the sorted order shards count in.
    pub jobs: Vec<Job>,
    /// This run's share of the jobs (None: all of them).
    pub shard: Option<Shard>,
    /// Leave a file whose outputs already read back whole.
    pub skip_existing: bool,
    /// Append one JSON line per file to this file.
    pub manifest: Option<PathBuf>,
}

impl Batch {
    /// The jobs this run does.
    pub fn selected(&self) -> impl Iterator<Item = &Job> {
        let shard = self.shard;
        (self.jobs.iter().enumerate())
            .filter(move |(i, _)| shard.is_none_or(|s| s.takes(*i)))
            .map(|(_, j)| j)
    }

    /// How many jobs this run does.
    pub fn selected_count(&self) -> usize {
        match self.shard {
            Some(s) => (self.jobs.len() + s.count - 1 - s.index) / s.count,
            None => self.jobs.len(),
        }
    }
}

/// What happened to one file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Enhanced and written.
    Done,
    /// Its outputs were there and read back whole (`--skip-existing`).
    Skipped,
    /// It could not be enhanced (the record says why).
    Failed,
}

/// One file's line in the manifest (and `--json`'s line for a file not
/// done).
#[derive(Clone, Debug, Serialize)]
pub struct Record {
    /// The input.
    pub input: String,
    /// Its DNG (or FITS file).
    pub output: String,
    /// Its preview, if asked for.
    pub png: Option<String>,
    /// Done, skipped or failed.
    pub status: Status,
    /// Seconds spent on it (checking it, for a skipped file).
    pub seconds: f64,
    /// The noise parameters a noise-aware model was told, and their source
    /// (None for another model, or a file not done).
    pub noise: Option<String>,
    /// Why it failed, on one line.
    pub error: Option<String>,
    /// The run's `--shard`.
    pub shard: Option<String>,
}

/// What the caller hears while a batch runs (the CLI draws bars and
/// prints lines; the library never draws).
pub trait BatchEvents {
    /// What hears one file's tiles.
    type Tiles: Progress;
    /// The whole batch: started with this run's file count, advanced by one
    /// per file done, skipped or failed, finished at the end.
    fn files(&self) -> &dyn Progress;
    /// File number `index` (from 0) of this run's `count` is open and ready
    /// to restore: what hears its tiles.
    fn tiles(&self, index: usize, count: usize, job: &Job) -> Self::Tiles;
    /// A file is over: its record (written to the manifest already), and
    /// its report when it was done.
    fn finished(&self, record: &Record, report: Option<&FileReport>);
}

/// A file that failed.
#[derive(Debug)]
pub struct Failure {
    /// The input.
    pub input: PathBuf,
    /// Why.
    pub error: EnhanceError,
}

/// How a batch went.
#[derive(Debug, Default)]
pub struct BatchOutcome {
    /// Files enhanced.
    pub done: usize,
    /// Files left alone (`--skip-existing`).
    pub skipped: usize,
    /// Files that failed, in order.
    pub failed: Vec<Failure>,
}

/// Why a batch did not end with every file done or skipped.
#[derive(Debug)]
pub enum BatchFailure {
    /// The command had one input, and it failed: its own error (the whole
    /// command failed).
    One(EnhanceError),
    /// Some files of several failed, the others were done
    /// ([`pgrf_core::exit::EXIT_PARTIAL`]).
    Some(PartialFailure),
}

impl BatchOutcome {
    /// How many files this run went through.
    pub fn total(&self) -> usize {
        self.done + self.skipped + self.failed.len()
    }

    /// None when no file failed. `planned` is the whole list's length: a
    /// command of one input that failed gets that input's error.
    pub fn failure(mut self, planned: usize) -> Option<BatchFailure> {
        if self.failed.is_empty() {
            return None;
        }
        if planned == 1 && self.failed.len() == 1 {
            return self.failed.pop().map(|f| BatchFailure::One(f.error));
        }
        Some(BatchFailure::Some(PartialFailure {
            total: self.total(),
            failed: (self.failed.iter())
                .map(|f| f.input.display().to_string())
                .collect(),
        }))
    }
}

/// `e` and its causes on one line, `: ` between them (what the manifest
/// and the per-file report say).
pub fn error_line(e: &(dyn std::error::Error + 'static)) -> String {
    let mut line = e.to_string();
    let mut next = e.source();
    while let Some(cause) = next {
        line.push_str(": ");
        line.push_str(&cause.to_string());
        next = cause.source();
    }
    line.replace('\n', " ")
}

/// The manifest: a JSON-lines file only ever appended to, each line in one
/// write, flushed and synced before the next file starts, so a run killed
/// at any moment leaves every earlier line whole and at most the last one
/// cut short.
struct Manifest {
    path: PathBuf,
    file: std::fs::File,
    /// The file ended without a newline (a line cut short by a kill): the
    /// first new line starts on a line of its own.
    needs_newline: bool,
}

impl Manifest {
    fn open(path: &Path) -> Result<Manifest, NnError> {
        let failed = |e: std::io::Error| NnError::Output {
            path: path.to_path_buf(),
            reason: format!("--manifest: cannot append: {e}"),
        };
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .read(true)
            .open(path)
            .map_err(failed)?;
        let len = file.metadata().map_err(failed)?.len();
        let mut last = [b'\n'];
        if len > 0 {
            file.seek(SeekFrom::Start(len - 1)).map_err(failed)?;
            file.read_exact(&mut last).map_err(failed)?;
        }
        Ok(Manifest {
            path: path.to_path_buf(),
            file,
            needs_newline: last[0] != b'\n',
        })
    }

    fn append(&mut self, record: &Record) -> Result<(), NnError> {
        let mut line = String::new();
        if self.needs_newline {
            line.push('\n');
        }
        line.push_str(&serde_json::to_string(record).map_err(|e| NnError::Output {
            path: self.path.clone(),
            reason: e.to_string(),
        })?);
        line.push('\n');
        (self.file.write_all(line.as_bytes()))
            .and_then(|()| self.file.flush())
            .and_then(|()| self.file.sync_data())
            .map_err(|e| NnError::Output {
                path: self.path.clone(),
                reason: format!("--manifest: cannot append: {e}"),
            })?;
        self.needs_newline = false;
        Ok(())
    }
}

/// Whether `job`'s outputs are there and read back whole: the DNG (or
/// FITS file) decodes with pgrf's own reader to the input's size and CFA or
/// monochrome layout (what enhancing it would write), a DNG's pixels match
/// the digest it was written with ([`pgrf_raw::pixels_intact`]: a byte
/// flipped inside a compressed tile can decode to wrong pixels), and the
/// preview, when asked for, decodes to the same size (either way round:
/// the preview is turned upright). A file cut short or damaged is redone;
/// a run of pgrf never leaves one (its writes are atomic), but a copy, a
/// full disk or a failing drive may.
pub fn reads_back(job: &Job, open: &dyn Fn(&Path) -> Result<RawFrame, BoxError>) -> bool {
    if !job.output.is_file() || job.png.as_ref().is_some_and(|p| !p.is_file()) {
        return false;
    }
    // Read once: decoded, and checked against the digest it was written with.
    let Ok(bytes) = std::fs::read(&job.output) else {
        return false;
    };
    let Ok(written) = decode_bytes(&job.output, &bytes, &LevelOverrides::default()) else {
        return false;
    };
    let Ok(input) = open(&job.input) else {
        return false;
    };
    let size = (input.width, input.height);
    if (written.width, written.height) != size
        || (written.cfa, written.mono) != (input.cfa, input.mono)
        || !pgrf_raw::pixels_intact(&bytes, &written)
    {
        return false;
    }
    drop((written, input, bytes));
    match &job.png {
        None => true,
        Some(png) => png_size(png).is_ok_and(|(w, h)| (w, h) == size || (h, w) == size),
    }
}

/// What a file whose enhancement panicked reports, before the panic's own
/// words.
const PANIC_LEAD: &str = "pgrf crashed on this file (a bug: please report it with the file)";

/// Run `batch`: each of this run's files skipped, enhanced or failed in
/// turn ([`enhance_file`] with `cfg` and `restorer`, inputs opened by
/// `open`), the manifest appended after each, `events` told as it goes. A
/// file's failure is recorded and the next file goes on; only a manifest
/// that cannot be written stops the batch (its record would be lost).
pub fn run_batch<E: BatchEvents>(
    cfg: &EnhanceConfig,
    restorer: &dyn Restore,
    batch: &Batch,
    open: &dyn Fn(&Path) -> Result<RawFrame, BoxError>,
    events: &E,
) -> Result<BatchOutcome, NnError> {
    let mut manifest = batch.manifest.as_deref().map(Manifest::open).transpose()?;
    let count = batch.selected_count();
    let shard = batch.shard.map(|s| s.to_string());
    let mut outcome = BatchOutcome::default();
    events.files().start(count as u64, "files");
    for (index, job) in batch.selected().enumerate() {
        let t0 = Instant::now();
        let result = if batch.skip_existing && reads_back(job, open) {
            None
        } else {
            let start = || events.tiles(index, count, job);
            // A panic (a bug) is this file's failure, not the shoot's end.
            Some(
                pgrf_core::panic_guard::quietly(PANIC_LEAD, || {
                    enhance_file(cfg, restorer, job, open, start)
                })
                .unwrap_or_else(|p| Err(p.into())),
            )
        };
        let (status, report, error) = match result {
            None => (Status::Skipped, None, None),
            Some(Ok(r)) => (Status::Done, Some(r), None),
            Some(Err(e)) => (Status::Failed, None, Some(e)),
        };
        let record = Record {
            input: job.input.display().to_string(),
            output: job.output.display().to_string(),
            png: job.png.as_ref().map(|p| p.display().to_string()),
            status,
            seconds: t0.elapsed().as_secs_f64(),
            noise: report.as_ref().and_then(|r| r.noise.clone()),
            error: error.as_ref().map(|e| error_line(e)),
            shard: shard.clone(),
        };
        if let Some(m) = &mut manifest {
            m.append(&record)?;
        }
        events.finished(&record, report.as_ref());
        events.files().advance(1);
        match error {
            Some(error) => outcome.failed.push(Failure {
                input: job.input.clone(),
                error,
            }),
            None if report.is_some() => outcome.done += 1,
            None => outcome.skipped += 1,
        }
    }
    events.files().finish();
    Ok(outcome)
}

/// `--manifest`'s checks, before any work, by the one rule on outputs
/// ([`pgrf_core::paths::Io`]): its folder exists, and it is not a folder,
/// an input, inside a folder given as input (the next run over that folder
/// would take it for a photo) or an output of the plan. `given` are the
/// inputs as named (files and folders), `jobs` the plan.
pub fn check_manifest(manifest: &Path, given: &[PathBuf], jobs: &[Job]) -> Result<(), NnError> {
    let mut io = pgrf_core::paths::Io::new();
    io.inputs("", given)
        .inputs("", jobs.iter().map(|j| &j.input))
        .file("--manifest", manifest);
    // Only a plan output of the manifest's name can be it (thousands of
    // outputs need not be compared with each other again).
    let name = manifest.file_name();
    for j in jobs {
        for (flag, out) in
            std::iter::once(("-o", &j.output)).chain(j.png.iter().map(|p| ("--png", p)))
        {
            if out.file_name() == name {
                io.file(flag, out);
            }
        }
    }
    io.check()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pgrf-batch-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A file whose enhancement panics (planted in its opener) is that
    /// file's failure, named with the panic's words; the files after it are
    /// done.
    #[test]
    fn a_panic_inside_one_file_fails_that_file_only() {
        use crate::enhance::RatioChoice;
        use pgrf_core::NoProgress;
        use pgrf_nn::arch::{Architecture, SidUnetConfig};
        use pgrf_nn::backend::{Cpu, DeviceKind};
        use pgrf_nn::infer::{SamplerChoice, Tiling};
        use pgrf_nn::weights::{NoiseSource, WeightMeta};
        struct Quiet;
        impl BatchEvents for Quiet {
            type Tiles = NoProgress;
            fn files(&self) -> &dyn Progress {
                &NoProgress
            }
            fn tiles(&self, _: usize, _: usize, _: &Job) -> NoProgress {
                NoProgress
            }
            fn finished(&self, _: &Record, _: Option<&FileReport>) {}
        }
        let d = scratch("panic");
        let arch = Architecture::SidUnet(SidUnetConfig::new().with_width(2));
        let model = d.join("m.safetensors");
        let net = arch.init_seeded::<Cpu>(&Default::default(), 1).unwrap();
        net.save(&model, &WeightMeta::new(arch, NoiseSource::default()))
            .unwrap();
        let restorer =
            pgrf_nn::infer::load(&model, SamplerChoice::default(), DeviceKind::Cpu).unwrap();
        let cfg = EnhanceConfig {
            ratio: RatioChoice::Fixed(1.0),
            calib: None,
            force: false,
            tiling: Tiling {
                tile: None,
                overlap: None,
                seed: 0,
                device: DeviceKind::Cpu,
                kernels: Default::default(),
            },
            noise: None,
            masked_black: false,
            darktable: None,
        };
        let job = |n: &str| Job {
            input: d.join(format!("{n}.dng")),
            output: d.join(format!("{n}.out.dng")),
            png: None,
        };
        let batch = Batch {
            jobs: vec![job("a"), job("b"), job("c")],
            shard: None,
            skip_existing: false,
            manifest: None,
        };
        let frame = RawFrame::from_mosaic(
            32,
            32,
            vec![600; 32 * 32],
            pgrf_raw::Cfa::Rggb,
            [512.0; 4],
            16383,
        )
        .unwrap();
        let open = |p: &Path| -> Result<RawFrame, BoxError> {
            if p.ends_with("b.dng") {
                panic!("planted panic");
            }
            Ok(frame.clone())
        };
        let outcome = run_batch(&cfg, restorer.as_ref(), &batch, &open, &Quiet).unwrap();
        assert_eq!(outcome.done, 2);
        assert_eq!(outcome.failed.len(), 1);
        let e = outcome.failed[0].error.to_string();
        assert!(
            e.contains("pgrf crashed on this file") && e.contains("planted panic"),
            "{e}"
        );
        assert!(d.join("a.out.dng").is_file() && d.join("c.out.dng").is_file());
        assert!(!d.join("b.out.dng").exists());
    }

    fn jobs(n: usize) -> Vec<Job> {
        (0..n)
            .map(|i| Job {
                input: PathBuf::from(format!("in/{i:03}.dng")),
                output: PathBuf::from(format!("out/{i:03}.dng")),
                png: None,
            })
            .collect()
    }

    #[test]
    fn shards_parse_as_i_of_n_counted_from_0() {
        assert_eq!("3/8".parse(), Ok(Shard { index: 3, count: 8 }));
        assert_eq!("0/1".parse(), Ok(Shard { index: 0, count: 1 }));
        assert_eq!(Shard { index: 7, count: 8 }.to_string(), "7/8");
        for (bad, says) in [
            ("8/8", "below N"),
            ("1/0", "at least 1"),
            ("0/0", "at least 1"),
            ("x/y", "expected I/N"),
            ("-1/4", "expected I/N"),
            ("1/2/3", "expected I/N"),
            ("", "expected I/N"),
        ] {
            let e = bad.parse::<Shard>().unwrap_err().to_string();
            assert!(
                e.contains(&format!("--shard {bad}")) && e.contains(says),
                "{e}"
            );
        }
    }

    /// For every list length and shard count up to 12, the shards are
    /// disjoint, cover the list, and each counts what it selects.
    #[test]
    fn shards_split_any_list_without_overlap() {
        for len in 0..13 {
            let all = jobs(len);
            for count in 1..13 {
                let mut seen = vec![0usize; len];
                for index in 0..count {
                    let b = Batch {
                        jobs: all.clone(),
                        shard: Some(Shard { index, count }),
                        skip_existing: false,
                        manifest: None,
                    };
                    let mine: Vec<&Job> = b.selected().collect();
                    assert_eq!(mine.len(), b.selected_count(), "{len} {index}/{count}");
                    for j in mine {
                        seen[all.iter().position(|a| a == j).unwrap()] += 1;
                    }
                }
                assert!(
                    seen.iter().all(|&n| n == 1),
                    "{len} files, {count} shards: {seen:?}"
                );
            }
        }
    }

    fn record(input: &str) -> Record {
        Record {
            input: input.into(),
            output: format!("{input}.out"),
            png: None,
            status: Status::Done,
            seconds: 0.5,
            noise: None,
            error: None,
            shard: Some("1/4".into()),
        }
    }

    /// A manifest whose last line a kill cut short gets the next line on a
    /// line of its own; a whole one is appended to as it is.
    #[test]
    fn the_manifest_appends_whole_lines_after_a_cut_one() {
        let d = scratch("manifest");
        let path = d.join("m.jsonl");
        std::fs::write(&path, "{\"input\":\"a\"}\n{\"inp").unwrap();
        let mut m = Manifest::open(&path).unwrap();
        m.append(&record("b")).unwrap();
        m.append(&record("c")).unwrap();
        drop(m);
        let mut m = Manifest::open(&path).unwrap();
        m.append(&record("d")).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 5, "{text}");
        assert_eq!(lines[1], "{\"inp");
        let inputs: Vec<String> = lines[2..]
            .iter()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["input"].to_string())
            .collect();
        assert_eq!(inputs, ["\"b\"", "\"c\"", "\"d\""]);
        assert!(lines[2].contains("\"status\":\"done\"") && lines[2].contains("\"png\":null"));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_partial_failure_names_the_files_and_one_input_keeps_its_error() {
        let fail = |name: &str| Failure {
            input: PathBuf::from(name),
            error: EnhanceError::Network(NnError::Config("broken".into())),
        };
        let o = BatchOutcome {
            done: 5,
            skipped: 2,
            failed: vec![fail("a.dng"), fail("b.dng")],
        };
        match o.failure(20) {
            Some(BatchFailure::Some(p)) => {
                assert_eq!(p.to_string(), "2 of 9 files failed: a.dng, b.dng")
            }
            other => panic!("{other:?}"),
        }
        let one = BatchOutcome {
            failed: vec![fail("a.dng")],
            ..Default::default()
        };
        match one.failure(1) {
            Some(BatchFailure::One(e)) => assert_eq!(e.to_string(), "broken"),
            other => panic!("{other:?}"),
        }
        assert!(BatchOutcome::default().failure(3).is_none());
    }

    #[test]
    fn the_manifest_may_not_be_an_input_an_output_or_inside_an_input_folder() {
        let d = scratch("check");
        let input = d.join("in");
        std::fs::create_dir(&input).unwrap();
        std::fs::write(input.join("a.dng"), b"raw").unwrap();
        let plan = vec![Job {
            input: input.join("a.dng"),
            output: d.join("a.dng"),
            png: Some(d.join("a.png")),
        }];
        let given = [input.clone()];
        let says = |m: &Path| check_manifest(m, &given, &plan).unwrap_err().to_string();
        // The input file lies in the input folder: either is named.
        let e = says(&input.join("a.dng"));
        assert!(
            e.contains("is the input") || e.contains("inside the input folder"),
            "{e}"
        );
        assert!(says(&input.join("m.jsonl")).contains("inside the input folder"));
        assert!(says(&d.join("a.png")).contains("--png and --manifest both name"));
        assert!(says(&d.join("nope/m.jsonl")).contains("does not exist"));
        check_manifest(&d.join("m.jsonl"), &given, &plan).unwrap();
        std::fs::remove_dir_all(&d).unwrap();
    }
}
