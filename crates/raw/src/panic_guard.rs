//! Decoder calls under [`pgrf_core::panic_guard`]: a panic inside rawler or
//! the FITS reader becomes one error line that says the file is the cause.

/// Run `f`; a panic inside it becomes `Err(message)`.
pub(crate) fn quietly<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    pgrf_core::panic_guard::quietly(
        "the RAW decoder failed on this file (malformed or truncated data?)",
        f,
    )
}
