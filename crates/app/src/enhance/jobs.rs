//! Which files `pgrf enhance` writes where: inputs (files, and folders
//! expanded) to output paths, every path checked before any work, so that a
//! typo costs a second and no input is ever written over.

use super::Job;
use pgrf_core::paths::{require_parent_dir, same_file};
use pgrf_nn::NnError;
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// Where the previews go: none, next to each DNG, or (one input) this PNG.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Previews<'a> {
    /// No previews.
    None,
    /// Next to each DNG, with a .png extension.
    BesideEach,
    /// This file (one input only).
    At(&'a Path),
}

fn refused(flag: &'static str, message: String) -> NnError {
    NnError::BadSetting { flag, message }
}

/// The inputs: files as given, folders expanded, sorted by path with
/// repeats left out (a file named twice, in the list and on the command
/// line, or as `./a.dng` and `a.dng`, is one input); and whether a folder
/// was among them. The order is what `--shard` counts in, so every shard
/// of one command line sees the same list.
fn expand_inputs(paths: &[PathBuf]) -> Result<(Vec<PathBuf>, bool), NnError> {
    let mut inputs = Vec::new();
    let mut had_dir = false;
    for p in paths {
        if p.is_dir() {
            had_dir = true;
            inputs.extend(pgrf_raw::files::list_files(p)?);
        } else if p.is_file() {
            inputs.push(p.clone());
        } else {
            return Err(NnError::NoSuchInput(p.clone()));
        }
    }
    inputs.sort();
    let mut seen = HashSet::new();
    inputs.retain(|p| seen.insert(p.canonicalize().unwrap_or_else(|_| p.clone())));
    Ok((inputs, had_dir))
}

/// The paths `--from-list` names: one a line, blank lines and lines
/// starting with `#` left out, spaces around a path dropped. A relative
/// path is taken relative to the current folder, not the list's, which is
/// how `find . -name '*.CR2' > night.txt` writes them. Every listed path
/// must exist (a file or a folder): the first that does not is refused
/// naming the list and the line, before any work.
pub fn read_list(list: &Path) -> Result<Vec<PathBuf>, NnError> {
    let refuse = |message: String| refused("--from-list", message);
    let text = std::fs::read_to_string(list)
        .map_err(|e| refuse(format!("--from-list {}: cannot read: {e}", list.display())))?;
    let mut paths = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let path = PathBuf::from(line);
        if !path.exists() {
            return Err(refuse(format!(
                "--from-list {} line {}: {line}: no such file or folder",
                list.display(),
                i + 1
            )));
        }
        paths.push(path);
    }
    Ok(paths)
}

/// Expand folders, decide every output path (`output` is a .dng for one
/// input file, else a folder, created if its parent exists; without it each
/// result goes [`beside`] its input), and check that the outputs can be
/// written.
pub fn plan_jobs(
    paths: &[PathBuf],
    output: Option<&Path>,
    previews: Previews,
) -> Result<Vec<Job>, NnError> {
    let (mut inputs, had_dir) = expand_inputs(paths)?;
    let single = inputs.len() == 1 && !had_dir;
    check_previews(previews, single)?;
    let Some(output) = output else {
        return beside_jobs(paths, inputs, had_dir, previews);
    };
    let is_file = output_is_file(output)?;
    if single && is_file {
        return single_job(inputs.remove(0), output, previews);
    }
    if is_file {
        return Err(refused(
            "-o",
            format!(
                "-o {}: several inputs need an output folder, not one file",
                output.display()
            ),
        ));
    }
    folder_jobs(inputs, output, previews != Previews::None)
}

/// `--png PATH` names one .png preview in an existing folder, for one input.
fn check_previews(previews: Previews, single: bool) -> Result<(), NnError> {
    let Previews::At(p) = previews else {
        return Ok(());
    };
    if !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")) {
        return Err(refused("--png", format!(
            "--png {}: expected a .png path (give --png after the input files, or without a value to write previews next to the DNGs)",
            p.display()
        )));
    }
    if !single {
        return Err(refused(
            "--png",
            "--png PATH names one preview; with several inputs give --png without a value".into(),
        ));
    }
    Ok(require_parent_dir(p)?)
}

/// The preview of the result `output`: none, beside it, or `--png PATH`.
fn preview_of(output: &Path, previews: Previews) -> Option<PathBuf> {
    match previews {
        Previews::None => None,
        Previews::BesideEach => Some(output.with_extension("png")),
        Previews::At(p) => Some(p.to_path_buf()),
    }
}

/// Where a result is written without `-o`: beside its input, named
/// `NAME.pgrf.dng` (`NAME.pgrf.fits` for a FITS input), so that neither the
/// input nor another camera file of the same name is touched.
pub fn beside(input: &Path) -> PathBuf {
    let ext = output_format(input).extension();
    input.with_file_name(format!("{}.pgrf.{ext}", stem(input)))
}

/// The input's name without its extension ("out" for a path without one).
fn stem(input: &Path) -> String {
    input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into())
}

/// Claim `output` for one input: refused when another input of the plan
/// has it already (`why`, after the path, says how two inputs came to
/// share it and what to do).
fn claim(seen: &mut HashSet<PathBuf>, output: &Path, why: &str) -> Result<(), NnError> {
    if seen.insert(output.to_path_buf()) {
        return Ok(());
    }
    Err(refused(
        "-o",
        format!(
            "two inputs would both be written to {} {why}",
            output.display()
        ),
    ))
}

/// One job per input file, its result [`beside`] it. A folder is refused:
/// its results would land in the folder being read (the path rule).
fn beside_jobs(
    paths: &[PathBuf],
    inputs: Vec<PathBuf>,
    had_dir: bool,
    previews: Previews,
) -> Result<Vec<Job>, NnError> {
    if had_dir {
        let folder = paths.iter().find(|p| p.is_dir()).unwrap_or(&paths[0]);
        return Err(refused(
            "-o",
            format!(
                "{} is a folder: give -o FOLDER for its results (without -o each result is written beside its input, inside the folder being read)",
                folder.display()
            ),
        ));
    }
    let mut seen = HashSet::new();
    inputs
        .into_iter()
        .map(|input| {
            let output = beside(&input);
            let why = "(same name, another extension): give -o FOLDER";
            claim(&mut seen, &output, why)?;
            let png = preview_of(&output, previews);
            Ok(Job { input, output, png })
        })
        .collect()
}

/// The job of one input file written to the file `output`.
fn single_job(input: PathBuf, output: &Path, previews: Previews) -> Result<Vec<Job>, NnError> {
    require_parent_dir(output)?;
    if same_file(output, &input) {
        return Err(refused(
            "-o",
            format!(
                "-o {} is the input file; write the result elsewhere",
                output.display()
            ),
        ));
    }
    let png = preview_of(output, previews);
    Ok(vec![Job {
        input,
        output: output.to_path_buf(),
        png,
    }])
}

/// Whether `-o` names one output file (else a folder): a `.dng` name, or
/// a FITS name (`.fits`, `.fit`, `.fts`; an astronomy camera's frame stays
/// FITS), an existing folder, or a new folder's name without an extension.
/// Another existing file or another extension (`-o model.safetensors`) is
/// refused in one line saying what enhance writes, rather than taken for a
/// folder to create ("File exists").
pub fn output_is_file(output: &Path) -> Result<bool, NnError> {
    if output.is_dir() {
        return Ok(false);
    }
    if pgrf_raw::FrameFormat::of_path(output).is_ok() {
        return Ok(true);
    }
    let what = if output.exists() {
        // A shard of the same batch may have made the folder since the
        // first look (a folder appears whole): it is then a folder.
        if output.is_dir() {
            return Ok(false);
        }
        "is an existing file, not a folder".to_string()
    } else {
        match output.extension() {
            Some(e) => format!("has the extension .{}", e.to_string_lossy()),
            None => return Ok(false),
        }
    };
    Err(refused(
        "-o",
        format!(
            "-o {} {what}: enhance writes DNG files (FITS for FITS inputs): name one .dng or .fits (one input) or a folder (an existing one, or a new name without an extension)",
            output.display()
        ),
    ))
}

/// The format a result of `input` is written in when `-o` is a folder: FITS
/// for a FITS input (what astronomy software reads next), else DNG.
fn output_format(input: &Path) -> pgrf_raw::FrameFormat {
    match pgrf_raw::FrameFormat::of_path(input) {
        Ok(pgrf_raw::FrameFormat::Fits) => pgrf_raw::FrameFormat::Fits,
        _ => pgrf_raw::FrameFormat::Dng,
    }
}

/// One job per input into the output folder (created if missing), keeping
/// the input's name with a .dng extension (.fits for a FITS input).
fn folder_jobs(inputs: Vec<PathBuf>, folder: &Path, png: bool) -> Result<Vec<Job>, NnError> {
    if !folder.is_dir() {
        require_parent_dir(folder)?;
        // Shards started together race to create it: one that lost the
        // race finds the folder there, which is all it wanted.
        match std::fs::create_dir(folder) {
            Err(e) if !(e.kind() == std::io::ErrorKind::AlreadyExists && folder.is_dir()) => {
                return Err(NnError::Output {
                    path: folder.to_path_buf(),
                    reason: format!("cannot create the output folder: {e}"),
                })
            }
            _ => {}
        }
    }
    let mut seen = HashSet::new();
    inputs
        .into_iter()
        .map(|input| {
            let ext = output_format(&input).extension();
            let output = folder.join(format!("{}.{ext}", stem(&input)));
            claim(&mut seen, &output, "(same name in different folders)")?;
            if same_file(&output, &input) {
                return Err(refused(
                    "-o",
                    format!(
                        "{} would overwrite its input; choose another output folder",
                        output.display()
                    ),
                ));
            }
            let png = png.then(|| output.with_extension("png"));
            Ok(Job { input, output, png })
        })
        .collect()
}
