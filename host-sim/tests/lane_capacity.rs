//! One lane under each invariant (docs/capacity.md): the planners hold a closed-up
//! platoon and discharge a standing queue with no collision, no violation of the
//! invariant each keeps and no fallback, and the leader-aware invariant carries more.
//! (The figures themselves are benchmarks: `host-sim experiment lane-capacity`.)

use host_sim::experiments::lane_capacity::{measure, Mode};
use planner_core::Invariant;

#[test]
fn both_invariants_are_safe_and_the_leader_aware_one_carries_more() {
    for speed in [13.9, 27.8] {
        for mode in [Mode::Flowing, Mode::Discharging] {
            let paper = measure(speed, mode, 12, Invariant::Paper).expect("runs");
            let aware = measure(speed, mode, 12, Invariant::LeaderAware).expect("runs");
            for r in [&paper, &aware] {
                assert_eq!(r.counted, 12 - 4, "{r:?}");
                assert_eq!(
                    (r.collisions, r.invariant_violations, r.limit_violations),
                    (0, 0, 0),
                    "{r:?}"
                );
                assert_eq!(r.fallback_steps, 0, "{r:?}");
            }
            assert!(
                aware.flow_vph > 1.5 * paper.flow_vph,
                "{speed} {mode:?}: {} vs {}",
                aware.flow_vph,
                paper.flow_vph
            );
        }
    }
}

#[test]
fn a_leader_aware_platoon_is_refused_under_the_papers_invariant() {
    // The flowing platoon spaced for the leader-aware invariant breaks the paper's: the
    // loader checks the invariant the scenario names.
    let text = host_sim::experiments::lane_capacity::scenario(
        27.8,
        Mode::Flowing,
        6,
        Invariant::LeaderAware,
    );
    assert!(host_sim::scenario::parse(&text, std::path::Path::new("a.toml")).is_ok());
    let paper = text.replace("invariant = \"leader-aware\"", "invariant = \"paper\"");
    let err = host_sim::scenario::parse(&paper, std::path::Path::new("a.toml"))
        .expect_err("refused")
        .to_string();
    assert!(err.contains("violates the safety invariant"), "{err}");
    let bad = text.replace("invariant = \"leader-aware\"", "invariant = \"wall\"");
    let err = host_sim::scenario::parse(&bad, std::path::Path::new("a.toml"))
        .expect_err("refused")
        .to_string();
    assert!(
        err.contains("invariant must be") && err.contains(":3"),
        "{err}"
    );
}
