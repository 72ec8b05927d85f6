//! Theorem 2 as a test: random multi-lane traffic — 3–4 lanes, 5–30 vehicles at random
//! safe spacings and speeds, random reference speeds and random target lanes, 20 s at
//! h = 0.01 — every vehicle its own multi-lane planner hearing the others only over the
//! bus. The independent monitor (oriented-rectangle collisions, the invariant in every
//! lane a rectangle overlaps, limits, road departures) must see nothing.
//!
//! `THEOREM2_CASES` sets the number of cases (default 100; README gives the 5,000 run,
//! `host-sim traffic --cases 5000 --json`); `THEOREM2_REUSE_CASES` those of the sweep
//! with certified plan reuse (default 30), which must see nothing either;
//! `THEOREM2_COMPARE_CASES` those compared against solving every step (default 8; the
//! 5,000-case comparison is `host-sim traffic --cases 5000 --compare --json`).

mod common;

use common::env;
use host_sim::experiments::traffic::traffic_sweep;

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

/// What the planner as shipped, and with certified plan reuse, gives up
/// against solving every step with the interior-point method alone (the planner before
/// its active-set step), on the same cases: the closed-loop cost, and the iterations it saves.
#[test]
fn cost_given_up_against_solving_every_step() {
    use host_sim::experiments::traffic::{traffic_compare, Planning};
    let (cases, seed) = (env("THEOREM2_COMPARE_CASES", 8), env("THEOREM2_SEED", 1));
    for reuse in [false, true] {
        let planning = Planning {
            reuse,
            ..Planning::DEFAULT
        };
        let r = traffic_compare(cases, seed, 10.0, 0, planning);
        println!("{r}");
        assert!(r.safe(), "{r:?}");
        // The baseline really is the interior-point method at every step.
        let base = &r.every_step;
        assert_eq!((base.reused_steps, base.active_set_solves), (0, 0));
        assert_eq!(r.current.planner_steps, base.planner_steps);
        // The active-set step answers most warm starts and saves iterations.
        assert!(
            r.current.active_set_solves * 10 > r.current.solved_steps * 8,
            "{r:?}"
        );
        assert!(r.iterations_ratio < 0.5, "{r}");
        if reuse {
            // Reuse applies plans certified within 1 % of each step's optimum.
            assert!(
                r.current.reused_steps * 5 > r.current.planner_steps,
                "{r:?}"
            );
            assert!((-1e-3..1e-2).contains(&r.cost_given_up), "{r}");
        } else {
            // Both solvers stop at the same tolerance: the closed loops agree.
            assert_eq!(r.current.reused_steps, 0);
            assert!(r.cost_given_up.abs() < 1e-3, "{r}");
        }
    }
}
