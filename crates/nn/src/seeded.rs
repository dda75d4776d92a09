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
