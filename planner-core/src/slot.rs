//! Places for planners that a `static` can hold, so that a microcontroller keeps them
//! off its stack.
//!
//! A [`Planner`] is ~45 N scalars (its solver's working storage), 11.7 KB in `f32` at
//! N = 50; a [`LanePlanner`] a little more. Built by value (`new` → `Result<Self, _>` →
//! the caller's variable) the compiler places one or more temporaries of that size on
//! the stack, and a planner kept in a task's frame stays there. A slot avoids both:
//!
//! - `PlannerSlot::new` is a `const fn` whose value is all zeros, so
//!   `static mut P: PlannerSlot<f32, 20> = PlannerSlot::new();` (or
//!   `cortex_m::singleton!`) puts the storage in `.bss`: RAM, no flash image, no stack;
//! - `PlannerSlot::init` validates the configuration and then writes the planner's
//!   state field by field into the slot ([`crate::solver::IpmSolver::reset`]), never
//!   materialising a whole planner anywhere else, and hands out `&mut Planner`.
//!
//! Until `init` succeeds the slot holds a placeholder with invalid (zero) parameters
//! that no one can reach: [`Slot::get`] returns `None`. A failed `init` changes
//! nothing. `init` again re-initialises the planner in place (as `new` would build it).
//!
//! On the Cortex-M4F firmware the slots took the painted peak stack from 14.8 KB
//! (N = 20) and 27.2 KB (N = 50) to what one control step needs (docs/firmware.md).

use crate::mpc::CostWeights;
use crate::params::Params;
use crate::planner::{ConfigError, Planner};
use crate::real::Real;
use crate::LanePlanner;

/// A place for one planner `T` that a `static` can hold: [`PlannerSlot`] for a
/// single-lane [`Planner`], [`LanePlannerSlot`] for a multi-lane [`LanePlanner`] (both with
/// our interior-point solver).
#[derive(Debug)]
pub struct Slot<T> {
    planner: T,
    ready: bool,
}

/// A place for one single-lane [`Planner`].
pub type PlannerSlot<F, const N: usize> = Slot<Planner<F, N>>;

/// A place for one multi-lane [`LanePlanner`].
pub type LanePlannerSlot<F, const N: usize> = Slot<LanePlanner<F, N>>;

impl<T> Slot<T> {
    /// The planner, once `init` has put one in.
    pub fn get(&mut self) -> Option<&mut T> {
        self.ready.then_some(&mut self.planner)
    }

    /// Whether `init` has put a planner in.
    pub const fn is_ready(&self) -> bool {
        self.ready
    }

    /// Marks the slot ready after a successful in-place rebuild, and hands out the planner.
    fn ready(&mut self) -> &mut T {
        self.ready = true;
        &mut self.planner
    }
}

impl<F: Real, const N: usize> Slot<Planner<F, N>> {
    /// An empty slot (all zeros: a `static` of it is placed in `.bss`).
    pub const fn new() -> Self {
        Self {
            planner: Planner::unset(),
            ready: false,
        }
    }

    /// Puts in the planner [`Planner::new`]`(params, weights)` would build, in place,
    /// and returns it. Invalid weights: [`ConfigError::InvalidWeights`], and the slot is
    /// left as it was.
    pub fn init(
        &mut self,
        params: Params<F>,
        weights: CostWeights<F>,
    ) -> Result<&mut Planner<F, N>, ConfigError> {
        self.planner.rebuild(params, weights)?;
        Ok(self.ready())
    }
}

impl<F: Real, const N: usize> Default for Slot<Planner<F, N>> {
    fn default() -> Self {
        Self::new()
    }
}

impl<F: Real, const N: usize> Slot<LanePlanner<F, N>> {
    /// An empty slot (all zeros: a `static` of it is placed in `.bss`).
    pub const fn new() -> Self {
        Self {
            planner: LanePlanner::unset(),
            ready: false,
        }
    }

    /// Puts in the planner [`LanePlanner::new`]`(params, weights, lane)` would build, in
    /// place, and returns it. Invalid weights: [`ConfigError::InvalidWeights`], and the
    /// slot is left as it was.
    pub fn init(
        &mut self,
        params: Params<F>,
        weights: CostWeights<F>,
        lane: u8,
    ) -> Result<&mut LanePlanner<F, N>, ConfigError> {
        self.planner.rebuild(params, weights, lane)?;
        Ok(self.ready())
    }
}

impl<F: Real, const N: usize> Default for Slot<LanePlanner<F, N>> {
    fn default() -> Self {
        Self::new()
    }
}
