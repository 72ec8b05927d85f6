//! Planners built in place in static slots: a slot hands out a planner only
//! after `init`, that planner plans bit for bit what one built by `new` plans (also after a
//! slot is re-initialised over a used planner), and a refused `init` changes nothing. The
//! in-place resets and workspaces they rely on (`IpmSolver::reset`, the lateral QP's
//! `LateralWork`) are checked against fresh state the same way.

use planner_core::lateral::{
    solve_lateral, solve_lateral_in, DenseQp, IpmWork, LateralInput, LateralWeights, LateralWork,
    BLOCKS, ROWS,
};
use planner_core::planner::Vehicle;
use planner_core::{
    ConfigError, CostWeights, IpmSolver, LaneObservation, LanePlanner, LanePlannerSlot, MpcSolver,
    Observation, Params, Planner, PlannerSlot, Pose, Real, Road, SingleLaneProblem,
};

const N: usize = 20;

/// Slots are `const`: statics of them need no runtime construction.
static STATIC_PLANNER: PlannerSlot<f32, 50> = PlannerSlot::new();
static STATIC_LANE_PLANNER: LanePlannerSlot<f32, 50> = LanePlannerSlot::new();

/// Commands of a single-lane approach to a stopped car, bit for bit.
fn approach<F: Real>(pl: &mut Planner<F, N>, steps: usize) -> Vec<u64> {
    let p = *pl.params();
    let car = [Vehicle::wall(F::from_f64(60.0), F::from_f64(4.5))];
    let (mut x, mut v) = (F::ZERO, F::from_f64(15.0));
    let mut out = Vec::new();
    for _ in 0..steps {
        let obs = Observation {
            x,
            v_prev: v,
            vehicles: &car,
            stop_line: None,
            target_x: F::ZERO,
            v_ref: p.v_max(),
        };
        let c = pl.step(&obs).expect("valid input");
        v = c.v;
        x += v * p.h();
        out.push(v.to_f64().to_bits());
    }
    out
}

/// Commands (v, ω) of a lane change from lane 0 to 1 on an empty road, bit for bit.
fn lane_change<F: Real>(lp: &mut LanePlanner<F, N>, steps: usize) -> Vec<(u64, u64)> {
    let p = *lp.params();
    let road = Road {
        lanes: 2,
        lane_width: F::from_f64(3.6),
        end_x: None,
    };
    let mut q = Pose {
        x: F::ZERO,
        y: F::from_f64(1.8),
        theta: F::ZERO,
    };
    let (mut v, mut w) = (F::from_f64(15.0), F::ZERO);
    let mut out = Vec::new();
    for _ in 0..steps {
        let obs = LaneObservation {
            pose: q,
            v_prev: v,
            omega_prev: w,
            others: &[],
            road,
            target_lane: 1,
            target: F::ZERO,
            v_ref: F::from_f64(15.0),
        };
        let c = lp.step(&obs).expect("valid input");
        q = planner_core::unicycle::step(q, c.v, c.omega, p.h());
        (v, w) = (c.v, c.omega);
        out.push((v.to_f64().to_bits(), w.to_f64().to_bits()));
    }
    out
}

fn slot_plans_as_new<F: Real>() {
    let params = Params::<F>::table_i();
    let w = CostWeights::default();
    let expected = approach(&mut Planner::new(params, w).expect("valid"), 400);
    let mut slot = Box::new(PlannerSlot::<F, N>::new());
    assert!(
        slot.get().is_none() && !slot.is_ready(),
        "no planner before init"
    );
    let pl = slot.init(params, w).expect("valid");
    assert_eq!(approach(pl, 400), expected);
    assert!(slot.is_ready() && slot.get().is_some());
    // Re-initialised over a used planner (plan, solver duals): as new again, to the last
    // bit of its state (Debug prints every field, floats exactly).
    let pl = slot.init(params, w).expect("valid");
    let fresh = Planner::<F, N>::new(params, w).expect("valid");
    assert_eq!(format!("{pl:?}"), format!("{fresh:?}"));
    assert_eq!(approach(pl, 400), expected);

    let expected = lane_change(&mut LanePlanner::new(params, w, 0).expect("valid"), 300);
    assert!(expected
        .iter()
        .any(|&(_, om)| F::ZERO.to_f64().to_bits() != om));
    let mut slot = Box::new(LanePlannerSlot::<F, N>::new());
    assert!(slot.get().is_none());
    let lp = slot.init(params, w, 0).expect("valid");
    assert_eq!(lane_change(lp, 300), expected);
    assert!(slot.is_ready());
    assert_eq!(
        slot.get().map(|lp| lp.lane()),
        Some(1),
        "the same planner, changed lanes"
    );
    let lp = slot.init(params, w, 0).expect("valid");
    let fresh = LanePlanner::<F, N>::new(params, w, 0).expect("valid");
    assert_eq!(format!("{lp:?}"), format!("{fresh:?}"));
    assert_eq!(lane_change(lp, 300), expected);
}

#[test]
fn a_slot_plans_exactly_what_new_builds_in_f64_and_f32() {
    slot_plans_as_new::<f64>();
    slot_plans_as_new::<f32>();
    // The statics are usable as they are (`new` is all a static needs).
    assert!(!STATIC_PLANNER.is_ready() && !STATIC_LANE_PLANNER.is_ready());
}

#[test]
fn a_refused_init_changes_nothing() {
    let params = Params::<f64>::table_i();
    let w = CostWeights::default();
    let bad = CostWeights {
        reference_speed: 0.0,
        smoothness: 0.0,
        ..w
    };
    let mut empty = PlannerSlot::<f64, N>::new();
    assert_eq!(
        empty.init(params, bad).err(),
        Some(ConfigError::InvalidWeights)
    );
    assert!(empty.get().is_none(), "still empty after a refused init");
    let mut lane_empty = LanePlannerSlot::<f64, N>::new();
    assert!(lane_empty.init(params, bad, 0).is_err());
    assert!(lane_empty.get().is_none());

    // A used planner: a refused init in the middle of a drive leaves it planning exactly
    // as a twin that never saw it.
    let mut twin = Planner::<f64, N>::new(params, w).expect("valid");
    let mut slot = PlannerSlot::<f64, N>::new();
    slot.init(params, w).expect("valid");
    let a = slot.get().expect("initialised");
    let first = approach(a, 150);
    assert_eq!(first, approach(&mut twin, 150));
    let nan = CostWeights {
        target_position: f64::NAN,
        ..w
    };
    assert!(slot.init(params, nan).is_err());
    let a = slot.get().expect("still there");
    // Both continue from their own state (x and v restart at the same values).
    assert_eq!(approach(a, 100), approach(&mut twin, 100));
}

/// A problem of the planner's kind with a stopped car `gap` metres ahead.
fn problem(gap: f64, v: f64) -> SingleLaneProblem<f64, N> {
    let p = Params::<f64>::table_i();
    SingleLaneProblem::new(&p, v, gap, 1e-6, CostWeights::default(), 0.0, 27.8).expect("valid")
}

#[test]
fn a_reset_solver_solves_as_a_new_one() {
    let mut used = IpmSolver::<f64, N>::default();
    for (gap, v) in [(40.0, 15.0), (25.0, 12.0), (80.0, 20.0)] {
        used.solve(&problem(gap, v), None).expect("solves");
    }
    assert!(used.duals().is_some());
    used.reset(Default::default());
    assert!(used.duals().is_none(), "no duals after a reset");
    let mut fresh = IpmSolver::<f64, N>::default();
    // Every field as `new` builds it (Debug prints floats exactly).
    assert_eq!(format!("{used:?}"), format!("{fresh:?}"));
    for (gap, v) in [(33.0, 14.0), (60.0, 9.0)] {
        let (a, b) = (
            used.solve(&problem(gap, v), None).expect("solves"),
            fresh.solve(&problem(gap, v), None).expect("solves"),
        );
        assert_eq!(a.v.map(f64::to_bits), b.v.map(f64::to_bits));
        assert_eq!(a.iterations, b.iterations);
    }
}

#[test]
fn the_lateral_qp_answers_the_same_in_any_workspace() {
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut r = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut dirty = LateralWork::<f64>::new();
    let mut dirty_ipm = IpmWork::<f64>::new();
    let mut solved = 0;
    for case in 0..200 {
        let v = [10.0 + 10.0 * r(); N];
        let omega_nominal: [f64; N] = core::array::from_fn(|_| 0.2 * (r() - 0.5));
        let y_ref = [1.8 + 3.6 * r(); N];
        let theta_ref = [0.0; N];
        let omega_lo = [-2.0; N];
        let omega_hi = [2.0; N];
        let inp = LateralInput {
            h: 0.01,
            y: 1.8 + r(),
            theta: 0.2 * (r() - 0.5),
            omega_prev: 0.1 * (r() - 0.5),
            v: &v,
            omega_nominal: &omega_nominal,
            y_ref: &y_ref,
            theta_ref: &theta_ref,
            omega_lo: &omega_lo,
            omega_hi: &omega_hi,
            theta_bounds: (-0.5, 0.5),
            band: (0.0, 7.2),
            half_length: 2.25,
            half_width: 0.85,
            weights: LateralWeights::default(),
        };
        let fresh = solve_lateral(&inp);
        let reused = solve_lateral_in(&mut dirty, &inp);
        assert_eq!(
            fresh.map(|(w, it)| (w.map(f64::to_bits), it)),
            reused.map(|(w, it)| (w.map(f64::to_bits), it)),
            "case {case}"
        );
        solved += usize::from(fresh.is_ok());
        // The dense solver alone, on a random convex QP, in a workspace left dirty.
        let mut qp = DenseQp {
            p: [[0.0; BLOCKS]; BLOCKS],
            q: core::array::from_fn(|_| r() - 0.5),
            g_mat: core::array::from_fn(|_| core::array::from_fn(|_| r() - 0.5)),
            g: core::array::from_fn(|_| r()),
        };
        for i in 0..BLOCKS {
            qp.p[i][i] = 1.0 + r();
        }
        let a = qp.solve();
        let b = qp.solve_with(&mut dirty_ipm);
        assert_eq!(
            a.map(|(u, it)| (u.map(f64::to_bits), it)),
            b.map(|(u, it)| (u.map(f64::to_bits), it))
        );
        assert_eq!(ROWS, qp.g.len());
    }
    assert!(solved > 150, "only {solved} of 200 lateral QPs solved");
}
