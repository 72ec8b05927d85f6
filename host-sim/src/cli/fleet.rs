//! `host-sim run FILE --bus can-hub|IFACE`: the world as a fleet of tasks on CAN.

use super::output::bad_input;
use host_sim::fleet::{self, FleetError, FleetSummary, Medium};
use host_sim::world::{SolverChoice, TraceRow, WorldSpec};
use std::path::Path;
use std::process::ExitCode;

/// `--bus`: the CAN medium of a fleet (`in-process` is handled by the caller).
pub fn medium(bus: &str) -> Result<Medium, String> {
    match bus {
        "can-hub" => Ok(Medium::Hub),
        // Linux interface names: 1 to 15 bytes (IFNAMSIZ − 1), no '/', no white space.
        iface
            if (1..=15).contains(&iface.len())
                && iface
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b"-_.".contains(&b)) =>
        {
            Ok(Medium::SocketCan(iface.to_string()))
        }
        other => Err(format!(
            "--bus {other:?}: expected in-process, can-hub or a network interface name (1–15 of a-z A-Z 0-9 - _ .)"
        )),
    }
}

/// Checks `--bus` before anything runs.
pub fn check_bus(bus: &str) -> Result<(), ExitCode> {
    medium(bus).map(|_| ()).map_err(bad_input)
}

/// Whether the scenario in `file` can run as a fleet.
pub fn fits_the_bus(file: &Path, spec: &WorldSpec) -> Result<(), ExitCode> {
    match fleet::unsupported(spec) {
        Some(why) => Err(bad_input(format!("{}: `--bus`: {why}", file.display()))),
        None => Ok(()),
    }
}

/// Runs the fleet.
pub fn run(
    bus: &str,
    spec: WorldSpec,
    solver: SolverChoice,
    seed: Option<u64>,
    trace: &mut dyn FnMut(&TraceRow),
) -> Result<FleetSummary, FleetError> {
    let m = medium(bus).map_err(FleetError::Unsupported)?;
    fleet::run(spec, solver, seed, &m, trace)
}
