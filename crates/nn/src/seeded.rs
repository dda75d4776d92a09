//! Seeded use of burn's random generator.
//!
//! burn draws initial weights (and `Tensor::random`) from one generator per
//! backend, shared by the whole process. Seeding it and then drawing is only
//! reproducible if no other thread seeds or draws in between: two trainings
//! in one process, or tests running in parallel, would otherwise get
//! different weights for the same seed (seen as a tiling test whose numbers
//! changed between runs). Every seeded draw in pgrf goes through [`seeded`],
//! which holds one process-wide lock while it seeds and runs its closure.
//! burn initialises parameters lazily, on first use, so a module made inside
//! the closure must also be materialised there ([`materialise`]); otherwise
//! its weights are drawn later, outside the lock.

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::backend::Backend;
use burn::tensor::Tensor;
use std::sync::Mutex;

static GENERATOR: Mutex<()> = Mutex::new(());

/// Seed `B`'s generator with `seed` and run `draw` with nobody else drawing.
/// Keep `draw` to initialisation and random tensors: it blocks other seeded
/// sections while it runs.
pub fn seeded<B: Backend, T>(device: &B::Device, seed: u64, draw: impl FnOnce() -> T) -> T {
    // A panic inside another section leaves nothing half-done to protect.
    let _guard = GENERATOR.lock().unwrap_or_else(|e| e.into_inner());
    B::seed(device, seed);
    draw()
}

/// Draw every lazily initialised parameter of `module` now.
pub fn materialise<B: Backend, M: Module<B>>(module: M) -> M {
    module.visit(&mut Touch);
    module
}

struct Touch;

impl<B: Backend> ModuleVisitor<B> for Touch {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<B, D>>) {
        let _ = param.val();
    }
}

/// Serde for a seed (any `u64`) in a configuration: TOML's integers stop at
/// `i64::MAX`, so a larger seed is written as a decimal string and read back
/// from either form (`seed = 7`, `seed = "9223372036854775808"`).
pub(crate) mod wide_seed {
    use serde::de::{self, Visitor};
    use serde::{Deserializer, Serializer};

    pub(crate) fn serialize<S: Serializer>(v: &u64, s: S) -> Result<S::Ok, S::Error> {
        match i64::try_from(*v) {
            Ok(_) => s.serialize_u64(*v),
            Err(_) => s.serialize_str(&v.to_string()),
        }
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
        struct Seed;
        impl Visitor<'_> for Seed {
            type Value = u64;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a seed from 0 to 18446744073709551615 (a number, or a string of one)")
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<u64, E> {
                Ok(v)
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<u64, E> {
                u64::try_from(v).map_err(|_| E::custom(format!("seed {v} is negative")))
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<u64, E> {
                v.trim().parse().map_err(|_| {
                    E::custom(format!(
                        "seed {v:?} is not a number from 0 to 18446744073709551615"
                    ))
                })
            }
        }
        d.deserialize_any(Seed)
    }
}

#[cfg(test)]
mod tests {
    use crate::TrainConfig;

    /// Seeds above i64::MAX go through TOML as strings and come back whole;
    /// smaller ones stay numbers (issue 37: 2^63 was refused).
    #[test]
    fn every_u64_seed_round_trips_through_toml_and_json() {
        for seed in [0, 7, i64::MAX as u64, 1 << 63, u64::MAX] {
            let c = TrainConfig {
                seed,
                ..Default::default()
            };
            let text = c.to_toml();
            let line = text.lines().find(|l| l.starts_with("seed")).unwrap();
            if seed <= i64::MAX as u64 {
                assert_eq!(line, format!("seed = {seed}"));
            } else {
                assert_eq!(line, format!("seed = \"{seed}\""));
            }
            assert_eq!(TrainConfig::from_toml(&text).unwrap().seed, seed);
            let json = serde_json::to_string(&c).unwrap();
            assert_eq!(
                serde_json::from_str::<TrainConfig>(&json).unwrap().seed,
                seed
            );
            let over = c.overlay(&toml::toml! { steps = 3 }).unwrap();
            assert_eq!((over.seed, over.steps), (seed, 3));
        }
        let e = TrainConfig::from_toml("seed = -1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("negative"), "{e}");
        let e = TrainConfig::from_toml("seed = \"x\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a number"), "{e}");
    }
}
