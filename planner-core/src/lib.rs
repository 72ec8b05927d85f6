//! # planner-core
//!
//! A `#![no_std]`, allocation-free implementation of Kim & Kumar's MPC-based approach to
//! provable system-wide safety and liveness of autonomous ground traffic (IEEE TAC
//! 59(12), 2014). Equation, lemma and theorem numbers in the docs are the paper's; the
//! choices where the paper is silent, and the rules that go beyond it, are argued in the
//! project's specification (`docs/spec.md` in the repository) and in each item's docs.
//!
//! One module per concept:
//! - [`params`]: Table I parameters, validated;
//! - [`safety`]: dMB, tL, dh, dS, the speed bounds (3)(4), tH (5)(6), V^k_t (7), the
//!   invariant of Lemma 3 (and the leader-aware one) and the max-braking sequence of
//!   Lemma 2;
//! - [`mpc`]: problem (10) as data with a configurable quadratic cost;
//! - [`solver`]: our solver with O(N) pentadiagonal Newton systems: an active-set
//!   step on warm starts, an interior-point method behind it;
//! - [`planner`]: the single-lane planner step: obstacle (2)/(22), solve, verify,
//!   certified fallback;
//! - [`reuse`]: certified plan reuse (the previous plan, shifted, when duality proves it
//!   near-optimal);
//! - [`unicycle`], [`lanes`], [`lateral`], [`free_space`], [`lane_change`]: the
//!   multi-lane planner — the unicycle (1), lanes and bands, the Lane Change Protocol
//!   (16)–(18), Yield, dead ends (22)(23);
//! - [`intersection`], [`crossing`]: the intersection layout, route conflicts,
//!   Spaciousness (27), the managers of the Intersection-Crossing Protocol and the
//!   vehicle side of it;
//! - [`world`], [`sensing`], [`time`]: V2V vehicle-state messages and the bounded world
//!   view built from them, onboard range sensors, and the integer time base (µs since an
//!   epoch the vehicles share);
//! - [`slot`]: placing a planner in a `static` without `alloc` or `static mut`.
//!
//! Memory is bounded by the const-generic horizon `N`; no function panics on any input
//! (clippy denies `unwrap`, `expect`, `panic!` and indexing that can panic), and every
//! loop has a fixed bound. Precision is a type parameter: `f32` for the Cortex-M4F FPU,
//! `f64` on hosts; the numerical margins of each are constants of [`Real`].
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
// No panics on any input path: enforced for the library; unit tests may unwrap and index.
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented
    )
)]
// `!(x > 0)` is used on purpose throughout: unlike `x <= 0` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod banded;
pub mod crossing;
pub mod free_space;
pub mod intersection;
pub mod lane_change;
pub mod lanes;
pub mod lateral;
pub mod mpc;
pub mod params;
pub mod planner;
pub mod real;
pub mod reuse;
pub mod safety;
pub mod sensing;
pub mod slot;
pub mod solver;
pub mod time;
pub mod unicycle;
pub mod world;

pub use lane_change::{
    LaneCommand, LaneEvent, LaneInputError, LaneObservation, LanePlanner, StartBlock,
};
pub use lanes::{Other, Road};
pub use mpc::{ConstraintKind, CostWeights, ProblemError, SingleLaneProblem, Violation};
pub use params::{Params, ParamsError, ParamsSpec};
pub use planner::{
    Command, ConfigError, FallbackReason, InputError, Observation, Planner, StepStatus, Vehicle,
};
pub use real::Real;
pub use reuse::ReusePolicy;
pub use safety::{BrakeLimit, Invariant};
pub use sensing::Sensing;
pub use slot::{LanePlannerSlot, PlannerSlot, Slot};
pub use solver::{IpmSolver, Method, MpcSolver, Settings, SettingsError, Solution, SolveError};
pub use time::{Duration, Instant};
pub use unicycle::Pose;
pub use world::{BodyLength, VehicleState, WorldError, WorldView};

/// The `heapless` this crate's API is written in ([`WorldView::others`] and
/// [`WorldView::lane_vehicles`] fill a `heapless::Vec`): name it as
/// `planner_core::heapless::Vec` and the versions always agree (a different `heapless` in
/// the user's crate is a different type).
pub use heapless;

/// The README's examples, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
