//! host-sim's integration tests, one binary: each file beside this one is a module
//! (`cargo test -p host-sim --test integration crossing_fleet::` runs one file's tests).
//! One binary, not one per file: each file's binary linked host-sim and instantiated its
//! generic worlds and fleets again; the 22 took 107 CPU-seconds of a release build, this
//! one takes 21 (cargo's `--timings`, at 47a8dbd). `monitor.rs` stays its own binary:
//! cargo-mutants rebuilds it for each mutant of the monitor (.ci/run).

mod common;
/// The test script's Python and its skips, shared with can-gateway's DBC test (the
/// viewer skips without a browser; trace_check needs no skip, python3 is a prerequisite).
#[path = "../../can-gateway/tests/support/mod.rs"]
mod support;

mod attacks;
mod can_fleet;
mod cli;
mod crossing_fleet;
mod export_sumo;
mod faults;
mod invariant_choice;
mod json_schema;
mod lane_capacity;
mod liveness;
mod network;
mod off_ideal;
mod outputs;
mod plausibility;
mod redteam;
mod scenario_keys;
mod scenarios;
mod shards;
mod trace_check;
mod uptime;
mod viewer;
mod views;
