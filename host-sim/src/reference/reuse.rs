//! `bench-planner`'s plan-reuse rows: the benchmark drive — one follower
//! behind a leader that draws a new admissible acceleration every 1.5 s — driven twice
//! with the same leader, by a planner solving every step and by one with a
//! [`ReusePolicy`], side by side: what reuse saves and what it gives up.

use super::instances::rng;
use planner_core::planner::free_road_gap;
use planner_core::{
    CostWeights, Params, Planner, Real, ReusePolicy, SingleLaneProblem, StepStatus,
};
use rand::Rng;
use serde::Serialize;
use std::time::Instant;

/// One horizon's comparison.
#[derive(Debug, Clone, Serialize)]
pub struct ReuseRow {
    /// N.
    pub horizon: usize,
    /// Planner steps of each drive.
    pub steps: usize,
    /// The reuse policy's tolerance (relative sub-optimality per step).
    pub tolerance: f64,
    /// The reuse policy's most consecutive steps without a solve.
    pub max_age: u8,
    /// Share of the reusing drive's steps that applied a certified plan, no solve.
    pub reused_share: f64,
    /// Interior-point iterations per step, solving every step.
    pub iterations_per_step: f64,
    /// The same, with reuse.
    pub iterations_per_step_reuse: f64,
    /// Mean wall time of a planner step (problem, solve or reuse check, verification),
    /// solving every step (µs).
    pub step_mean_us: f64,
    /// The same, with reuse (µs).
    pub step_mean_us_reuse: f64,
    /// step_mean_us / step_mean_us_reuse.
    pub speedup: f64,
    /// Closed-loop cost Σ w_v (v − v_ref)² + w_Δ (v − v_prev)² of the applied speeds,
    /// relative change with reuse (what reuse gives up on the road).
    pub closed_loop_cost_change: f64,
    /// Largest certified bound on J(plan) − J* of a reused step, relative to 1 + |J|
    /// (≤ the tolerance by construction).
    pub max_certified_gap: f64,
}

struct Drive {
    steps: usize,
    reused: usize,
    iterations: u64,
    seconds: f64,
    cost: f64,
    max_gap: f64,
}

/// One drive of `steps` steps with `policy` (the leader is the same for every policy).
fn drive<const N: usize>(steps: usize, seed: u64, policy: Option<ReusePolicy<f64>>) -> Drive {
    let p = Params::<f64>::table_i();
    let w = CostWeights::<f64>::default();
    let mut planner = Planner::<f64, N>::new(p, w).expect("default weights are valid");
    planner.set_reuse(policy).expect("a valid policy");
    let mut r = rng(seed);
    let (mut x, mut v, mut xl, mut vl, mut accel) = (0.0f64, 15.0f64, 60.0f64, 15.0f64, 0.0);
    let mut d = Drive {
        steps,
        reused: 0,
        iterations: 0,
        seconds: 0.0,
        cost: 0.0,
        max_gap: 0.0,
    };
    for step in 0..steps {
        if step % 150 == 149 {
            accel = r.random_range(p.a_min()..p.a_max());
        }
        let gap = (xl - x - p.length() - p.d0()).min(free_road_gap(&p, N));
        let t0 = Instant::now();
        let c = planner.step_gap(v, gap, 0.0, p.v_max());
        d.seconds += t0.elapsed().as_secs_f64();
        let Ok(c) = c else { break };
        match c.status {
            StepStatus::Solved { iterations, .. } => d.iterations += u64::from(iterations),
            StepStatus::Reused { certified_gap, .. } => {
                d.reused += 1;
                // J of the applied plan on the step's own problem, as the planner scored it.
                let pr = SingleLaneProblem::<f64, N>::new(
                    &p,
                    v,
                    gap,
                    f64::SAFETY_MARGIN_M,
                    w,
                    0.0,
                    p.v_max(),
                );
                let j = match (pr, planner.plan()) {
                    (Ok(pr), Some(plan)) => pr.objective(plan),
                    _ => 0.0,
                };
                d.max_gap = d.max_gap.max(certified_gap / (1.0 + j.abs()));
            }
            // The fallback, and whatever else a planner may do: no solve to count.
            _ => {}
        }
        d.cost += w.stage_cost(c.v, v, p.v_max());
        v = c.v;
        x += v * p.h();
        vl = (vl + accel * p.h()).clamp(0.0, p.v_max());
        xl += vl * p.h();
    }
    d
}

/// The drive of `steps` steps at horizon N, solving every step and with `policy`.
pub fn compare<const N: usize>(steps: usize, seed: u64, policy: ReusePolicy<f64>) -> ReuseRow {
    let every = drive::<N>(steps, seed, None);
    let reuse = drive::<N>(steps, seed, Some(policy));
    let per = |x: f64, d: &Drive| x / d.steps.max(1) as f64;
    ReuseRow {
        horizon: N,
        steps,
        tolerance: policy.tolerance,
        max_age: policy.max_age,
        reused_share: per(reuse.reused as f64, &reuse),
        iterations_per_step: per(every.iterations as f64, &every),
        iterations_per_step_reuse: per(reuse.iterations as f64, &reuse),
        step_mean_us: per(every.seconds * 1e6, &every),
        step_mean_us_reuse: per(reuse.seconds * 1e6, &reuse),
        speedup: every.seconds / reuse.seconds.max(f64::MIN_POSITIVE),
        closed_loop_cost_change: (reuse.cost - every.cost) / every.cost.max(f64::MIN_POSITIVE),
        max_certified_gap: reuse.max_gap,
    }
}

/// N = 20 and N = 50 with `policy`.
pub fn run(steps: usize, seed: u64, policy: ReusePolicy<f64>) -> Vec<ReuseRow> {
    vec![
        compare::<20>(steps, seed, policy),
        compare::<50>(steps, seed, policy),
    ]
}
