//! The MPC problem (10)'s objective and constraint values against hand computation
//! (the second mutation pass: these were checked only through the Clarabel
//! cross-check in host-sim).

use planner_core::mpc::{ConstraintKind, CostWeights, SingleLaneProblem};
use planner_core::Params;

const N: usize = 4;

fn problem(weights: CostWeights<f64>) -> (Params<f64>, SingleLaneProblem<f64, N>) {
    let p = Params::<f64>::table_i();
    // Plenty of room: every constraint but the ones a test breaks is slack.
    let pr = SingleLaneProblem::<f64, N>::new(&p, 1.0, 80.0, 0.0, weights, 3.0, 2.0)
        .expect("invariant holds");
    (p, pr)
}

/// J = Σ_k wr (v_k − v_ref)² + ws (v_k − v_{k−1})², + wt (x^f − Σ_k v_k h)², each term
/// with its own weight so that a mistake in any one shows.
#[test]
fn the_objective_is_the_papers_j() {
    let w = CostWeights {
        target_position: 0.7,
        reference_speed: 1.3,
        smoothness: 2.9,
    };
    let (p, pr) = problem(w);
    let h = p.h();
    let v = [1.5, 2.5, 2.0, 4.0];
    let (mut prev, mut pos, mut j) = (1.0, 0.0, 0.0);
    for vk in v {
        pos += vk * h;
        j += 1.3 * (vk - 2.0) * (vk - 2.0) + 2.9 * (vk - prev) * (vk - prev);
        prev = vk;
    }
    j += 0.7 * (3.0 - pos) * (3.0 - pos);
    let got = pr.objective(&v);
    assert!((got - j).abs() < 1e-12 * j.abs().max(1.0), "{got} vs {j}");
    // Each weight alone.
    for (wt, wr, ws) in [(1.0, 0.0, 1e-9), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)] {
        let (_, pr) = problem(CostWeights {
            target_position: wt,
            reference_speed: wr,
            smoothness: ws,
        });
        assert!(pr.objective(&v) > 0.0);
    }
}

/// Every constraint value of (10), in order, for a plan that breaks several.
#[test]
fn each_constraint_value_is_as_written() {
    let (p, pr) = problem(CostWeights::default());
    let h = p.h();
    // Up by 0.5 twice (over the acceleration limit), then down by 1.5 (over the
    // deceleration limit), then far above V^k_t's upper edge.
    let v = [1.5, 2.0, 0.5, 40.0];
    let mut seen = Vec::new();
    pr.for_each_constraint(&v, |g, kind, k| {
        seen.push((g, kind, k));
        true
    });
    assert_eq!(seen.len(), 5 * N);
    let brake = p.brake();
    let (mut prev, mut pos) = (1.0, 0.0);
    for (k, &vk) in v.iter().enumerate() {
        pos += vk * h;
        let safety = pos + vk * h + vk * vk / (2.0 * brake) + 0.5 * brake * h * h - pr.gap;
        let want = [
            (vk - pr.hi[k], ConstraintKind::SpeedUpper),
            (pr.lo[k] - vk, ConstraintKind::SpeedLower),
            (vk - prev - p.a_max() * h, ConstraintKind::Accel),
            (p.a_min() * h - (vk - prev), ConstraintKind::Decel),
            (safety, ConstraintKind::Safety),
        ];
        for (i, (g, kind)) in want.into_iter().enumerate() {
            let (got, got_kind, got_k) = seen[5 * k + i];
            assert_eq!((got_kind, got_k), (kind, k));
            assert!((got - g).abs() < 1e-12, "{kind:?} at {k}: {got} vs {g}");
        }
        prev = vk;
    }
    // The visitor stops the walk when it returns false.
    let mut calls = 0;
    pr.for_each_constraint(&v, |_, _, _| {
        calls += 1;
        calls < 3
    });
    assert_eq!(calls, 3);
}

/// The worst violation: the largest value, the first on a tie, and NaN as the worst.
#[test]
fn max_violation_reports_the_largest_the_first_of_a_tie_and_nan() {
    let (p, pr) = problem(CostWeights::default());
    // Wide speed bounds, so that the acceleration limit is what a jump breaks most.
    let pr = SingleLaneProblem {
        hi: [10.0; N],
        lo: [0.0; N],
        ..pr
    };
    let feasible = [1.0; N];
    assert!(pr.max_violation(&feasible).amount <= 0.0);
    // Two equal jumps of 0.5 m/s: the same acceleration violation at steps 0 and 1.
    let v = [1.5, 2.0, 2.0, 2.0];
    let w = pr.max_violation(&v);
    assert_eq!((w.kind, w.step), (ConstraintKind::Accel, 0));
    assert!((w.amount - (0.5 - p.a_max() * p.h())).abs() < 1e-12);
    // A larger one later wins.
    let v = [1.5, 2.0, 3.0, 3.0];
    assert_eq!(pr.max_violation(&v).step, 2);
    // NaN is the worst, wherever it is.
    let v = [1.5, f64::NAN, 2.0, 2.0];
    let w = pr.max_violation(&v);
    assert!(w.amount.is_nan());
    assert_eq!(w.step, 1);
}

/// `Planner::step` works in the road's coordinates and `step_gap` in the ego's: the same
/// situation far along the road gives the same command (the target and the obstacle are
/// both taken relative to the ego).
#[test]
fn a_step_far_along_the_road_equals_the_step_in_ego_coordinates() {
    use planner_core::planner::{Observation, Planner, Vehicle};
    let p = Params::<f64>::table_i();
    let x = 537.25;
    let ahead = [Vehicle::wall(x + 60.0, 4.5)];
    let obs = Observation {
        x,
        v_prev: 12.0,
        vehicles: &ahead,
        stop_line: None,
        target_x: x + 1.0,
        v_ref: 12.0,
    };
    // A target weight and a target within the horizon's reach (N h v ≈ 2.4 m), so that
    // x^f − x shows in the command.
    let w = CostWeights {
        target_position: 1.0,
        ..CostWeights::default()
    };
    let mut road = Planner::<f64, 20>::new(p, w).expect("planner");
    let mut ego = Planner::<f64, 20>::new(p, w).expect("planner");
    let gap = 60.0 - 0.5 * (4.5 + p.length()) - p.d0();
    let a = road.step(&obs).expect("step");
    let b = ego.step_gap(12.0, gap, 1.0, 12.0).expect("step");
    assert!((a.v - b.v).abs() < 1e-9, "{} vs {}", a.v, b.v);
    assert!((a.gap - b.gap).abs() < 1e-9);
    // And the target matters here: 1 m ahead slows the vehicle, far ahead does not.
    let mut far = Planner::<f64, 20>::new(p, w).expect("planner");
    let c = far.step_gap(12.0, gap, 100.0, 12.0).expect("step");
    assert!(c.v > a.v + 1e-6, "{} vs {}", c.v, a.v);
}
