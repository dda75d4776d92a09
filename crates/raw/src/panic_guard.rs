//! Decoder calls under [`pgrf_core::panic_guard`]: a panic inside rawler or
//! the FITS reader becomes one error line that says the file is the cause.

use pgrf_core::panic_guard::Panicked;

/// Run `f`; a panic inside it becomes `Err(`[`Panicked`]`)`, led by the
/// sentence that blames the file.
pub(crate) fn quietly<T>(f: impl FnOnce() -> T) -> Result<T, Panicked> {
    pgrf_core::panic_guard::quietly(
        "the RAW decoder failed on this file (malformed or truncated data?)",
        f,
    )
}
