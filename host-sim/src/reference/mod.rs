//! The reference side of the planner: Clarabel on the same problems, random instances of
//! (10), and the planner benchmark (ours vs Clarabel; solving every step vs certified
//! plan reuse).

pub mod bench;
pub mod clarabel;
pub mod instances;
pub mod reuse;

pub use clarabel::{conic_data, ClarabelSolver};
