//! # host-sim
//!
//! Host-side tools around planner-core: the Clarabel reference solver, random problem
//! instances, and the planner benchmark. (Multi-vehicle simulation over a bus is not
//! implemented yet.)
#![deny(missing_docs)]

pub mod bench;
pub mod instances;
pub mod monitor;
pub mod platoon;
pub mod reference;
