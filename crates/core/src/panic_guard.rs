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

/// Run `f`; a panic inside it becomes `Err(message)`, the message led by
/// `lead` (who failed and what it means: "the RAW decoder failed on this
/// file (malformed or truncated data?)").
pub fn quietly<T>(lead: &str, f: impl FnOnce() -> T) -> Result<T, String> {
    install_hook();
    let was = QUIET_HERE.with(|q| q.replace(true));
    QUIET_CALLS.fetch_add(1, Ordering::SeqCst);
    let out = panic::catch_unwind(AssertUnwindSafe(f));
    QUIET_CALLS.fetch_sub(1, Ordering::SeqCst);
    QUIET_HERE.with(|q| q.set(was));
    out.map_err(|payload| payload_message(lead, payload.as_ref()))
}

/// What a user reads when a reader gave up by panicking: `lead`, and the
/// reader's own words kept for a bug report.
fn payload_message(lead: &str, p: &(dyn Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        format!("{lead}: {s}")
    } else if let Some(s) = p.downcast_ref::<String>() {
        format!("{lead}: {s}")
    } else {
        lead.to_string()
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn panic_becomes_error() {
        let r: Result<(), String> = super::quietly("the reader failed", || panic!("boom {}", 7));
        assert_eq!(r.unwrap_err(), "the reader failed: boom 7");
        assert_eq!(super::quietly("unused", || 3).unwrap(), 3);
    }
}
