//! The solver's active-set step (`planner_core::solver::active_set`): what
//! it answers is a KKT point of (10) by an independent check written in the speeds (not
//! the solver's prefix-sum stencils), it finds the same optima as the interior-point
//! method alone, redundant speed bounds carry no multiplier, and its give-up paths (the
//! cap, the backoff after failures in a row, a non-finite warm start) hand over to the
//! interior-point method as documented.

use planner_core::planner::{free_road_gap, shifted, MIN_ROOM_M};
use planner_core::reuse::Duals;
use planner_core::safety::{max_braking, max_braking_command};
use planner_core::solver::active_set::{BACKOFF, FAILS_BEFORE_BACKOFF};
use planner_core::solver::IterationInfo;
use planner_core::{
    CostWeights, IpmSolver, Method, MpcSolver, Params, Real, Settings, SingleLaneProblem, Solution,
};
use proptest::prelude::*;

/// A stop-and-go drive behind a leader whose acceleration is redrawn every 150 steps
/// (as in `host-sim bench-planner`'s warm rows), one problem of (10) per step for a
/// planner that applies its own plan's first speed. Standstill steps with no room skip
/// the solver, as the planner does. Calls `visit` with each problem, its warm start, the
/// solver after it answered, the answer and which methods ran (one entry per reported
/// iteration).
fn drive<F: Real, const N: usize>(
    seed: u64,
    steps: usize,
    settings: Settings<F>,
    mut visit: impl FnMut(
        &SingleLaneProblem<F, N>,
        Option<&[F; N]>,
        &IpmSolver<F, N>,
        &Solution<F, N>,
        &[Method],
    ),
) {
    let p = Params::<F>::table_i();
    let pm = Params::<f64>::table_i();
    let mut solver = IpmSolver::<F, N>::new(settings);
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut uniform = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut x, mut v) = (0.0f64, 15.0f64);
    let (mut xl, mut vl) = (60.0f64, 15.0f64);
    let mut accel = 0.0;
    let mut plan: Option<[F; N]> = None;
    for step in 1..=steps {
        if step % 150 == 0 {
            accel = pm.a_min() + (pm.a_max() - pm.a_min()) * uniform();
        }
        let gap = (xl - x - pm.length() - pm.d0()).min(free_road_gap(&pm, N));
        let weights = CostWeights::default();
        let pr = SingleLaneProblem::<F, N>::new(
            &p,
            F::from_f64(v),
            F::from_f64(gap),
            F::SAFETY_MARGIN_M,
            weights,
            F::ZERO,
            p.v_max(),
        )
        .expect("the drive keeps the invariant");
        let vb = max_braking_command(&p, pr.v_prev);
        let applied = if -pr.safety_value(p.h() * vb, vb) < F::from_f64(MIN_ROOM_M) {
            plan = Some(max_braking(&p, pr.v_prev));
            vb.to_f64()
        } else {
            let warm = plan.as_ref().map(shifted);
            let mut methods = Vec::new();
            let sol = solver
                .solve_traced(&pr, warm.as_ref(), &mut |i: IterationInfo<F>| {
                    methods.push(i.method)
                })
                .unwrap_or_else(|e| panic!("step {step}: {e:?}"));
            visit(&pr, warm.as_ref(), &solver, &sol, &methods);
            plan = Some(sol.v);
            let first = sol.v.first().copied().unwrap_or(F::ZERO);
            first
                .max(pr.lo.first().copied().unwrap_or(F::ZERO))
                .min(pr.hi_exact.first().copied().unwrap_or(F::ZERO))
                .to_f64()
        };
        v = applied;
        x += v * pm.h();
        vl = (vl + accel * pm.h()).clamp(0.0, pm.v_max());
        xl += vl * pm.h();
    }
}

/// KKT residuals of `v` with multipliers `d`, computed in the speeds: the largest
/// stationarity residual relative to its largest term, the largest constraint value, the
/// largest |λ_i g_i| and the smallest multiplier.
fn kkt<const N: usize>(
    pr: &SingleLaneProblem<f64, N>,
    v: &[f64; N],
    d: &Duals<f64, N>,
) -> [f64; 4] {
    let w = pr.weights;
    let pos: f64 = v.iter().sum::<f64>() * pr.h;
    let mut grad = [0.0; N];
    let mut scale = 1.0f64;
    let add = |g: &mut [f64; N], j: usize, x: f64, scale: &mut f64| {
        g[j] += x;
        *scale = scale.max(x.abs());
    };
    for j in 0..N {
        let prev = if j == 0 { pr.v_prev } else { v[j - 1] };
        add(
            &mut grad,
            j,
            -2.0 * w.target_position * pr.h * (pr.target - pos),
            &mut scale,
        );
        add(
            &mut grad,
            j,
            2.0 * w.reference_speed * (v[j] - pr.v_ref),
            &mut scale,
        );
        add(&mut grad, j, 2.0 * w.smoothness * (v[j] - prev), &mut scale);
        if j + 1 < N {
            add(
                &mut grad,
                j,
                -2.0 * w.smoothness * (v[j + 1] - v[j]),
                &mut scale,
            );
        }
    }
    let (mut max_g, mut max_comp, mut min_l) = (f64::NEG_INFINITY, 0.0f64, f64::INFINITY);
    let mut prefix = 0.0;
    for k in 0..N {
        let prev = if k == 0 { pr.v_prev } else { v[k - 1] };
        prefix += v[k];
        let g = [
            v[k] - pr.hi[k],
            pr.lo[k] - v[k],
            v[k] - prev - pr.dv_max,
            pr.dv_min - (v[k] - prev),
            pr.safety_value(pr.h * prefix, v[k]),
        ];
        let l = [d.upper[k], d.lower[k], d.accel[k], d.decel[k], d.safety[k]];
        for (gi, li) in g.iter().zip(l.iter()) {
            max_g = max_g.max(*gi);
            max_comp = max_comp.max((gi * li).abs());
            min_l = min_l.min(*li);
        }
        // Σ λ ∇g, term by term.
        add(&mut grad, k, l[0] - l[1] + l[2] - l[3], &mut scale);
        if k > 0 {
            add(&mut grad, k - 1, -l[2] + l[3], &mut scale);
        }
        let slope = pr.h + v[k] / pr.brake;
        add(&mut grad, k, l[4] * slope, &mut scale);
        for j in 0..=k {
            add(&mut grad, j, l[4] * pr.h, &mut scale);
        }
    }
    let stat = grad.iter().fold(0.0f64, |a, g| a.max(g.abs())) / scale;
    [stat, max_g, max_comp, min_l]
}

fn assert_kkt<const N: usize>(
    pr: &SingleLaneProblem<f64, N>,
    sol: &Solution<f64, N>,
    d: &Duals<f64, N>,
    at: &str,
) {
    let [stat, max_g, comp, min_l] = kkt(pr, &sol.v, d);
    // The solvers' dual tolerance (Real::SOLVER_DUAL_TOL, f64) in the speeds as well.
    assert!(stat <= 1e-6, "{at}: stationarity {stat:e}");
    assert!(max_g <= 1e-9, "{at}: violation {max_g:e}");
    assert!(
        comp <= 1e-7 * (1.0 + sol.objective.abs()),
        "{at}: complementarity {comp:e}"
    );
    assert!(min_l >= 0.0, "{at}: negative multiplier {min_l:e}");
}

/// Every answer of stop-and-go drives, the active-set step's and the interior-point
/// method's, is a KKT point by the independent check, with the multipliers the solver
/// reports; both kinds of answer occur.
fn answers_are_kkt_points<const N: usize>() {
    let (mut by_active_set, mut by_ipm) = (0, 0);
    for seed in 1..=3 {
        let mut step = 0;
        drive::<f64, N>(seed, 2000, Settings::default(), |pr, _, solver, sol, _| {
            step += 1;
            let d = solver.duals().expect("a solve leaves its multipliers");
            assert_kkt(
                pr,
                sol,
                &d,
                &format!("N={N} seed {seed} step {step} {:?}", sol.method),
            );
            match sol.method {
                Method::ActiveSet => by_active_set += 1,
                Method::InteriorPoint => by_ipm += 1,
                other => panic!("a method this test does not know: {other:?}"),
            }
        });
    }
    assert!(
        by_active_set > 1000 && by_ipm > 10,
        "{by_active_set} / {by_ipm}"
    );
}

#[test]
fn answers_are_kkt_points_n20() {
    answers_are_kkt_points::<20>();
}

#[test]
fn answers_are_kkt_points_n50() {
    answers_are_kkt_points::<50>();
}

/// Solution::iterations counts every Newton step: the active-set step's and, when it
/// gave up, the interior-point iterations after them (each trace report that took a
/// step).
#[test]
fn iterations_count_every_newton_step() {
    let mut failed_then_ipm = 0;
    drive::<f64, 20>(2, 2000, Settings::default(), |_, _, _, sol, methods| {
        let _ = methods;
        assert!(sol.iterations >= 1 || sol.method == Method::ActiveSet);
        if sol.method == Method::InteriorPoint && methods.contains(&Method::ActiveSet) {
            failed_then_ipm += 1;
        }
    });
    let mut steps_taken = 0u32;
    let mut solver = IpmSolver::<f64, 20>::default();
    let mut plan: Option<[f64; 20]> = None;
    for k in 0..400 {
        // An obstacle that comes and goes: gaps jump, so some warm starts are far off.
        let gap = if (k / 25) % 2 == 0 {
            12.0 + 0.01 * k as f64
        } else {
            80.0
        };
        let pr = SingleLaneProblem::<f64, 20>::new(
            &Params::table_i(),
            8.0,
            gap,
            f64::SAFETY_MARGIN_M,
            CostWeights::default(),
            0.0,
            20.0,
        )
        .expect("feasible");
        let warm = plan.as_ref().map(shifted);
        steps_taken = 0;
        let sol = solver
            .solve_traced(&pr, warm.as_ref(), &mut |i: IterationInfo<f64>| {
                if i.step > 0.0 {
                    steps_taken += 1;
                }
            })
            .expect("solves");
        assert_eq!(sol.iterations, steps_taken, "solve {k}: {:?}", sol.method);
        plan = Some(sol.v);
    }
    assert!(
        failed_then_ipm > 0,
        "the drive must exercise a failed active-set step"
    );
    let _ = steps_taken;
}

/// After FAILS_BEFORE_BACKOFF failures in a row the next BACKOFF warm starts skip the
/// step; a success resets the count. With a cap of one Newton step the step fails
/// wherever its first step does not land on the optimum, so the drive exercises the
/// rule; an independent model of it predicts which solves try the step.
#[test]
fn backoff_follows_its_rule() {
    let settings = Settings::default().with_active_set_iter(1).expect("valid");
    let (mut fails, mut skip, mut have_duals) = (0u8, 0u8, false);
    let (mut tried, mut skipped, mut failures) = (0, 0, 0);
    drive::<f64, 20>(3, 1500, settings, |_, warm, _, sol, methods| {
        let attempted = methods.contains(&Method::ActiveSet);
        let expected = if warm.is_none() || !have_duals {
            false
        } else if skip > 0 {
            skip -= 1;
            false
        } else {
            true
        };
        assert_eq!(attempted, expected, "fails {fails}, skip {skip}");
        if attempted {
            tried += 1;
            if sol.method == Method::ActiveSet {
                fails = 0;
            } else {
                failures += 1;
                fails = fails.saturating_add(1);
                if fails >= FAILS_BEFORE_BACKOFF {
                    skip = BACKOFF;
                }
            }
        } else if warm.is_some() && have_duals {
            skipped += 1;
        }
        have_duals = true;
    });
    assert!(
        tried > 50 && skipped > 50 && failures > 20,
        "{tried} {skipped} {failures}"
    );
}

/// With the step off, or with a warm start that is not finite, no active-set iteration
/// runs and the interior-point method answers.
#[test]
fn the_step_runs_only_on_finite_warm_starts_when_on() {
    let off = Settings::default().with_active_set_iter(0).expect("valid");
    drive::<f64, 20>(1, 600, off, |_, _, _, sol, methods| {
        assert_eq!(sol.method, Method::InteriorPoint);
        assert!(!methods.contains(&Method::ActiveSet));
    });
    let pr = SingleLaneProblem::<f64, 20>::new(
        &Params::table_i(),
        12.0,
        40.0,
        f64::SAFETY_MARGIN_M,
        CostWeights::default(),
        0.0,
        20.0,
    )
    .expect("feasible");
    let mut solver = IpmSolver::<f64, 20>::default();
    let first = solver.solve(&pr, None).expect("solves");
    assert_eq!(
        first.method,
        Method::InteriorPoint,
        "a cold start has no multipliers"
    );
    let mut bad = shifted(&first.v);
    bad[3] = f64::NAN;
    let mut methods = Vec::new();
    let sol = solver
        .solve_traced(&pr, Some(&bad), &mut |i: IterationInfo<f64>| {
            methods.push(i.method)
        })
        .expect("a non-finite warm start is answered cold");
    assert!(methods.iter().all(|m| *m == Method::InteriorPoint));
    assert!((sol.objective - first.objective).abs() <= 1e-8 * (1.0 + first.objective.abs()));
    // A finite warm start of the same problem: the step answers.
    let again = solver.solve(&pr, Some(&shifted(&sol.v))).expect("solves");
    assert_eq!(again.method, Method::ActiveSet);
}

/// Accelerating on a free road the bound v_k ≤ hi_k is implied by the acceleration
/// limits where hi_k = v_{t−h} + (k+1) amax h: an active-set answer gives it no
/// multiplier (rule 3), and the acceleration limits that imply it carry one.
#[test]
fn implied_bounds_carry_no_multiplier() {
    let p = Params::<f64>::table_i();
    let pr = SingleLaneProblem::<f64, 20>::new(
        &p,
        10.0,
        free_road_gap(&p, 20),
        f64::SAFETY_MARGIN_M,
        CostWeights::default(),
        0.0,
        p.v_max(),
    )
    .expect("feasible");
    let mut solver = IpmSolver::<f64, 20>::default();
    let cold = solver.solve(&pr, None).expect("solves");
    let sol = solver.solve(&pr, Some(&cold.v)).expect("solves");
    assert_eq!(sol.method, Method::ActiveSet);
    let d = solver.duals().expect("multipliers");
    let mut implied = 0;
    for k in 0..20 {
        if pr.hi[k] >= pr.v_prev + (k + 1) as f64 * pr.dv_max {
            implied += 1;
            assert_eq!(d.upper[k], 0.0, "k={k}");
        }
    }
    assert!(implied >= 10, "{implied}");
    assert!(d.accel[0] > 0.0, "{:?}", d.accel);
    assert_kkt(&pr, &sol, &d, "accelerating");
}

fn weights() -> impl Strategy<Value = CostWeights<f64>> {
    (
        prop::sample::select(vec![0.0, 1e-3, 0.3]),
        prop::sample::select(vec![0.4, 1.0, 2.5]),
        prop::sample::select(vec![0.0, 3.0, 10.0]),
    )
        .prop_map(
            |(target_position, reference_speed, smoothness)| CostWeights {
                target_position,
                reference_speed,
                smoothness,
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// From the previous step's answer, shifted, the default solver (active-set step
    /// first) and the interior-point method alone, solving cold, find the same optimum
    /// of a problem that moved by one step and a random change of the gap and speed.
    #[test]
    fn the_step_finds_the_interior_point_optimum(
        v in 0.0f64..27.8,
        margin in 0.05f64..60.0,
        dv in -0.05f64..0.05,
        dgap in -0.5f64..0.5,
        v_ref in 0.0f64..27.8,
        target in 0.0f64..400.0,
        w in weights(),
    ) {
        let p = Params::<f64>::table_i();
        let make = |v: f64, gap: f64| {
            SingleLaneProblem::<f64, 20>::new(&p, v.clamp(0.0, p.v_max()), gap.min(free_road_gap(&p, 20)), f64::SAFETY_MARGIN_M, w, target, v_ref).ok()
        };
        let gap = planner_core::safety::d_s(&p, v) + margin;
        let (Some(before), Some(after)) = (make(v, gap), make(v + dv, gap + dgap)) else {
            return Ok(());
        };
        let mut solver = IpmSolver::<f64, 20>::default();
        let Ok(first) = solver.solve(&before, None) else { return Ok(()) };
        let sol = solver.solve(&after, Some(&shifted(&first.v))).expect("the default solver answers");
        let reference = IpmSolver::<f64, 20>::new(Settings::interior_point_only())
            .solve(&after, None)
            .expect("the interior-point method answers");
        let gap_rel = (sol.objective - reference.objective).abs() / (1.0 + reference.objective.abs());
        prop_assert!(gap_rel <= 1e-7, "{:?}: {} vs {} ({gap_rel:e})", sol.method, sol.objective, reference.objective);
        prop_assert!(after.max_violation(&sol.v).amount <= 1e-9);
        let d = solver.duals().expect("multipliers");
        let [stat, max_g, _, min_l] = kkt(&after, &sol.v, &d);
        prop_assert!(stat <= 1e-6 && max_g <= 1e-9 && min_l >= 0.0, "{stat:e} {max_g:e} {min_l:e}");
    }
}

/// In f32 (the firmware's precision) the drives solve every step, mostly by the step,
/// and its answers satisfy the constraints to f32's tolerance.
#[test]
fn f32_drives_solve_every_step() {
    for seed in 1..=2 {
        let (mut by_active_set, mut total) = (0, 0);
        drive::<f32, 50>(seed, 1500, Settings::default(), |pr, _, _, sol, _| {
            total += 1;
            if sol.method == Method::ActiveSet {
                by_active_set += 1;
            }
            let viol = pr.max_violation(&sol.v);
            assert!(viol.amount <= 1e-3, "{viol:?}");
        });
        assert!(
            by_active_set * 10 > total,
            "seed {seed}: {by_active_set} of {total}"
        );
    }
}
