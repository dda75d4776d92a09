//! Checks on where a command will write, made before any work starts, so a
//! typo in a path costs a second rather than a finished run. Shared by the
//! program and the library recipes that plan their outputs (enhance's
//! folder jobs, calibration's masters), so that the rules exist once.

use std::path::{Path, PathBuf};

/// An output path that may not be written; renders as one line naming it
/// (and, where it came from one, the option that gave it).
#[derive(Debug, thiserror::Error)]
pub enum PathError {
    /// The folder that would hold `path` does not exist (commands write
    /// into folders, they do not make them).
    #[error("{}: folder {} does not exist", path.display(), dir.display())]
    NoFolder {
        /// The output.
        path: PathBuf,
        /// Its missing folder.
        dir: PathBuf,
    },
    /// The output is an existing folder.
    #[error("{flag} {} is a folder; give a file name", path.display())]
    IsFolder {
        /// The option that named it.
        flag: String,
        /// The output.
        path: PathBuf,
    },
    /// The output is one of the inputs.
    #[error("{flag} {} is the input {}; write the result elsewhere", path.display(), input.display())]
    IsInput {
        /// The option that named it.
        flag: String,
        /// The output.
        path: PathBuf,
        /// The input it would overwrite.
        input: PathBuf,
    },
    /// Two outputs name one file.
    #[error("{flag} and {other} both name {}; give two different files", path.display())]
    Twice {
        /// The later option.
        flag: String,
        /// The earlier option naming the same file.
        other: String,
        /// The file.
        path: PathBuf,
    },
    /// [`PathError::NoFolder`] of the output the option `flag` gave.
    #[error("{flag} {cause}")]
    Flag {
        /// The option.
        flag: String,
        /// What was wrong with its path (in the message only: one-line
        /// reports print the chain of sources, which would say it twice).
        cause: Box<PathError>,
    },
}

/// `p`'s folder must exist.
pub fn require_parent_dir(p: &Path) -> Result<(), PathError> {
    if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !dir.is_dir() {
            return Err(PathError::NoFolder {
                path: p.to_path_buf(),
                dir: dir.to_path_buf(),
            });
        }
    }
    Ok(())
}

/// Whether `a` and `b` name the same existing file (links and `..`
/// resolved); false when either does not exist.
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// `p` made absolute with its folder resolved, for comparing outputs that
/// do not exist yet.
fn resolved(p: &Path) -> PathBuf {
    let dir = p
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    match (dir.canonicalize(), p.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => p.to_path_buf(),
    }
}

/// Every check on a command's outputs, before any work: each output's
/// folder exists, no output is an existing folder, names one of `inputs`,
/// or is named twice. `outputs` pairs each path with the flag that gave it.
pub fn check_outputs(outputs: &[(&str, &Path)], inputs: &[&Path]) -> Result<(), PathError> {
    for (k, (flag, out)) in outputs.iter().enumerate() {
        require_parent_dir(out).map_err(|e| PathError::Flag {
            flag: flag.to_string(),
            cause: Box::new(e),
        })?;
        if out.is_dir() {
            return Err(PathError::IsFolder {
                flag: flag.to_string(),
                path: out.to_path_buf(),
            });
        }
        if let Some(input) = inputs.iter().find(|i| same_file(out, i)) {
            return Err(PathError::IsInput {
                flag: flag.to_string(),
                path: out.to_path_buf(),
                input: input.to_path_buf(),
            });
        }
        if let Some((other, _)) = outputs[..k]
            .iter()
            .find(|(_, o)| resolved(o) == resolved(out))
        {
            return Err(PathError::Twice {
                flag: flag.to_string(),
                other: other.to_string(),
                path: out.to_path_buf(),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_may_not_name_inputs_folders_or_each_other() {
        let d = std::env::temp_dir().join(format!("pgrf-output-test-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let input = d.join("in.dng");
        std::fs::write(&input, b"raw").unwrap();
        let fresh = d.join("out.dng");
        let ok = check_outputs(&[("-o", &fresh), ("--png", &d.join("out.png"))], &[&input]);
        assert!(ok.is_ok(), "{ok:?}");
        // The input itself, also through another spelling of its path.
        let other = d.join(".").join("in.dng");
        let e = check_outputs(&[("-o", &other)], &[&input])
            .unwrap_err()
            .to_string();
        assert!(e.contains("is the input"), "{e}");
        let e = check_outputs(&[("-o", &d)], &[]).unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
        let e = check_outputs(&[("-o", &fresh), ("--png", &d.join("./out.dng"))], &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("both name"), "{e}");
        let e = check_outputs(&[("-o", &d.join("no/such/x.dng"))], &[])
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("-o ") && e.contains("does not exist"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
