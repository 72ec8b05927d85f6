//! # host-sim
//!
//! Host-side tools around planner-core: a simulator in which every vehicle is its own
//! planner instance talking only over a bus, with independent monitors, scenario files,
//! traces and plots; the Clarabel reference solver; the planner benchmark.
#![deny(missing_docs)]
// `!(x > y)` is used on purpose: unlike `x <= y` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bench;
pub mod bus;
pub mod can;
pub mod crossing_fleet;
pub mod faulty;
pub mod fleet;
pub mod instances;
pub mod intersection;
pub mod monitor;
pub mod multilane;
pub mod par;
pub mod platoon;
pub mod plot;
pub mod reference;
pub mod scale;
pub mod scenario;
pub mod sim;
pub mod trace;
