//! `bench-planner`: our solver and Clarabel on identical instances of (10), side by side.

use super::clarabel::{conic_data, ClarabelSolver, PersistentClarabel};
use super::instances::{random_instances, rng};
use planner_core::planner::{free_road_gap, shifted};
use planner_core::{
    CostWeights, IpmSolver, Method, MpcSolver, Params, Real, ReusePolicy, Settings,
    SingleLaneProblem, Solution, SolveError,
};
use rand::Rng;
use serde::Serialize;
use std::time::Instant;

/// One row of the benchmark output.
#[derive(Debug, Clone, Serialize)]
pub struct BenchResult {
    /// N.
    pub horizon: usize,
    /// "cold" or "warm".
    pub mode: &'static str,
    /// Problems solved by both.
    pub problems: usize,
    /// Median wall time of our solver (µs).
    pub planner_median_us: f64,
    /// 99th percentile of our solver (µs).
    pub planner_p99_us: f64,
    /// Median wall time of Clarabel, setup + solve (µs).
    pub clarabel_median_us: f64,
    /// clarabel_median_us / planner_median_us.
    pub speedup: f64,
    /// Median wall time of a resident Clarabel that takes each problem's data in place
    /// (`update_P/q/A/b`, presolve off) and solves: how a user would run it in a
    /// receding horizon (µs).
    pub clarabel_persistent_median_us: f64,
    /// clarabel_persistent_median_us / planner_median_us.
    pub speedup_persistent: f64,
    /// Median wall time of Clarabel's `solve()` alone, its setup done beforehand and
    /// not timed (µs): a lower bound on any way of running it.
    pub clarabel_solve_only_median_us: f64,
    /// clarabel_solve_only_median_us / planner_median_us.
    pub speedup_solve_only: f64,
    /// Largest |J_ours − J_resident| / (1 + |J_resident|): the resident solver answers
    /// the same problems.
    pub max_rel_objective_gap_persistent: f64,
    /// Largest |J_ours − J_clarabel| / (1 + |J_clarabel|).
    pub max_rel_objective_gap: f64,
    /// Largest constraint violation of our plans (m or m/s).
    pub max_constraint_violation: f64,
    /// Median Newton steps of ours per solve.
    pub planner_median_iterations: f64,
    /// Of our solves, the share the active-set step answered.
    pub active_set_share: f64,
    /// Median wall time of our solver with the interior-point method alone, as it was
    /// before the active-set step ([`planner_core::Settings::interior_point_only`]), on the same
    /// problems, warm-started from its own previous plans (µs).
    pub interior_point_median_us: f64,
    /// Its 99th percentile (µs).
    pub interior_point_p99_us: f64,
    /// Its median iterations.
    pub interior_point_median_iterations: f64,
    /// interior_point_median_us / planner_median_us.
    pub speedup_vs_interior_point: f64,
    /// Largest |J_ours − J_interior_point| / (1 + |J_interior_point|): both find the
    /// same optima.
    pub max_rel_objective_gap_interior_point: f64,
}

/// The whole benchmark output.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// Rows: N = 20 and 50, cold and warm.
    pub results: Vec<BenchResult>,
    /// The warm drive solving every step against certified plan reuse, N = 20 and 50.
    pub reuse: Vec<super::reuse::ReuseRow>,
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let idx = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[idx.min(sorted.len() - 1)]
}

/// Times `f` as the minimum over `reps` runs (µs): the least disturbed by the machine.
/// `setup` runs before each repetition, outside the timed region.
fn time_us<T>(reps: usize, mut setup: impl FnMut(), mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..reps.max(1) {
        setup();
        let t0 = Instant::now();
        let r = f();
        best = best.min(t0.elapsed().as_secs_f64() * 1e6);
        last = Some(r);
    }
    (best, last.expect("reps >= 1"))
}

struct Sample {
    ours_us: f64,
    ipm_us: f64,
    ipm_iterations: u32,
    active_set: bool,
    gap_ipm: f64,
    clarabel_us: f64,
    persistent_us: f64,
    solve_only_us: f64,
    gap: f64,
    gap_persistent: f64,
    viol: f64,
    iterations: u32,
}

/// Clarabel three ways on `pr`'s conic data: setup + solve from scratch (the
/// reference answer), `solve()` alone on a solver built beforehand, and the resident
/// solver taking the data in place. Times in µs, with the objectives of the reference
/// and of the resident solver.
fn clarabel_times<const N: usize>(
    pr: &SingleLaneProblem<f64, N>,
    resident: &mut PersistentClarabel,
    reps: usize,
) -> Option<[f64; 5]> {
    let data = conic_data(pr);
    let reference = ClarabelSolver {
        tol_gap: 1e-8,
        tol_feas: 1e-8,
        accept_almost_solved: false,
    };
    let (full_us, r) = time_us(reps, || {}, || reference.solve_conic(pr, &data));
    let r = r.ok()?;
    // Solve only: a fresh resident solver per repetition, built outside the timing.
    let fresh = std::cell::RefCell::new(PersistentClarabel::new(1e-8));
    let (solve_only_us, _) = time_us(
        reps,
        || {
            let mut f = PersistentClarabel::new(1e-8);
            let _ = f.load(&data);
            *fresh.borrow_mut() = f;
        },
        || fresh.borrow_mut().solve_loaded(pr, &data),
    );
    // Resident: the first problem of a shape builds it, untimed (a one-off setup).
    if !resident.load(&data).ok()? {
        let _ = resident.solve_loaded(pr, &data);
    }
    let (persistent_us, p) = time_us(
        reps,
        || {},
        || {
            resident.load(&data)?;
            resident.solve_loaded(pr, &data)
        },
    );
    let p = p.ok()?;
    Some([
        full_us,
        solve_only_us,
        persistent_us,
        r.objective,
        p.objective,
    ])
}

/// Our two solvers in one: the default one (the active-set step first) and the
/// interior-point method alone, each with its own warm-start chain.
struct Ours<const N: usize> {
    solver: IpmSolver<f64, N>,
    ipm: IpmSolver<f64, N>,
}

impl<const N: usize> Ours<N> {
    fn new() -> Self {
        Self {
            solver: IpmSolver::default(),
            ipm: IpmSolver::new(Settings::interior_point_only()),
        }
    }
}

/// Times `solver` on `pr` from `warm`, every repetition from the same solver state
/// (warm duals included).
fn time_solver<const N: usize>(
    solver: &mut IpmSolver<f64, N>,
    pr: &SingleLaneProblem<f64, N>,
    warm: Option<&[f64; N]>,
    reps: usize,
) -> (f64, Result<Solution<f64, N>, SolveError>) {
    let snapshot = solver.clone();
    let cell = std::cell::RefCell::new(solver);
    time_us(
        reps,
        || cell.borrow_mut().clone_from(&snapshot),
        || cell.borrow_mut().solve(pr, warm),
    )
}

/// One of our solves as it was timed: the problem, the warm start and the solver's state
/// before it, for [`retime`].
struct Replay<const N: usize> {
    pr: SingleLaneProblem<f64, N>,
    warm: [Option<[f64; N]>; 2],
    state: [IpmSolver<f64, N>; 2],
}

/// Times every recorded solve of ours again, `reps` rounds over the whole list, and keeps
/// each solve's least time. Why: a solve's `reps` back-to-back repetitions all fall in
/// the same few tens of µs, so a millisecond-long slowdown of the machine (another VM on
/// the host, a frequency step) slows all of them and lands in the p99; rounds over the
/// whole list are spread over the run, so each solve gets a time the machine did not
/// disturb. Solver state is restored before each solve, so every round times the same
/// work.
fn retime<const N: usize>(samples: &mut [Sample], replays: &[Replay<N>], reps: usize) {
    for _ in 0..reps {
        for (s, r) in samples.iter_mut().zip(replays) {
            for (k, t) in [&mut s.ours_us, &mut s.ipm_us].into_iter().enumerate() {
                let mut solver = r.state[k].clone();
                let t0 = Instant::now();
                let _ = std::hint::black_box(solver.solve(&r.pr, r.warm[k].as_ref()));
                *t = t.min(t0.elapsed().as_secs_f64() * 1e6);
            }
        }
    }
}

/// Both of ours and Clarabel on `pr`; our plans (default, interior point alone) for the
/// next warm starts. Our solves are recorded in `replays` for [`retime`].
fn compare<const N: usize>(
    pr: &SingleLaneProblem<f64, N>,
    warm: [Option<&[f64; N]>; 2],
    ours: &mut Ours<N>,
    resident: &mut PersistentClarabel,
    reps: usize,
    replays: &mut Vec<Replay<N>>,
) -> Option<(Sample, [[f64; N]; 2])> {
    let replay = Replay {
        pr: pr.clone(),
        warm: warm.map(|w| w.copied()),
        state: [ours.solver.clone(), ours.ipm.clone()],
    };
    let [warm, ipm_warm] = warm;
    let (ours_us, sol) = time_solver(&mut ours.solver, pr, warm, reps);
    let (ipm_us, ipm) = time_solver(&mut ours.ipm, pr, ipm_warm, reps);
    let (sol, ipm) = (sol.ok()?, ipm.ok()?);
    let [clarabel_us, solve_only_us, persistent_us, j_ref, j_res] =
        clarabel_times(pr, resident, reps)?;
    let gap = |j: f64| (sol.objective - j).abs() / (1.0 + j.abs());
    replays.push(replay);
    Some((
        Sample {
            ours_us,
            ipm_us,
            ipm_iterations: ipm.iterations,
            active_set: sol.method == Method::ActiveSet,
            clarabel_us,
            persistent_us,
            solve_only_us,
            gap: gap(j_ref),
            gap_ipm: gap(ipm.objective),
            gap_persistent: gap(j_res),
            viol: pr.max_violation(&sol.v).amount.max(0.0),
            iterations: sol.iterations,
        },
        [sol.v, ipm.v],
    ))
}

fn summarize(horizon: usize, mode: &'static str, samples: &[Sample]) -> BenchResult {
    let mut ours: Vec<f64> = samples.iter().map(|s| s.ours_us).collect();
    let median_of = |f: fn(&Sample) -> f64| {
        let mut v: Vec<f64> = samples.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        percentile(&v, 0.5)
    };
    let mut cl: Vec<f64> = samples.iter().map(|s| s.clarabel_us).collect();
    let mut it: Vec<f64> = samples.iter().map(|s| f64::from(s.iterations)).collect();
    ours.sort_by(f64::total_cmp);
    cl.sort_by(f64::total_cmp);
    it.sort_by(f64::total_cmp);
    let pm = percentile(&ours, 0.5);
    let cm = percentile(&cl, 0.5);
    let persistent = median_of(|s| s.persistent_us);
    let mut ipm: Vec<f64> = samples.iter().map(|s| s.ipm_us).collect();
    ipm.sort_by(f64::total_cmp);
    let ipm_median = percentile(&ipm, 0.5);
    let solve_only = median_of(|s| s.solve_only_us);
    BenchResult {
        horizon,
        mode,
        problems: samples.len(),
        planner_median_us: pm,
        planner_p99_us: percentile(&ours, 0.99),
        clarabel_median_us: cm,
        speedup: cm / pm,
        clarabel_persistent_median_us: persistent,
        speedup_persistent: persistent / pm,
        clarabel_solve_only_median_us: solve_only,
        speedup_solve_only: solve_only / pm,
        max_rel_objective_gap_persistent: samples
            .iter()
            .map(|s| s.gap_persistent)
            .fold(0.0, f64::max),
        max_rel_objective_gap: samples.iter().map(|s| s.gap).fold(0.0, f64::max),
        max_constraint_violation: samples.iter().map(|s| s.viol).fold(0.0, f64::max),
        planner_median_iterations: percentile(&it, 0.5),
        active_set_share: samples.iter().filter(|s| s.active_set).count() as f64
            / samples.len().max(1) as f64,
        interior_point_median_us: ipm_median,
        interior_point_p99_us: percentile(&ipm, 0.99),
        interior_point_median_iterations: median_of(|s| f64::from(s.ipm_iterations)),
        speedup_vs_interior_point: ipm_median / pm,
        max_rel_objective_gap_interior_point: samples.iter().map(|s| s.gap_ipm).fold(0.0, f64::max),
    }
}

/// Cold: `problems` random instances, each solved from scratch by both.
pub fn cold<const N: usize>(problems: usize, seed: u64, reps: usize) -> BenchResult {
    let mut ours = Ours::<N>::new();
    let mut resident = PersistentClarabel::new(1e-8);
    let mut replays = Vec::with_capacity(problems);
    let mut samples: Vec<Sample> = random_instances(seed, problems, N)
        .iter()
        .filter_map(|spec| spec.build::<f64, N>())
        .filter_map(|pr| {
            compare(
                &pr,
                [None, None],
                &mut ours,
                &mut resident,
                reps,
                &mut replays,
            )
            .map(|(s, _)| s)
        })
        .collect();
    retime(&mut samples, &replays, reps);
    summarize(N, "cold", &samples)
}

/// Warm: the receding-horizon sequence of a simulated drive — one follower behind a
/// stop-and-go leader, tracking vmax — each problem warm-started from our previous plan,
/// shifted (the interior-point method alone from its own); Clarabel solves the same
/// problems cold.
pub fn warm<const N: usize>(problems: usize, seed: u64, reps: usize) -> BenchResult {
    let p = Params::<f64>::table_i();
    let mut r = rng(seed);
    let mut ours = Ours::<N>::new();
    let mut resident = PersistentClarabel::new(1e-8);
    let (mut x, mut v) = (0.0f64, 15.0f64);
    let (mut xl, mut vl) = (60.0f64, 15.0f64);
    let mut accel = 0.0;
    let mut plans: Option<[[f64; N]; 2]> = None;
    let mut samples = Vec::with_capacity(problems);
    let mut replays = Vec::with_capacity(problems);
    let mut step = 0u64;
    while samples.len() < problems && step < 100 * problems as u64 {
        step += 1;
        if step.is_multiple_of(150) {
            accel = r.random_range(p.a_min()..p.a_max());
        }
        let gap = (xl - x - p.length() - p.d0()).min(free_road_gap(&p, N));
        let pr = SingleLaneProblem::<f64, N>::new(
            &p,
            v,
            gap,
            f64::SAFETY_MARGIN_M,
            CostWeights::default(),
            0.0,
            p.v_max(),
        );
        let Ok(pr) = pr else { break };
        let warm = plans.map(|[a, b]| [shifted(&a), shifted(&b)]);
        let starts = warm
            .as_ref()
            .map_or([None, None], |[a, b]| [Some(a), Some(b)]);
        let Some((sample, sols)) =
            compare(&pr, starts, &mut ours, &mut resident, reps, &mut replays)
        else {
            break;
        };
        samples.push(sample);
        plans = Some(sols);
        v = sols[0][0].clamp(pr.lo[0], pr.hi_exact[0]);
        x += v * p.h();
        vl = (vl + accel * p.h()).clamp(0.0, p.v_max());
        xl += vl * p.h();
    }
    retime(&mut samples, &replays, reps);
    summarize(N, "warm", &samples)
}

/// The full benchmark: N = 20 and 50, cold and warm.
pub fn run(problems: usize, seed: u64, reps: usize) -> BenchReport {
    BenchReport {
        results: vec![
            cold::<20>(problems, seed, reps),
            warm::<20>(problems, seed, reps),
            cold::<50>(problems, seed, reps),
            warm::<50>(problems, seed, reps),
        ],
        // A longer drive than the solver rows': reuse pays off over many steps.
        reuse: super::reuse::run(problems.max(1) * 10, seed, ReusePolicy::default()),
    }
}
