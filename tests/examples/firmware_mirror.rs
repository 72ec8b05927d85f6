//! The firmware's scenarios planned on the host, in the same precision (f32) from the
//! same inputs: prints the same `cmd <scenario> <step> <v bits> <ω bits>` lines as the
//! firmware, for CI to compare step for step.
//!
//! `cargo run --release -p workspace-tests --example firmware_mirror -- 20` (or `50`).

#[path = "../../firmware-example/src/scenarios.rs"]
#[allow(dead_code)]
mod scenarios;

use planner_core::{CostWeights, LanePlannerSlot, Params, PlannerSlot};
use scenarios::StepRecord;

fn run<const N: usize>() -> bool {
    let mut now = || 0u32;
    let mut emit = |r: &StepRecord| {
        println!(
            "cmd {} {} {:08x} {:08x}",
            r.scenario,
            r.k,
            r.v.to_bits(),
            r.omega.to_bits()
        );
    };
    // Built as the firmware builds them: in place, in slots.
    let params = Params::<f32>::table_i();
    let mut slots = Box::new((
        PlannerSlot::<f32, N>::new(),
        LanePlannerSlot::<f32, N>::new(),
    ));
    let (Ok(planner), Ok(lane_planner)) = (
        slots.0.init(params, CostWeights::default()),
        slots.1.init(params, CostWeights::default(), 0),
    ) else {
        return false;
    };
    let mut node = Box::new(scenarios::Node::new());
    let start = scenarios::CLOCK_START;
    let a = scenarios::approach::<N>(planner, &mut node, start, &mut now, &mut emit);
    let l =
        scenarios::lane_change::<N>(lane_planner, planner, &mut node, start, &mut now, &mut emit);
    a.is_some() && l.is_some()
}

fn main() -> std::process::ExitCode {
    let ok = match std::env::args().nth(1).as_deref() {
        Some("20") | None => run::<20>(),
        Some("50") => run::<50>(),
        Some(other) => {
            eprintln!("error: horizon must be 20 or 50, got {other}");
            return std::process::ExitCode::from(2);
        }
    };
    if ok {
        std::process::ExitCode::SUCCESS
    } else {
        std::process::ExitCode::FAILURE
    }
}
