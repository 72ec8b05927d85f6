//! Theorem 2 as a test: random multi-lane traffic — 3–4 lanes, 5–30 vehicles at random
//! safe spacings and speeds, random reference speeds and random target lanes, 20 s at
//! h = 0.01 — every vehicle its own multi-lane planner hearing the others only over the
//! bus. The independent monitor (oriented-rectangle collisions, the invariant in every
//! lane a rectangle overlaps, limits, road departures) must see nothing.
//!
//! `THEOREM2_CASES` sets the number of cases (default 100; README gives the 5,000 run,
//! `host-sim traffic --cases 5000 --json`); `THEOREM2_REUSE_CASES` those of the sweep
//! with certified plan reuse (issue 19 §1; default 30), which must see nothing either.

mod common;

use common::env;
use host_sim::experiments::multilane::traffic_sweep;

/// Runs the sweep and requires nothing unsafe and lane changes; returns reused steps.
fn sweep(cases: u64, reuse: bool) -> u64 {
    let seed = env("THEOREM2_SEED", 1);
    let r = traffic_sweep(cases, seed, 20.0, 0, reuse);
    println!("{r:#?}");
    assert_eq!(
        (r.collisions, r.invariant_violations, r.limit_violations),
        (0, 0, 0),
        "failing seeds {:?}",
        r.failing_seeds
    );
    assert!(r.failing_seeds.is_empty());
    assert_eq!(r.cases, cases);
    // Lane changes really happen (most vehicles want another lane).
    assert!(r.lane_changes >= r.cases * 3, "{r:?}");
    r.reused_steps
}

#[test]
fn theorem_2_random_multilane_traffic() {
    assert_eq!(sweep(env("THEOREM2_CASES", 100), false), 0);
}

#[test]
fn theorem_2_random_multilane_traffic_with_plan_reuse() {
    let cases = env("THEOREM2_REUSE_CASES", 30);
    // Reuse really happens (about half of the steps), so the sweep tests it.
    assert!(sweep(cases, true) > cases * 5000);
}
