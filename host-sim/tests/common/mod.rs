//! Helpers shared by host-sim's test files.
// Each test file uses part of these helpers.
#![allow(dead_code)]

use can_gateway::FdFrame;
use host_sim::fleet::can::{CanPort, HubPort};
use host_sim::world::summary::Summary;
use host_sim::world::{SolverChoice, World, WorldSpec};
use std::io;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, SystemTime};

/// `s` seconds after the epoch, to the microsecond.
pub fn secs(s: f64) -> planner_core::Instant {
    planner_core::Instant::from_micros((s * 1e6).round() as u64)
}

/// A cooperative vehicle's state in lane 0 of a road's first segment (y = 1.8 m, heading
/// along the road, not turning, no lane change).
pub fn lane_state(id: u16, x: f64, v: f64, stamp: f64) -> planner_core::VehicleState<f64> {
    planner_core::VehicleState {
        id,
        x,
        y: 1.8,
        theta: 0.0,
        v,
        omega: 0.0,
        lane: 0,
        alpha: None,
        beta: None,
        stamp: secs(stamp),
        cooperative: true,
        brake: None,
        length: None,
    }
}

/// A scenario file shipped in `scenarios/`.
pub fn builtin(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(name)
}

/// A built-in scenario, loaded.
pub fn load(name: &str) -> WorldSpec {
    let path = builtin(name);
    host_sim::scenario::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Scenario text parsed as if it were in `scenarios/` under `name`.
pub fn parse(text: &str, name: &str) -> WorldSpec {
    host_sim::scenario::parse(text, &builtin(name)).unwrap_or_else(|e| panic!("{e}"))
}

/// Runs `spec` to its end on the in-process bus (horizon 20).
pub fn run_world(spec: WorldSpec) -> Summary {
    let mut w = World::<20>::new(spec, SolverChoice::Ours, None);
    while !w.finished() {
        w.step(&mut |_| {})
            .expect("the in-process bus does not fail");
    }
    w.summary(0.0)
}

/// Runs the built-in Fig. 8 intersection scenario under algorithm `alg` (its TOML name),
/// with `extra` appended to the file, and checks that all 8 vehicles cross with no
/// collision, no violation and nobody entering A_S without a permission.
pub fn intersection_all_cross(alg: &str, extra: &str) {
    let path = builtin("intersection.toml");
    let text = std::fs::read_to_string(&path).expect("read");
    let t = text.replace(
        "algorithm = \"concurrent\"",
        &format!("algorithm = \"{alg}\""),
    ) + extra;
    let spec = parse(&t, "intersection.toml");
    assert_eq!(spec.vehicles.len(), 8);
    assert_all_crossed_safely(&run_world(spec), 8);
}

/// No collision, invariant or limit violation, nobody in A_S without a permission, and
/// all `vehicles` crossed.
pub fn assert_all_crossed_safely(s: &Summary, vehicles: u64) {
    assert_safe(s);
    assert_eq!(s.unpermitted_entries(), 0, "{s:?}");
    let c = s.crossing.as_ref().expect("a junction");
    assert_eq!((c.crossed, c.in_system), (vehicles, 0), "{s:?}");
}

/// No collision, invariant, limit, road-end or off-road finding in a run.
pub fn assert_safe(s: &Summary) {
    assert_eq!(
        (
            s.collisions,
            s.invariant_violations,
            s.limit_violations,
            s.road_end_overruns,
            s.off_road
        ),
        (0, 0, 0, 0, 0),
        "{s:?}"
    );
}

/// A port whose transmitter fails (bus-off) after `left` frames.
pub struct Failing {
    pub inner: HubPort,
    pub left: u32,
}

impl CanPort for Failing {
    fn transmit(&mut self, frame: &FdFrame) -> io::Result<()> {
        if self.left == 0 {
            return Err(io::Error::other("bus-off"));
        }
        self.left -= 1;
        self.inner.transmit(frame)
    }
    fn receive(&mut self, timeout: Duration) -> io::Result<Option<(FdFrame, SystemTime)>> {
        self.inner.receive(timeout)
    }
}

/// `host-sim run FILE --bus can-hub` refuses `file` as bad input (exit 2), saying `says`.
pub fn refused_on_the_bus(file: &Path, says: &str) {
    let out = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .arg("run")
        .arg(file)
        .args(["--bus", "can-hub"])
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{}: {err}", file.display());
    assert!(err.contains(says), "{}: {err}", file.display());
}

/// `host-sim run FILE --bus can-hub --json`: succeeds; its JSON, on the hub.
pub fn json_on_the_hub(file: &Path) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .arg("run")
        .arg(file)
        .args(["--bus", "can-hub", "--json"])
        .output()
        .expect("runs");
    assert!(out.status.success(), "{out:?}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(v["medium"], "can-hub");
    v
}
