//! How many threads pgrf's work uses from Python, and the GIL released
//! while it runs. Every pgrf result is the same at any thread count (the
//! samplers draw per pixel from the seed, the sums are in fixed order), so
//! this only sets speed.
//!
//! The work always runs in a pool of this module's own, made in the process
//! that uses it: a PyTorch DataLoader forks its workers, and a forked child
//! has none of its parent's threads, so a pool (rayon's global one
//! included) made before the fork would wait forever on workers that do not
//! exist there. The pool is keyed by process id and made anew after a fork.

use pyo3::prelude::*;
use std::sync::{Arc, Mutex};

struct Pool {
    /// The process the pool's threads live in.
    pid: u32,
    /// The count asked for with `set_threads` (None: all cores).
    threads: Option<usize>,
    pool: Option<Arc<rayon::ThreadPool>>,
}

static POOL: Mutex<Pool> = Mutex::new(Pool {
    pid: 0,
    threads: None,
    pool: None,
});

/// The pool for this process, made (with the count asked for) when there
/// is none or it was made in another process.
fn pool() -> PyResult<Arc<rayon::ThreadPool>> {
    let mut p = POOL.lock().unwrap_or_else(|e| e.into_inner());
    let pid = std::process::id();
    if p.pid != pid {
        // Made before a fork: its threads are in the parent. Dropping it
        // would signal threads that are not here; leak it instead.
        if let Some(old) = p.pool.take() {
            std::mem::forget(old);
        }
        p.pid = pid;
    }
    if let Some(pool) = &p.pool {
        return Ok(pool.clone());
    }
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = p.threads {
        b = b.num_threads(n);
    }
    let pool = Arc::new(b.build().map_err(crate::errors::to_py)?);
    p.pool = Some(pool.clone());
    Ok(pool)
}

/// Run `work` without the GIL, in this process's pool; its error as the
/// Python exception ([`crate::errors::to_py`]).
pub fn run<T: Send, E: std::error::Error + Send + 'static>(
    py: Python<'_>,
    work: impl FnOnce() -> Result<T, E> + Send,
) -> PyResult<T> {
    let pool = pool()?;
    py.detach(move || pool.install(work))
        .map_err(crate::errors::to_py)
}

/// set_threads(n: int | None) -> None
///
/// Use `n` threads for pgrf's work from now on in this process; None (or 0)
/// returns to all cores (or RAYON_NUM_THREADS when set). Results do not
/// depend on it.
#[pyfunction]
#[pyo3(signature = (n=None))]
pub fn set_threads(n: Option<usize>) -> PyResult<()> {
    let threads = match n {
        None | Some(0) => None,
        Some(n) if n > 1024 => {
            return Err(crate::errors::bad(format!(
                "set_threads: {n} threads is more than 1024"
            )))
        }
        Some(n) => Some(n),
    };
    let mut p = POOL.lock().unwrap_or_else(|e| e.into_inner());
    if p.threads != threads || p.pid != std::process::id() {
        p.threads = threads;
        // The next call makes the pool (a fork's stale one is handled there).
        if p.pid == std::process::id() {
            p.pool = None;
        }
    }
    Ok(())
}

/// get_threads() -> int
///
/// The number of threads pgrf's work uses now.
#[pyfunction]
pub fn get_threads() -> PyResult<usize> {
    Ok(pool()?.current_num_threads())
}
