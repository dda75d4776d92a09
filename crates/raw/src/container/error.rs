//! Why a file's structure is refused before rawler reads it: the cause a
//! caller may act on (a file cut short can be fetched or written again; a
//! malformed or contradictory one cannot), and the one-line message that
//! says where.

use std::fmt;

/// The kind of fault a structure check found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cause {
    /// The structure itself is malformed: loops, offsets or counts outside
    /// the file, more entries or boxes than any file holds.
    Malformed,
    /// Image data the structure declares run past the end of the file.
    Truncated,
    /// A DNG whose tags contradict its data (bits, tiles, strips).
    Inconsistent,
    /// Data that do not decode whole (a cut LJPEG stream), or a header
    /// claiming an image no file holds.
    Damaged,
    /// A tag pgrf reads (NoiseProfile) that cannot be used.
    BadTag,
}

/// A refused structure: its cause and the message (which names the fault
/// and where it is; the structures it was found inside are appended by
/// `ContainerError::within`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ContainerError {
    /// What kind of fault.
    pub cause: Cause,
    message: String,
}

impl fmt::Display for ContainerError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for ContainerError {}

impl ContainerError {
    /// A malformed structure, in `message`'s words.
    pub(crate) fn malformed(message: String) -> Self {
        ContainerError {
            cause: Cause::Malformed,
            message,
        }
    }

    /// Image data cut short.
    pub(crate) fn truncated(message: String) -> Self {
        ContainerError {
            cause: Cause::Truncated,
            message,
        }
    }

    /// A DNG contradicting itself.
    pub(crate) fn inconsistent(message: String) -> Self {
        ContainerError {
            cause: Cause::Inconsistent,
            message,
        }
    }

    /// Data that do not decode whole, or a header claiming more than a file
    /// holds.
    pub(crate) fn damaged(message: String) -> Self {
        ContainerError {
            cause: Cause::Damaged,
            message,
        }
    }

    /// A tag that cannot be used.
    pub(crate) fn bad_tag(message: String) -> Self {
        ContainerError {
            cause: Cause::BadTag,
            message,
        }
    }

    /// The same fault, found inside `context` ("in the MakerNote at byte
    /// 812"): appended in parentheses.
    pub(crate) fn within(self, context: impl fmt::Display) -> Self {
        ContainerError {
            cause: self.cause,
            message: format!("{} ({context})", self.message),
        }
    }
}
