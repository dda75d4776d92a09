//! The one error of pgrf's value parsers (`FromStr` of a command-line
//! choice such as `--demosaic`, `--cfa`, `--noise K=..,read=..`).
//!
//! Every crate's parsers return it, so a caller (clap, the Python binding,
//! a config reader) handles one type: it tells whether the text named
//! nothing known, was malformed or gave a number out of range, and which
//! text was refused, beside the sentence a user reads. clap prints that
//! sentence after `error: invalid value 'x' for '--flag <F>': `, so each
//! parser words its own.

use std::fmt;

/// What kind of text a parser refused: a caller may list the choices on
/// [`ParseErrorKind::UnknownName`], show the syntax on
/// [`ParseErrorKind::Malformed`] or the range on
/// [`ParseErrorKind::OutOfRange`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParseErrorKind {
    /// A name that is none of the choices (`--demosaic fast`).
    UnknownName,
    /// Text that does not follow the value's syntax (`--noise K1.5`).
    Malformed,
    /// A well-formed number outside the range the value allows
    /// (`--noise K=0,read=1`).
    OutOfRange,
}

/// A value a parser refused: its kind, the text given, and the one-line
/// sentence that says what was expected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParseError {
    kind: ParseErrorKind,
    input: String,
    message: String,
}

impl ParseError {
    /// `input` names none of the choices; `message` says which there are.
    pub fn unknown_name(input: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(ParseErrorKind::UnknownName, input, message)
    }

    /// `input` does not follow the syntax; `message` shows it.
    pub fn malformed(input: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(ParseErrorKind::Malformed, input, message)
    }

    /// `input` is a number outside its range; `message` gives the range.
    pub fn out_of_range(input: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(ParseErrorKind::OutOfRange, input, message)
    }

    fn new(kind: ParseErrorKind, input: impl Into<String>, message: impl Into<String>) -> Self {
        ParseError {
            kind,
            input: input.into(),
            message: message.into(),
        }
    }

    /// Why the text was refused.
    pub fn kind(&self) -> ParseErrorKind {
        self.kind
    }

    /// The text refused (the whole value, or the part of it at fault).
    pub fn input(&self) -> &str {
        &self.input
    }
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for ParseError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shows_its_sentence_and_keeps_the_cause() {
        let e = ParseError::unknown_name("fast", "unknown demosaic 'fast' (bilinear or malvar)");
        assert_eq!(
            e.to_string(),
            "unknown demosaic 'fast' (bilinear or malvar)"
        );
        assert_eq!(e.kind(), ParseErrorKind::UnknownName);
        assert_eq!(e.input(), "fast");
        // What clap needs of a value parser's error.
        fn boxed(e: impl Into<Box<dyn std::error::Error + Send + Sync + 'static>>) -> String {
            e.into().to_string()
        }
        assert_eq!(boxed(e.clone()), e.to_string());
    }
}
