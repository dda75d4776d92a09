//! Turns panics inside the third-party decoder into ordinary errors.
//!
//! rawler is fuzzed but still asserts and `todo!()`s on some malformed files.
//! A user feeding pgrf a truncated RAW must get one clear line and a non-zero
//! exit, not a backtrace, so decoder calls run under `catch_unwind` and the
//! default panic message is silenced for them (including on rayon workers the
//! decoder spawns, whose panics rayon re-raises on the calling thread).

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

/// Run `f`; a panic inside it becomes `Err(message)`.
pub(crate) fn quietly<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    install_hook();
    let was = QUIET_HERE.with(|q| q.replace(true));
    QUIET_CALLS.fetch_add(1, Ordering::SeqCst);
    let out = panic::catch_unwind(AssertUnwindSafe(f));
    QUIET_CALLS.fetch_sub(1, Ordering::SeqCst);
    QUIET_HERE.with(|q| q.set(was));
    out.map_err(|payload| payload_message(payload.as_ref()))
}

/// What a user reads when the decoder gave up by panicking: the file is
/// malformed (or a format variant the decoder gets wrong), and the
/// decoder's own words are kept for a bug report.
fn payload_message(p: &(dyn Any + Send)) -> String {
    const LEAD: &str = "the RAW decoder failed on this file (malformed or truncated data?)";
    if let Some(s) = p.downcast_ref::<&str>() {
        format!("{LEAD}: {s}")
    } else if let Some(s) = p.downcast_ref::<String>() {
        format!("{LEAD}: {s}")
    } else {
        LEAD.to_string()
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn panic_becomes_error() {
        let r: Result<(), String> = super::quietly(|| panic!("boom {}", 7));
        assert_eq!(
            r.unwrap_err(),
            "the RAW decoder failed on this file (malformed or truncated data?): boom 7"
        );
        assert_eq!(super::quietly(|| 3).unwrap(), 3);
    }
}
