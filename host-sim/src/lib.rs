//! # host-sim
//!
//! Host-side tools around planner-core: one world of roads and intersections in which
//! every vehicle is its own planner instance talking only over a bus, with independent
//! monitors; the paper's experiments and the theorems' sweeps; scenario files, traces,
//! plots and a viewer; the Clarabel reference solver and the planner benchmark.
//!
//! - [`scenario`]: the scenario file format (roads, intersections, networks), validated;
//! - [`world`]: the network, vehicles, managers and the one simulation loop;
//! - [`bus`]: the bus trait, its messages and node addresses, the in-process bus with faults;
//! - [`firmware`]: vehicle computers in the loop — the firmware's image in QEMU, talking
//!   serial-line CAN on its UART;
//! - [`fleet`]: CAN media (SocketCAN, an in-process frame hub) and a world run as a fleet
//!   of tasks on them, one per vehicle and per junction manager;
//! - [`monitor`]: ground-truth safety checks, liveness and the deadlock detector;
//! - [`experiments`]: the paper's figures and the sweeps, each one type implementing
//!   [`experiments::experiment::Experiment`] (settings, run a range, report from parts);
//! - [`verdict`]: the one verdict every command and `host-sim merge` reach;
//! - [`output`]: traces, plots and the viewer;
//! - [`reference`](mod@reference): the Clarabel reference, random instances, the planner benchmark.
//!
//! Modules depend on each other one way, folders and the files inside them alike (the
//! workspace's `tests/tests/layout.rs` checks it): `monitor`, `reference`, `bus`,
//! `firmware` and `verdict` on nothing; `world` on those; `scenario` (the
//! file formats, which build a world) on `world`; `fleet` and `experiments` on all of
//! these; `output` on `experiments`; the binary's `cli` on everything.
#![deny(missing_docs)]
// `!(x > y)` is used on purpose: unlike `x <= y` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bus;
pub mod experiments;
pub mod firmware;
pub mod fleet;
pub mod monitor;
pub mod output;
pub mod reference;
pub mod scenario;
pub mod verdict;
pub mod world;
