//! Decoded training images kept in memory up to a byte budget, shared by
//! the RAW-folder and photo sources: beyond the budget an image is decoded
//! again each time it is drawn, so memory stays bounded whatever the
//! folder's size.

use crate::error::Result;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Images by index, and the bytes they hold, under one lock.
pub(crate) struct BudgetCache<T> {
    held: Mutex<(HashMap<usize, Arc<T>>, usize)>,
    budget_bytes: usize,
}

impl<T> BudgetCache<T> {
    /// An empty cache of `budget_mib` MiB (0 keeps nothing).
    pub(crate) fn new(budget_mib: usize) -> BudgetCache<T> {
        BudgetCache {
            held: Mutex::new((HashMap::new(), 0)),
            budget_bytes: budget_mib << 20,
        }
    }

    /// Keep image `i` (of `bytes` bytes) if it fits in what is left of the
    /// budget and is not held yet.
    pub(crate) fn offer(&self, i: usize, img: &Arc<T>, bytes: usize) {
        let mut held = self.held.lock().expect("cache lock");
        if held.1 + bytes <= self.budget_bytes && !held.0.contains_key(&i) {
            held.1 += bytes;
            held.0.insert(i, img.clone());
        }
    }

    /// Image `i`: the held one, or `load()`ed (and offered, `bytes` telling
    /// its size). The lock is not held while loading.
    pub(crate) fn get_or_load(
        &self,
        i: usize,
        load: impl FnOnce() -> Result<T>,
        bytes: impl Fn(&T) -> usize,
    ) -> Result<Arc<T>> {
        if let Some(img) = self.held.lock().expect("cache lock").0.get(&i) {
            return Ok(img.clone());
        }
        let img = Arc::new(load()?);
        self.offer(i, &img, bytes(&img));
        Ok(img)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_what_fits_and_reloads_the_rest() {
        let cache = BudgetCache::<Vec<u8>>::new(1);
        let loads = std::cell::Cell::new(0);
        let load = |n: usize| {
            loads.set(loads.get() + 1);
            Ok(vec![0u8; n])
        };
        let mib = 1 << 20;
        let a = cache.get_or_load(0, || load(mib / 2), |v| v.len()).unwrap();
        cache.get_or_load(0, || load(mib / 2), |v| v.len()).unwrap();
        assert_eq!(loads.get(), 1, "held: no second load");
        // 3/4 MiB does not fit beside the 1/2 MiB held: loaded each time.
        cache
            .get_or_load(1, || load(3 * mib / 4), |v| v.len())
            .unwrap();
        cache
            .get_or_load(1, || load(3 * mib / 4), |v| v.len())
            .unwrap();
        assert_eq!(loads.get(), 3);
        assert_eq!(a.len(), mib / 2);
    }
}
