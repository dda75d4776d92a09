//! What every command reads and writes, declared in one place and checked
//! by one rule ([`pgrf_core::paths::Io::check`]) before the command starts:
//! no output may be an input, sit inside an input folder or, as a folder,
//! hold an input, and no two outputs may share a path. A command that adds
//! a path option declares it here.

use crate::cmd;
use crate::Command;
use anyhow::Result;
use pgrf_core::paths::{Io, Kind};
use std::path::{Path, PathBuf};

/// Check `command`'s paths (and the global `--darktable-profiles` file,
/// which every command may read) before any work.
pub fn check(command: &Command, darktable_profiles: Option<&Path>) -> Result<()> {
    let mut io = Io::new();
    if let Some(p) = darktable_profiles {
        io.input("--darktable-profiles", p);
    }
    declare(command, &mut io)?;
    io.check()?;
    Ok(())
}

/// The files a camera-profile option names (`dng:FILE`, a JSON file, in a
/// mix of several); built-in and darktable names are no files and are
/// passed over by the check.
fn profile_files(spec: &str) -> Vec<PathBuf> {
    pgrf_noise::mix::parse_profiles(spec)
        .map(|entries| {
            entries
                .into_iter()
                .map(|e| PathBuf::from(e.name.strip_prefix("dng:").unwrap_or(&e.name)))
                .collect()
        })
        .unwrap_or_default()
}

fn declare(command: &Command, io: &mut Io) -> Result<()> {
    match command {
        Command::Demo(a) => {
            io.inputs("--photo", &a.photo)
                .inputs("--spc", &a.spc)
                .inputs("--pgrf", &a.pgrf)
                .folder("-o", &a.output);
        }
        Command::Info(a) => {
            io.input("", &a.file);
        }
        Command::Metrics(a) => {
            io.input("", &a.output).input("", &a.reference);
        }
        Command::Profiles(_) => {}
        Command::Preview(a) => {
            io.input("", &a.file).file("-o", &a.output);
        }
        Command::Convert(a) => {
            io.input("", &a.file).file("-o", &a.output);
        }
        Command::Chart(a) => {
            io.file("-o", &a.output);
        }
        Command::Synth(a) => declare_synth(a, io),
        Command::SimulateSensor(a) => {
            io.folder("-o", &a.output);
        }
        Command::MakeDataset(a) => {
            io.folder("-o", &a.output);
        }
        Command::Calibrate(a) => declare_calibrate(a, io),
        Command::Reduce(a) => {
            io.inputs("", &a.lights)
                .input("--masters", &a.masters)
                .input("--calib", &a.calib)
                .output("-o", &a.output, Kind::Tree);
        }
        Command::Train(a) => declare_train(a, io)?,
        Command::Enhance(a) => declare_enhance(a, io)?,
        Command::Search(a) => {
            let r = a.request(Default::default());
            io.input("--model", &r.model)
                .inputs("--val", &a.val)
                .inputs("--calib", &a.calib)
                .file("--plot", &r.plot);
        }
        Command::Eval(a) => declare_eval(a, io)?,
        Command::ImportWeights(a) => {
            io.input("", &a.file).file("-o", &a.output);
        }
        Command::ExportWeights(a) => {
            io.input("", &a.model).file("-o", &a.output);
        }
    }
    Ok(())
}

fn declare_synth(a: &cmd::synth::SynthArgs, io: &mut Io) {
    io.input("", &a.clean)
        .inputs("--calib", &a.calib)
        .inputs("--profile", profile_files(&a.profile))
        .file("-o", &a.output)
        .output_opt("--png", a.png.as_ref(), Kind::File);
}

fn declare_calibrate(a: &cmd::calibrate::CalibrateArgs, io: &mut Io) {
    io.input("--bias", &a.bias)
        .inputs("--dark", &a.dark)
        .input("--flat", &a.flat)
        .file("-o", &a.output)
        .output_opt("--report", a.report.as_ref(), Kind::Tree)
        .output_opt("--masters", a.masters.as_ref(), Kind::Tree);
    let (flag, darktable) =
        pgrf_calib::outputs::darktable_file(a.darktable_into.as_deref(), &a.output);
    io.file(flag, darktable);
}

fn declare_train(a: &cmd::train::TrainArgs, io: &mut Io) -> Result<()> {
    io.inputs("--config", &a.config);
    let config = a.settings.merge(a.config.as_deref(), a.method)?;
    io.inputs("--data", config.input_files())
        .inputs("--profile", profile_files(&config.profile));
    if a.print_config {
        return Ok(());
    }
    let out = config.outputs()?;
    io.file("-o", &out.weights)
        .file("--checkpoint", &out.checkpoint)
        .file("--log", &out.log);
    Ok(())
}

fn declare_enhance(a: &cmd::enhance::EnhanceArgs, io: &mut Io) -> Result<()> {
    let e = &a.enhance;
    // The files a list names are inputs too (a list that cannot be read
    // is reported by the command itself).
    let listed = (e.from_list.as_deref())
        .and_then(|l| pgrf_app::enhance::jobs::read_list(l).ok())
        .unwrap_or_default();
    io.inputs("", &e.inputs)
        .inputs("--from-list", &e.from_list)
        .inputs("--from-list", &listed)
        .inputs("--model", &e.model)
        .inputs("--calib", &e.calib)
        .output_opt("--manifest", e.manifest.as_ref(), Kind::File);
    match &e.output {
        Some(o) => {
            let is_file = pgrf_app::enhance::jobs::output_is_file(o)?;
            let kind = if is_file { Kind::File } else { Kind::Folder };
            io.output("-o", o, kind);
        }
        // Each result beside its input file (a folder input, and two
        // inputs whose results share a name, are refused by the plan with
        // their own words).
        None => {
            let files = e.inputs.iter().chain(&listed).filter(|p| !p.is_dir());
            let beside: std::collections::BTreeSet<PathBuf> =
                files.map(|p| pgrf_app::enhance::jobs::beside(p)).collect();
            for output in beside {
                io.file("-o", output);
            }
        }
    }
    if let Some(Some(png)) = &e.png {
        io.file("--png", png);
    }
    Ok(())
}

fn declare_eval(a: &cmd::eval::EvalArgs, io: &mut Io) -> Result<()> {
    let e = &a.eval;
    io.inputs("--root", &e.root)
        .inputs("--model", &a.model)
        .inputs("--list", &e.list)
        .inputs(
            "--profile",
            e.profile.as_deref().map(profile_files).unwrap_or_default(),
        );
    for item in &e.outputs {
        if let Some((_, dir)) = item.split_once('=') {
            io.input("--outputs", dir);
        }
    }
    io.output_opt("--csv", e.csv.as_ref(), Kind::File)
        .output_opt("--markdown", e.markdown.as_ref(), Kind::File)
        .output_opt(
            if e.worst.is_some() {
                "--worst"
            } else {
                "--worst (beside --csv)"
            },
            pgrf_eval::worst_path(e.worst.as_deref(), e.csv.as_deref()).as_ref(),
            Kind::File,
        )
        .output_opt("--dump", e.dump.as_ref(), Kind::Folder);
    Ok(())
}
