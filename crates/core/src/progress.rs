//! The one interface through which library work reports progress. Libraries
//! take `&dyn Progress` and never draw anything; the CLI implements it once
//! over indicatif (bar, rate, ETA) and tests pass [`NoProgress`].

/// Receiver of progress reports from long library calls. `Sync`, because
/// parallel workers report from several threads.
pub trait Progress: Sync {
    /// A stage of `len` units starts (`len` 0: unknown length); `what` names
    /// the units or the stage ("frames", "tiles", "t values").
    fn start(&self, len: u64, what: &str) {
        let _ = (len, what);
    }
    /// `n` more units are done.
    fn advance(&self, n: u64);
    /// `done` units are done in all (a resumed run starts past zero).
    fn set_position(&self, done: u64) {
        let _ = done;
    }
    /// A short status shown beside the bar (loss, learning rate, ...).
    fn message(&self, msg: &str) {
        let _ = msg;
    }
    /// A line for the user, printed without breaking a bar.
    fn note(&self, line: &str) {
        let _ = line;
    }
    /// The stage is over.
    fn finish(&self) {}
}

/// Reports nowhere: for tests and quiet runs.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn advance(&self, _n: u64) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU64, Ordering};

    struct Count(AtomicU64);
    impl Progress for Count {
        fn advance(&self, n: u64) {
            self.0.fetch_add(n, Ordering::Relaxed);
        }
    }

    #[test]
    fn parallel_reports_add_up() {
        use rayon::prelude::*;
        let c = Count(AtomicU64::new(0));
        let p: &dyn Progress = &c;
        (0..1000u64).into_par_iter().for_each(|_| p.advance(2));
        assert_eq!(c.0.load(Ordering::Relaxed), 2000);
        NoProgress.advance(1);
    }
}
