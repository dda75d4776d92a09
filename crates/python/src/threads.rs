//! How many threads pgrf's work uses from Python, and the GIL released
//! while it runs. Every pgrf result is the same at any thread count (the
//! samplers draw per pixel from the seed, the sums are in fixed order), so
//! this only sets speed; a DataLoader's workers may each want 1.

use pyo3::prelude::*;
use std::sync::{Arc, Mutex};

static POOL: Mutex<Option<Arc<rayon::ThreadPool>>> = Mutex::new(None);

/// The pool set by [`set_threads`], None for rayon's global one.
fn pool() -> Option<Arc<rayon::ThreadPool>> {
    POOL.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

/// Run `work` without the GIL, in the pool [`set_threads`] chose.
pub fn run<T: Send>(py: Python<'_>, work: impl FnOnce() -> T + Send) -> T {
    let pool = pool();
    py.detach(move || match pool {
        Some(p) => p.install(work),
        None => work(),
    })
}

/// set_threads(n: int | None) -> None
///
/// Use `n` threads for pgrf's work from now on in this process; None (or 0)
/// returns to all cores (or RAYON_NUM_THREADS when set). Results do not
/// depend on it.
#[pyfunction]
#[pyo3(signature = (n=None))]
pub fn set_threads(n: Option<usize>) -> PyResult<()> {
    let new = match n {
        None | Some(0) => None,
        Some(n) if n > 1024 => {
            return Err(crate::errors::bad(format!(
                "set_threads: {n} threads is more than 1024"
            )))
        }
        Some(n) => Some(Arc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(crate::errors::to_py)?,
        )),
    };
    *POOL.lock().unwrap_or_else(|e| e.into_inner()) = new;
    Ok(())
}

/// get_threads() -> int
///
/// The number of threads pgrf's work uses now.
#[pyfunction]
pub fn get_threads() -> usize {
    match pool() {
        Some(p) => p.current_num_threads(),
        None => rayon::current_num_threads(),
    }
}
