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
    /// into folders, they do not make them), or, for a [`Kind::Tree`], its
    /// nearest existing ancestor `dir` is not a folder.
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
    /// A folder output names an existing file.
    #[error("{flag} {} is a file; give a folder", path.display())]
    IsFile {
        /// The option that named it.
        flag: String,
        /// The output.
        path: PathBuf,
    },
    /// The output lies inside an input folder, where it would join the
    /// inputs (and the next run would read it as one).
    #[error("{flag} {} is inside the input folder {}{}; write the result outside it", path.display(), input.display(), named_by(input_flag))]
    InsideInput {
        /// The option that named the output.
        flag: String,
        /// The output.
        path: PathBuf,
        /// The option that named the input folder.
        input_flag: String,
        /// The input folder.
        input: PathBuf,
    },
    /// The output folder holds an input, which its files could replace.
    #[error("{flag} {} holds the input {}{}; write the result into a folder without inputs", path.display(), input.display(), named_by(input_flag))]
    HoldsInput {
        /// The option that named the output folder.
        flag: String,
        /// The output folder.
        path: PathBuf,
        /// The option that named the input.
        input_flag: String,
        /// The input inside it.
        input: PathBuf,
    },
    /// Two outputs name one path (or one output folder lies in another).
    #[error("{flag} and {other} both name {}; give two different paths", path.display())]
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

/// " (FLAG)" after an input the option `flag` named; nothing for a
/// positional input (`flag` empty).
fn named_by(flag: &str) -> String {
    if flag.is_empty() {
        String::new()
    } else {
        format!(" ({flag})")
    }
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

/// `p` made absolute with links and `..` resolved as far as it exists: the
/// whole path when it exists, else its nearest existing ancestor's
/// resolution joined with the rest (an output not written yet, and the
/// folders a [`Kind::Tree`] creates), else `p` joined to the current folder.
fn resolved(p: &Path) -> PathBuf {
    if let Ok(c) = p.canonicalize() {
        return c;
    }
    // The nearest ancestor that exists, resolved; below it nothing exists,
    // so no link can hide there and `..` and `.` are taken lexically.
    for base in p.ancestors().skip(1) {
        let dir = if base.as_os_str().is_empty() {
            Path::new(".")
        } else {
            base
        };
        if let (Ok(d), Ok(rest)) = (dir.canonicalize(), p.strip_prefix(base)) {
            let mut out = d;
            for c in rest.components() {
                match c {
                    std::path::Component::ParentDir => {
                        out.pop();
                    }
                    std::path::Component::Normal(n) => out.push(n),
                    _ => {}
                }
            }
            return out;
        }
    }
    std::env::current_dir()
        .map(|c| c.join(p))
        .unwrap_or_else(|_| p.to_path_buf())
}

/// A [`Kind::Tree`]'s check: the nearest of its ancestors that exists must
/// be a folder, for the missing ones to be made in it.
pub fn require_tree_root(p: &Path) -> Result<(), PathError> {
    let mut dir = p.parent();
    while let Some(d) = dir.filter(|d| !d.as_os_str().is_empty()) {
        if d.exists() {
            return if d.is_dir() {
                Ok(())
            } else {
                Err(PathError::NoFolder {
                    path: p.to_path_buf(),
                    dir: d.to_path_buf(),
                })
            };
        }
        dir = d.parent();
    }
    Ok(())
}

/// What an output is: a file the command writes, or a folder it writes
/// files into (created if missing).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// One file.
    File,
    /// A folder of files (its parent must exist).
    Folder,
    /// A folder of files that the command creates with any missing parent
    /// folders (`create_dir_all`): the nearest existing ancestor must be a
    /// folder.
    Tree,
}

impl Kind {
    /// A folder, with or without its parents made.
    fn is_folder(self) -> bool {
        matches!(self, Kind::Folder | Kind::Tree)
    }
}

/// A path and the option that named it.
#[derive(Clone, Debug)]
struct Named {
    flag: String,
    path: PathBuf,
}

/// Everything a command reads and writes, declared before any work so that
/// one rule ([`Io::check`]) decides for every command whether its outputs
/// are safe to write: no output may be an input, sit inside an input
/// folder or, as a folder, hold an input; no two outputs may share a path.
/// Inputs that do not exist (a built-in model's name, a profile name) are
/// not files and are passed over; the command reports them itself.
#[derive(Clone, Debug, Default)]
pub struct Io {
    inputs: Vec<Named>,
    outputs: Vec<(Named, Kind)>,
}

impl Io {
    /// Nothing read or written yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// `path` (a file or a folder) is read; `flag` names it in messages
    /// (empty for positional arguments).
    pub fn input(&mut self, flag: &str, path: impl AsRef<Path>) -> &mut Self {
        self.inputs.push(Named {
            flag: flag.to_string(),
            path: path.as_ref().to_path_buf(),
        });
        self
    }

    /// Each of `paths` is read.
    pub fn inputs<P: AsRef<Path>>(
        &mut self,
        flag: &str,
        paths: impl IntoIterator<Item = P>,
    ) -> &mut Self {
        for p in paths {
            self.input(flag, p);
        }
        self
    }

    /// The file `path` is written.
    pub fn file(&mut self, flag: &str, path: impl AsRef<Path>) -> &mut Self {
        self.output(flag, path, Kind::File)
    }

    /// Files are written into the folder `path`.
    pub fn folder(&mut self, flag: &str, path: impl AsRef<Path>) -> &mut Self {
        self.output(flag, path, Kind::Folder)
    }

    /// `path` is written, as a file or a folder of files.
    pub fn output(&mut self, flag: &str, path: impl AsRef<Path>, kind: Kind) -> &mut Self {
        let named = Named {
            flag: flag.to_string(),
            path: path.as_ref().to_path_buf(),
        };
        self.outputs.push((named, kind));
        self
    }

    /// `path`, where given, is written.
    pub fn output_opt(
        &mut self,
        flag: &str,
        path: Option<impl AsRef<Path>>,
        kind: Kind,
    ) -> &mut Self {
        if let Some(p) = path {
            self.output(flag, p, kind);
        }
        self
    }

    /// The rule, checked on the paths alone (nothing is read or written):
    /// every output's folder exists; a file output is not an existing
    /// folder and a folder output not an existing file; no output is an
    /// input, inside an input folder or (a folder) around an input; no two
    /// outputs name one path, and no output folder lies in another.
    pub fn check(&self) -> Result<(), PathError> {
        let inputs: Vec<(&Named, PathBuf, bool)> = self
            .inputs
            .iter()
            .filter(|i| i.path.exists())
            .map(|i| (i, resolved(&i.path), i.path.is_dir()))
            .collect();
        let mut seen: Vec<(&Named, PathBuf, Kind)> = Vec::new();
        for (out, kind) in &self.outputs {
            let flag = out.flag.clone();
            let path = out.path.clone();
            let parent = if *kind == Kind::Tree {
                require_tree_root(&path)
            } else {
                require_parent_dir(&path)
            };
            parent.map_err(|e| PathError::Flag {
                flag: flag.clone(),
                cause: Box::new(e),
            })?;
            match kind {
                Kind::File if path.is_dir() => return Err(PathError::IsFolder { flag, path }),
                Kind::Folder | Kind::Tree if path.exists() && !path.is_dir() => {
                    return Err(PathError::IsFile { flag, path })
                }
                _ => {}
            }
            let at = resolved(&path);
            for (input, place, is_dir) in &inputs {
                // `resolved` canonicalises what exists, so an output that is
                // an input (through links or `..`) resolves to its place.
                if at == *place {
                    return Err(PathError::IsInput {
                        flag,
                        path,
                        input: input.path.clone(),
                    });
                }
                if *is_dir && at.starts_with(place) {
                    return Err(PathError::InsideInput {
                        flag,
                        path,
                        input_flag: input.flag.clone(),
                        input: input.path.clone(),
                    });
                }
                if kind.is_folder() && place.starts_with(&at) {
                    return Err(PathError::HoldsInput {
                        flag,
                        path,
                        input_flag: input.flag.clone(),
                        input: input.path.clone(),
                    });
                }
            }
            for (other, place, other_kind) in &seen {
                let nested = kind.is_folder()
                    && other_kind.is_folder()
                    && (at.starts_with(place) || place.starts_with(&at));
                if at == *place || nested {
                    return Err(PathError::Twice {
                        flag,
                        other: other.flag.clone(),
                        path,
                    });
                }
            }
            seen.push((out, at, *kind));
        }
        Ok(())
    }
}

/// Every check on a command's output files, before any work: [`Io::check`]
/// with `outputs` (each paired with the flag that gave it) as files and
/// `inputs` as read.
pub fn check_outputs(outputs: &[(&str, &Path)], inputs: &[&Path]) -> Result<(), PathError> {
    let mut io = Io::new();
    io.inputs("", inputs);
    for (flag, out) in outputs {
        io.file(flag, out);
    }
    io.check()
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

    /// A folder made with its parents (`--report out/report` where `out`
    /// does not exist yet) is accepted, but not under a file, nor (through
    /// folders not made yet) inside an input folder, nor twice.
    #[test]
    fn a_tree_output_may_have_missing_parents() {
        let d = std::env::temp_dir().join(format!("pgrf-tree-test-{}", std::process::id()));
        let stack = d.join("bias");
        std::fs::create_dir_all(&stack).unwrap();
        std::fs::write(d.join("file"), b"x").unwrap();
        let check = |outs: &[(&str, PathBuf)]| {
            let mut io = Io::new();
            io.input("--bias", &stack);
            for (flag, p) in outs {
                io.output(flag, p, Kind::Tree);
            }
            io.check().map_err(|e| e.to_string())
        };
        assert_eq!(check(&[("--report", d.join("out/more/report"))]), Ok(()));
        let e = check(&[("--report", d.join("file/report"))]).unwrap_err();
        assert!(e.starts_with("--report ") && e.contains("file"), "{e}");
        let e = check(&[("--report", stack.join("new/report"))]).unwrap_err();
        assert!(e.contains("inside the input folder"), "{e}");
        let e = check(&[
            ("--report", d.join("out/r")),
            ("--masters", d.join("out/../out/r/m")),
        ])
        .unwrap_err();
        assert!(e.contains("both name"), "{e}");
        // Still refused for a plain folder.
        let mut io = Io::new();
        io.folder("-o", d.join("out/report"));
        assert!(io
            .check()
            .unwrap_err()
            .to_string()
            .contains("does not exist"));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn outputs_keep_out_of_input_folders_and_away_from_each_other() {
        let d = std::env::temp_dir().join(format!("pgrf-io-test-{}", std::process::id()));
        let stack = d.join("bias");
        std::fs::create_dir_all(&stack).unwrap();
        std::fs::write(stack.join("f1.dng"), b"raw").unwrap();
        let model = d.join("m.safetensors");
        std::fs::write(&model, b"w").unwrap();
        let check = |outs: &[(&str, PathBuf, Kind)]| {
            let mut io = Io::new();
            io.input("--bias", &stack).input("--model", &model);
            io.input("--profile", "builtin-name-not-a-file");
            for (flag, p, kind) in outs {
                io.output(flag, p, *kind);
            }
            io.check().map_err(|e| e.to_string())
        };
        // Beside the inputs, a file and a folder (new or existing) are fine,
        // and so is a file in an output folder.
        std::fs::create_dir_all(d.join("report")).unwrap();
        let ok = check(&[
            ("-o", d.join("c.safetensors"), Kind::File),
            ("--report", d.join("report"), Kind::Folder),
            ("--log", d.join("report").join("log.csv"), Kind::File),
        ]);
        assert_eq!(ok, Ok(()));
        // The model through another spelling.
        let e = check(&[("--csv", d.join("bias/../m.safetensors"), Kind::File)]).unwrap_err();
        assert!(e.contains("is the input"), "{e}");
        // A file or folder inside the stack, even one not made yet.
        for (p, kind) in [
            (stack.join("c.safetensors"), Kind::File),
            (stack.join("masters"), Kind::Folder),
            (stack.clone(), Kind::Folder),
        ] {
            let e = check(&[("--masters", p, kind)]).unwrap_err();
            assert!(
                e.contains("inside the input folder") && e.contains("(--bias)")
                    || e.contains("is the input"),
                "{e}"
            );
        }
        // A folder around an input: the stack's parent holds it.
        let e = check(&[("--dump", d.clone(), Kind::Folder)]).unwrap_err();
        assert!(
            e.contains("holds the input")
                && e.ends_with("(--bias); write the result into a folder without inputs"),
            "{e}"
        );
        // A folder output that is a file, two outputs on one path, one
        // output folder in another.
        let e = check(&[("--report", model.clone(), Kind::Folder)]).unwrap_err();
        assert!(
            e.contains("is a file; give a folder") || e.contains("is the input"),
            "{e}"
        );
        let r = d.join("r.csv");
        let e = check(&[
            ("--csv", r.clone(), Kind::File),
            ("--markdown", r, Kind::File),
        ])
        .unwrap_err();
        assert_eq!(
            e,
            format!(
                "--markdown and --csv both name {}; give two different paths",
                d.join("r.csv").display()
            )
        );
        std::fs::create_dir_all(d.join("out")).unwrap();
        let e = check(&[
            ("--report", d.join("out"), Kind::Folder),
            ("--masters", d.join("out").join("m"), Kind::Folder),
        ])
        .unwrap_err();
        assert!(e.contains("--masters and --report both name"), "{e}");
        std::fs::write(d.join("plain"), b"x").unwrap();
        let e = check(&[("--report", d.join("plain"), Kind::Folder)]).unwrap_err();
        assert!(e.ends_with("is a file; give a folder"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
