//! Turns panics inside third-party readers into ordinary errors.
//!
//! rawler is fuzzed but still asserts and `todo!()`s on some malformed files,
//! and so may the FITS and PyTorch readers. A user feeding pgrf a truncated
//! file must get one clear line and a non-zero exit, not a backtrace, so
//! reader calls run under `catch_unwind` and the default panic message is
//! silenced for them (including on rayon workers the reader spawns, whose
//! panics rayon re-raises on the calling thread).

use std::any::Any;
use std::cell::Cell;
use std::panic::{self, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Once;

static INSTALL: Once = Once::new();
static QUIET_CALLS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    static QUIET_HERE: Cell<bool> = const { Cell::new(false) };
}

fn install_hook() {
    INSTALL.call_once(|| {
        let previous = panic::take_hook();
        panic::set_hook(Box::new(move |info| {
            let here = QUIET_HERE.with(Cell::get);
            let worker_of_quiet_call =
                QUIET_CALLS.load(Ordering::SeqCst) > 0 && rayon::current_thread_index().is_some();
            if !(here || worker_of_quiet_call) {
                previous(info);
            }
        }));
    });
}

/// A reader that gave up by panicking: who failed and what that means
/// (`lead`), and the panic's own words when it had any, kept for a bug
/// report. Its own type, so that a caller can tell a reader's crash from
/// the reader's ordinary refusals.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Panicked {
    /// Who failed and what it means: "the RAW decoder failed on this file
    /// (malformed or truncated data?)".
    pub lead: String,
    /// The panic's message, when it was a string.
    pub message: Option<String>,
}

impl std::fmt::Display for Panicked {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.message {
            Some(m) => write!(f, "{}: {m}", self.lead),
            None => f.write_str(&self.lead),
        }
    }
}

impl std::error::Error for Panicked {}

/// Run `f`; a panic inside it becomes `Err(`[`Panicked`]`)`, led by `lead`
/// (who failed and what it means: "the RAW decoder failed on this file
/// (malformed or truncated data?)").
pub fn quietly<T>(lead: &str, f: impl FnOnce() -> T) -> Result<T, Panicked> {
    install_hook();
    let was = QUIET_HERE.with(|q| q.replace(true));
    QUIET_CALLS.fetch_add(1, Ordering::SeqCst);
    let out = panic::catch_unwind(AssertUnwindSafe(f));
    QUIET_CALLS.fetch_sub(1, Ordering::SeqCst);
    QUIET_HERE.with(|q| q.set(was));
    out.map_err(|payload| Panicked {
        lead: lead.to_string(),
        message: payload_message(payload.as_ref()),
    })
}

/// The reader's own words in a panic's payload, when they are text.
fn payload_message(p: &(dyn Any + Send)) -> Option<String> {
    if let Some(s) = p.downcast_ref::<&str>() {
        Some(s.to_string())
    } else {
        p.downcast_ref::<String>().cloned()
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn panic_becomes_error() {
        let r: Result<(), super::Panicked> =
            super::quietly("the reader failed", || panic!("boom {}", 7));
        let e = r.unwrap_err();
        assert_eq!(e.to_string(), "the reader failed: boom 7");
        assert_eq!(e.message.as_deref(), Some("boom 7"));
        let quiet = super::quietly("the reader failed", || std::panic::panic_any(7_u8));
        assert_eq!(quiet.unwrap_err().to_string(), "the reader failed");
        assert_eq!(super::quietly("unused", || 3).unwrap(), 3);
    }
}
