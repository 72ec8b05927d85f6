//! Theorem 2 as a test: random multi-lane traffic — 3–4 lanes, 5–30 vehicles at random
//! safe spacings and speeds, random reference speeds and random target lanes, 20 s at
//! h = 0.01 — every vehicle its own multi-lane planner hearing the others only over the
//! bus. The independent monitor (oriented-rectangle collisions, the invariant in every
//! lane a rectangle overlaps, limits, road departures) must see nothing.
//!
//! `THEOREM2_CASES` sets the number of cases (default 100; README gives the 5,000 run,
//! `host-sim traffic --cases 5000 --json`).

use host_sim::experiments::multilane::traffic_sweep;

#[test]
fn theorem_2_random_multilane_traffic() {
    let env = |k: &str, d: u64| {
        std::env::var(k)
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let cases = env("THEOREM2_CASES", 100);
    let seed = env("THEOREM2_SEED", 1);
    let r = traffic_sweep(cases, seed, 20.0, 0);
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
}
