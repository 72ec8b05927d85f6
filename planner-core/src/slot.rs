//! Places for planners that a `static` can hold, so that a microcontroller keeps them
//! off its stack.
//!
//! A [`Planner`] holds its solver's working storage — a few dozen arrays of N scalars:
//! 5,272 B in `f32` at N = 20 on the Cortex-M4F (the table below) — and a
//! [`LanePlanner`] more. Built by value (`new` → `Result<Self, _>` → the caller's
//! variable) the compiler places one or more temporaries of that size on the stack, and
//! a planner kept in a task's frame stays there. A slot avoids both:
//!
//! - `PlannerSlot::new` is a `const fn` whose value is all zeros, so a `static` of slots
//!   sits in `.bss`: RAM, no flash image, no stack;
//! - `PlannerSlot::init` validates the configuration and then writes the planner's
//!   state field by field into the slot ([`crate::solver::IpmSolver::reset`]), never
//!   materialising a whole planner anywhere else, and hands out `&mut Planner`.
//!
//! Until `init` succeeds the slot holds a placeholder with invalid (zero) parameters
//! that no one can reach: [`Slot::get`] returns `None`. A failed `init` changes
//! nothing. `init` again re-initialises the planner in place (as `new` would build it).
//!
//! # The pattern that works
//!
//! A `static mut` of slots, reached once — in `main`, through `addr_of_mut!` — and handed
//! down as `&mut` (firmware-example does this; so does can-gateway's `period` example):
//!
//! ```
//! use core::ptr::addr_of_mut;
//! use planner_core::{CostWeights, LanePlannerSlot, Params, PlannerSlot};
//!
//! static mut SLOTS: (PlannerSlot<f32, 20>, LanePlannerSlot<f32, 20>) =
//!     (PlannerSlot::new(), LanePlannerSlot::new());
//!
//! // In `main`, once: the only reference to SLOTS there will ever be.
//! let slots = unsafe { &mut *addr_of_mut!(SLOTS) };
//! let params = Params::<f32>::table_i();
//! let planner = slots.0.init(params, CostWeights::default())?;
//! let lane_planner = slots.1.init(params, CostWeights::default(), 0)?;
//! planner.set_bus_resolution(0.01, 0.02)?;
//! lane_planner.set_bus_resolution(0.01, 0.02)?;
//! # Ok::<(), planner_core::ConfigError>(())
//! ```
//!
//! What does not: `&mut SLOTS` (a reference to a `static mut`, refused in edition 2024:
//! `static_mut_refs`), and `cortex_m::singleton!(: PlannerSlot<f32, 20> =
//! PlannerSlot::new())`, which builds the value on the stack and moves it into its
//! static — measured on the firmware, the peak stack doubled (15,312 B against 7,492 B).
//! An RTOS or RTIC resource works the same way as long as the slot is created `const`
//! in its static and only `init` runs at start-up.
//!
//! # Resources on a Cortex-M4F
//!
//! Measured by firmware-example in QEMU (mps2-an386, `-icount`: one instruction is 8 ns
//! of a 125 MHz core; 1.25 M instructions are one 10 ms period), `f32`, thumbv7em-none-eabihf,
//! release build. "Stack per call" is what a control loop's call took below its caller
//! (its own frame, the planner's step and the CAN decoding it calls; the node's CAN state
//! and view live in a static): the approach runs the single-lane planner behind a car
//! heard over CAN, the lane change runs *both* planners every period beside a car heard
//! over CAN. Instructions per step are the planners' `step` alone. CI checks this table
//! against the firmware's output (`firmware-example/resources.py`).
//!
//! <!-- resources: begin (firmware-example/resources.py) -->
//! | N | `size_of` `Planner` | `size_of` `LanePlanner` | stack per call: approach | stack per call: lane change, both planners | peak stack, whole firmware | instructions per single-lane step, median / worst | per lane-change step, median / worst |
//! |---|---|---|---|---|---|---|---|
//! | 20 | 5,276 B | 8,788 B | 3,184 B | 3,768 B | 4,032 B | 50,970 / 331,040 | 198,585 / 204,400 |
//! | 50 | 12,996 B | 16,628 B | 6,480 B | 7,648 B | 7,904 B | 125,630 / 1,049,720 | 254,460 / 700,350 |
//! <!-- resources: end -->

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
