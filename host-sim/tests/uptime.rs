//! A fleet whose clocks have run 99 days and run across a wrap of the wire's 32-bit
//! milliseconds ends exactly as one whose clocks start at zero: the multi-lane road and
//! the corridor over CAN frames on the hub, every planner, manager and codec in `f32`
//! as on the microcontroller (`host-sim run --bus can-hub --precision f32
//! --clock-start S`). The traces are written in the world's time (seconds since the run
//! began), so "equal up to the clock offset" is equal byte for byte.

use std::path::{Path, PathBuf};
use std::process::Command;

fn scenario(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(name)
}

fn tmp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("host-sim-uptime-{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temp dir");
    d.join(name)
}

/// The trace and the summary's outcome of `file` from clock reading `start` (s).
fn run(file: &str, start: &str) -> (Vec<u8>, serde_json::Value) {
    run_in(file, start, "f32")
}

/// [`run`] in `precision`.
fn run_in(file: &str, start: &str, precision: &str) -> (Vec<u8>, serde_json::Value) {
    let trace = tmp(&format!("{file}-{start}-{precision}.csv"));
    let out = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .arg("run")
        .arg(scenario(file))
        .args(["--bus", "can-hub", "--precision", precision, "--json"])
        .args(["--clock-start", start, "--trace"])
        .arg(&trace)
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{file} from {start}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let run = &v;
    let outcome = serde_json::json!({
        "collisions": run["collisions"],
        "invariant_violations": run["invariant_violations"],
        "completed": run["completed"],
        "lane_changes": run["lane_changes"],
        "crossing": run["crossing"],
        "messages_rejected": run["messages_rejected"],
    });
    (std::fs::read(&trace).expect("trace"), outcome)
}

/// Runs `file` from 0 and from 99 days, across a wrap; its trace from 0.
fn same_from_any_uptime(file: &str) -> Vec<u8> {
    let (trace, outcome) = run(file, "0");
    assert_eq!(outcome["collisions"], 0, "{outcome}");
    assert_eq!(outcome["completed"], true, "{outcome}");
    assert_eq!(outcome["messages_rejected"], 0, "{outcome}");
    // 0.5 s before the second wrap of the wire's milliseconds (2 x 4294967.296 s, 99.4
    // days), so the run crosses it: past 60 days of uptime and across a wrap in one run
    // (they were two runs of the corridor, 20 s of CI each).
    let start = "8589934.092";
    let (t, o) = run(file, start);
    assert_eq!(o, outcome, "{file} from {start} s");
    assert!(t == trace, "{file}: the trace from {start} s differs");
    trace
}

#[test]
fn the_multilane_road_in_f32_on_can_ends_the_same_from_any_uptime() {
    let f32_trace = same_from_any_uptime("multilane.toml");
    // And the planners did run in f32: the commands differ from f64's in their last bits.
    let (f64_trace, o) = run_in("multilane.toml", "0", "f64");
    assert_eq!(o["collisions"], 0);
    assert!(
        f32_trace != f64_trace,
        "--precision f32 planned as f64 does"
    );
}

#[test]
fn the_corridor_in_f32_on_can_ends_the_same_from_any_uptime() {
    same_from_any_uptime("corridor.toml");
}
