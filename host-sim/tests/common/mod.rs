//! Helpers shared by host-sim's test files.
// Each test file uses part of these helpers.
#![allow(dead_code)]

use host_sim::intersection::CrossingScenario;
use host_sim::sim::RunSummary;
use std::path::{Path, PathBuf};

/// A scenario file shipped in `scenarios/`.
pub fn builtin(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(name)
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
    let sc = CrossingScenario::parse(&t, &path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(sc.placements.len(), 8);
    let s = sc.run(&mut |_, _| {});
    assert_eq!(
        (
            s.collisions,
            s.invariant_violations,
            s.limit_violations,
            s.unpermitted_entries
        ),
        (0, 0, 0, 0),
        "{alg}: {s:?}"
    );
    assert_eq!((s.crossed, s.in_system), (8, 0), "{alg}: {s:?}");
}

/// No collision, invariant, limit, road-end or off-road finding in a run.
pub fn assert_safe(s: &RunSummary) {
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
