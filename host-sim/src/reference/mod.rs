//! The reference side of the planner: Clarabel on the same problems, random instances of
//! (10), and the planner benchmark (ours vs Clarabel).

pub mod bench;
pub mod clarabel;
pub mod instances;

pub use clarabel::{conic_data, ClarabelSolver};
