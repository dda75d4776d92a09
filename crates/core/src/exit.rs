//! How pgrf's programs end: whatever happened, the user reads one line on
//! stderr (`PROGRAM: error: ...`), and scripts get exit code 1 for an error.
//! Shared by the `pgrf` and `pgrf-bench` binaries.

use std::fmt::Display;
use std::process::ExitCode;

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

/// The exit code of a command's result; an error is printed as one line
/// `PROGRAM: error: ...` (with its causes, `{:#}`, newlines folded).
pub fn finish<E: Display>(program: &str, result: Result<(), E>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{}", error_line(program, &e));
            ExitCode::FAILURE
        }
    }
}

/// The line [`finish`] prints for `e`.
fn error_line<E: Display>(program: &str, e: &E) -> String {
    let msg = format!("{e:#}").replace('\n', " ");
    format!("{program}: error: {msg}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn errors_are_one_line_with_the_program_name() {
        let e = std::io::Error::other("first\nsecond");
        assert_eq!(super::error_line("pgrf", &e), "pgrf: error: first second");
    }
}
