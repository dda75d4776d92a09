//! How pgrf's programs end: whatever happened, the user reads one line on
//! stderr (`PROGRAM: error: ...`), and scripts read the outcome from the exit
//! code: 0 done, 1 the command failed, 2 a usage error (clap's), 3 a batch
//! finished but some of its items failed ([`PartialFailure`]), so a job
//! scheduler can tell "retry the whole thing" from "look at these files".
//! Shared by the `pgrf` and `pgrf-bench` binaries.

use std::error::Error;
use std::fmt::Display;
use std::process::ExitCode;

/// The exit code of a command that failed as a whole.
pub const EXIT_FAILURE: u8 = 1;
/// The exit code of a batch that processed every item it could but some
/// failed ([`PartialFailure`]).
pub const EXIT_PARTIAL: u8 = 3;

/// A batch ran to its end and some of its items failed (each already
/// reported on its own): [`finish`] prints this one line and exits with
/// [`EXIT_PARTIAL`] instead of 1, wherever it sits in the error's chain.
#[derive(Debug)]
pub struct PartialFailure {
    /// How many items the batch had.
    pub total: usize,
    /// The items that failed, as the user named them.
    pub failed: Vec<String>,
}

/// How many failed items [`PartialFailure`]'s line names; the rest are
/// counted (each was reported on its own line, and in a manifest).
const NAMED: usize = 10;

impl Display for PartialFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.failed.len();
        write!(f, "{n} of {} files failed: ", self.total)?;
        write!(f, "{}", self.failed[..n.min(NAMED)].join(", "))?;
        if n > NAMED {
            write!(f, " and {} more", n - NAMED)?;
        }
        Ok(())
    }
}

impl Error for PartialFailure {}

/// The exit code for error `e`: [`EXIT_PARTIAL`] when a [`PartialFailure`]
/// is in its chain of causes, else [`EXIT_FAILURE`].
pub fn exit_code_of(e: &(dyn Error + 'static)) -> u8 {
    let mut next: Option<&(dyn Error + 'static)> = Some(e);
    while let Some(err) = next {
        if err.is::<PartialFailure>() {
            return EXIT_PARTIAL;
        }
        next = err.source();
    }
    EXIT_FAILURE
}

/// Make a panic print one line, `PROGRAM: internal error (please report):
/// MESSAGE at FILE:LINE`, instead of Rust's multi-line report. A panic about
/// a broken pipe (`pgrf info x | head -1`: the reader went away) exits 0
/// quietly: it is not an error of ours.
pub fn one_line_panics(program: &'static str) {
    std::panic::set_hook(Box::new(move |info| {
        let msg = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        if msg.contains("Broken pipe") {
            std::process::exit(0);
        }
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        eprintln!("{program}: internal error (please report): {msg}{at}");
    }));
}

/// The exit code of a command's result ([`exit_code_of`]); an error is
/// printed as one line `PROGRAM: error: ...` (with its causes, `{:#}`,
/// newlines folded).
pub fn finish<E>(program: &str, result: Result<(), E>) -> ExitCode
where
    E: Display + AsRef<dyn Error + Send + Sync + 'static>,
{
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{}", error_line(program, &e));
            let err: &(dyn Error + Send + Sync + 'static) = e.as_ref();
            ExitCode::from(exit_code_of(err))
        }
    }
}

/// The line [`finish`] prints for `e`.
fn error_line<E: Display>(program: &str, e: &E) -> String {
    let msg = format!("{e:#}").replace('\n', " ");
    format!("{program}: error: {msg}")
}

/// A flag renamed so that one name means one thing in every command:
/// (command, old spelling, new spelling). The old spelling keeps parsing
/// (a clap alias) for one release; [`renamed_notes`] names the new one.
pub type Renamed = (&'static str, &'static str, &'static str);

/// One note per old spelling among `args` (the process arguments) of
/// `command`, `--old` or `--old=VALUE`; printed by [`note_renamed`].
pub fn renamed_notes(renamed: &[Renamed], command: &str, args: &[String]) -> Vec<String> {
    renamed
        .iter()
        .filter(|(c, old, _)| {
            *c == command
                && args
                    .iter()
                    .any(|a| a == old || a.starts_with(&format!("{old}=")))
        })
        .map(|(c, old, new)| {
            format!("`{c} {old}` is now `{c} {new}`; the old spelling goes in the next release")
        })
        .collect()
}

/// Print `PROGRAM: note: ...` on stderr for each old spelling this
/// process was given ([`renamed_notes`]).
pub fn note_renamed(program: &str, renamed: &[Renamed], command: &str) {
    let args: Vec<String> = std::env::args().collect();
    for note in renamed_notes(renamed, command, &args) {
        eprintln!("{program}: note: {note}");
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn errors_are_one_line_with_the_program_name() {
        let e = std::io::Error::other("first\nsecond");
        assert_eq!(super::error_line("pgrf", &e), "pgrf: error: first second");
    }

    /// A partial failure gives code 3 wherever it sits in the chain (under
    /// a context, say); any other error 1.
    #[test]
    fn a_partial_failure_anywhere_in_the_chain_exits_3() {
        #[derive(Debug, thiserror::Error)]
        #[error("while enhancing")]
        struct Context(#[source] super::PartialFailure);
        let partial = super::PartialFailure {
            total: 7,
            failed: vec!["a.dng".into(), "b.dng".into()],
        };
        assert_eq!(partial.to_string(), "2 of 7 files failed: a.dng, b.dng");
        let many = super::PartialFailure {
            total: 30,
            failed: (0..12).map(|i| format!("{i}.dng")).collect(),
        };
        assert!(many.to_string().ends_with(", 9.dng and 2 more"), "{many}");
        assert_eq!(super::exit_code_of(&Context(partial)), 3);
        assert_eq!(super::exit_code_of(&std::io::Error::other("x")), 1);
    }

    #[test]
    fn an_old_spelling_is_named_once_for_its_own_command() {
        let renamed = [("synth", "--model", "--noise-model")];
        let args = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let note = "`synth --model` is now `synth --noise-model`; the old spelling goes in the next release";
        let given = args(&["pgrf", "synth", "--model=eld", "x.dng"]);
        assert_eq!(super::renamed_notes(&renamed, "synth", &given), [note]);
        let given = args(&["pgrf", "synth", "--model", "eld"]);
        assert_eq!(super::renamed_notes(&renamed, "synth", &given), [note]);
        let new = args(&["pgrf", "synth", "--noise-model", "eld"]);
        assert!(super::renamed_notes(&renamed, "synth", &new).is_empty());
        let other = args(&["pgrf", "enhance", "--model", "m.safetensors"]);
        assert!(super::renamed_notes(&renamed, "enhance", &other).is_empty());
    }
}
