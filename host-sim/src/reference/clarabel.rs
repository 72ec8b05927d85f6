//! Clarabel as the reference solver for problem (10), on the identical SOCP.
//!
//! Formulation (same variables as ours, z_k = Σ_{j≤k} v_j): the 4N linear constraints in
//! the nonnegative cone; each safety constraint v_k² ≤ 2|amin| t_k, with
//! t_k = x̄ − |amin|h²/2 − h z_k − h v_k, as the second-order cone
//! ‖(2 v_k, t_k − 2|amin|)‖ ≤ t_k + 2|amin|.
//!
//! Clarabel's variables are shifted, δ = z − z_c, with z_c the prefix sums of the Lemma 2
//! max-braking sequence (a feasible point that owes nothing to our solver): Clarabel's
//! objective ½δᵀPδ + q'ᵀδ then equals J − J(z_c), so its relative duality-gap test is
//! measured against a quantity of J's size. Unshifted, the dropped constant of J can be
//! 10⁴ times J and Clarabel stops (or gives up, "AlmostSolved") ~1e-5 short of the optimum.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use planner_core::{Method, MpcSolver, SingleLaneProblem, Solution, SolveError};

/// Clarabel, cold-started every time (Clarabel has no warm start), tolerances 1e-10.
#[derive(Debug, Clone)]
pub struct ClarabelSolver {
    /// Absolute and relative duality-gap tolerance.
    pub tol_gap: f64,
    /// Primal/dual feasibility tolerance.
    pub tol_feas: f64,
    /// Return Clarabel's reduced-accuracy answers ("AlmostSolved") instead of an error.
    /// Off for cross-checks (only certified optima count); on when Clarabel drives a
    /// planner, whose verifier decides whether the plan is safe to apply.
    pub accept_almost_solved: bool,
}

impl Default for ClarabelSolver {
    fn default() -> Self {
        Self {
            tol_gap: 1e-10,
            tol_feas: 1e-10,
            accept_almost_solved: false,
        }
    }
}

/// Problem data in Clarabel's form: min ½zᵀPz + qᵀz s.t. Az + s = b, s ∈ K.
pub struct ConicData {
    /// Upper triangle of P.
    pub p: CscMatrix<f64>,
    /// q.
    pub q: Vec<f64>,
    /// A.
    pub a: CscMatrix<f64>,
    /// b.
    pub b: Vec<f64>,
    /// Cones, in row order.
    pub cones: Vec<SupportedConeT<f64>>,
    /// The shift z_c: Clarabel's x is z − z_c.
    pub shift: Vec<f64>,
}

fn dense_to_csc(rows: usize, cols: usize, m: &[Vec<f64>], upper_only: bool) -> CscMatrix<f64> {
    let mut colptr = Vec::with_capacity(cols + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for j in 0..cols {
        for (i, row) in m.iter().enumerate().take(rows) {
            if upper_only && i > j {
                break;
            }
            let x = row[j];
            if x != 0.0 {
                rowval.push(i);
                nzval.push(x);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(rows, cols, colptr, rowval, nzval)
}

/// Row k of D (v = D z): z_k − z_{k−1}.
fn d_row(n: usize, k: usize) -> Vec<f64> {
    let mut r = vec![0.0; n];
    r[k] = 1.0;
    if k >= 1 {
        r[k - 1] = -1.0;
    }
    r
}

/// Row k of D2 (Δv = D2 z − v_prev e_0): z_k − 2 z_{k−1} + z_{k−2}.
fn d2_row(n: usize, k: usize) -> Vec<f64> {
    let mut r = vec![0.0; n];
    r[k] = 1.0;
    if k >= 1 {
        r[k - 1] = -2.0;
    }
    if k >= 2 {
        r[k - 2] = 1.0;
    }
    r
}

/// The cost of (10) in z as dense (P, q): a sum of weighted squares.
fn cost<const N: usize>(pr: &SingleLaneProblem<f64, N>) -> (Vec<Vec<f64>>, Vec<f64>) {
    let (n, w) = (N, pr.weights);
    let mut p = vec![vec![0.0; n]; n];
    let mut q = vec![0.0; n];
    let mut add_sq = |row: &[f64], target: f64, weight: f64| {
        // weight (rowᵀz − target)² → P += 2w row rowᵀ, q += −2w target row.
        for i in 0..n {
            q[i] -= 2.0 * weight * target * row[i];
            for j in 0..n {
                p[i][j] += 2.0 * weight * row[i] * row[j];
            }
        }
    };
    let mut last = vec![0.0; n];
    last[n - 1] = pr.h;
    add_sq(&last, pr.target, w.target_position);
    for k in 0..n {
        add_sq(&d_row(n, k), pr.v_ref, w.reference_speed);
        let first = if k == 0 { pr.v_prev } else { 0.0 };
        add_sq(&d2_row(n, k), first, w.smoothness);
    }
    (p, q)
}

/// The constraints of (10) as dense rows A z ≤ b (the nonnegative cone's 4N rows: speed
/// and acceleration bounds), then N second-order cones of 3 rows (the safety constraint).
fn constraints<const N: usize>(pr: &SingleLaneProblem<f64, N>) -> (Vec<Vec<f64>>, Vec<f64>) {
    let n = N;
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let neg = |r: Vec<f64>| r.into_iter().map(|x| -x).collect::<Vec<_>>();
    for k in 0..n {
        let first = if k == 0 { pr.v_prev } else { 0.0 };
        a.push(d_row(n, k));
        b.push(pr.hi[k]);
        a.push(neg(d_row(n, k)));
        b.push(-pr.lo[k]);
        a.push(d2_row(n, k));
        b.push(pr.dv_max + first);
        a.push(neg(d2_row(n, k)));
        b.push(-pr.dv_min - first);
    }
    let bb = pr.brake;
    let c0 = pr.gap - 0.5 * bb * pr.h * pr.h;
    for k in 0..n {
        let mut t_row = vec![0.0; n];
        t_row[k] = 2.0 * pr.h;
        if k >= 1 {
            t_row[k - 1] = -pr.h;
        }
        a.push(t_row.clone());
        b.push(c0 + 2.0 * bb);
        let mut v_row = vec![0.0; n];
        v_row[k] = -2.0;
        if k >= 1 {
            v_row[k - 1] = 2.0;
        }
        a.push(v_row);
        b.push(0.0);
        a.push(t_row);
        b.push(c0 - 2.0 * bb);
    }
    (a, b)
}

/// Builds the conic form of `pr`.
pub fn conic_data<const N: usize>(pr: &SingleLaneProblem<f64, N>) -> ConicData {
    let n = N;
    let (p, mut q) = cost(pr);
    let (a, mut b) = constraints(pr);
    let mut cones = vec![SupportedConeT::NonnegativeConeT(4 * n)];
    cones.extend((0..n).map(|_| SupportedConeT::SecondOrderConeT(3)));
    // Shift to δ = z − z_c: q' = q + P z_c, b' = b − A z_c.
    let mut shift = vec![0.0; n];
    let mut acc = 0.0;
    let mut v = pr.v_prev;
    for zc in shift.iter_mut() {
        v = (v + pr.dv_min).max(0.0);
        acc += v;
        *zc = acc;
    }
    for i in 0..n {
        q[i] += (0..n).map(|j| p[i][j] * shift[j]).sum::<f64>();
    }
    for (row, bi) in a.iter().zip(b.iter_mut()) {
        *bi -= row
            .iter()
            .zip(shift.iter())
            .map(|(x, y)| x * y)
            .sum::<f64>();
    }
    ConicData {
        p: dense_to_csc(n, n, &p, true),
        q,
        a: dense_to_csc(a.len(), n, &a, false),
        b,
        cones,
        shift,
    }
}

impl ClarabelSolver {
    /// Solves pre-built conic data (so that timing can exclude our matrix building).
    pub fn solve_conic<const N: usize>(
        &self,
        pr: &SingleLaneProblem<f64, N>,
        data: &ConicData,
    ) -> Result<Solution<f64, N>, SolveError> {
        // Clarabel's floor is near 1e-10 on these problems: where it stops there short
        // ("AlmostSolved", typically with the optimum already right to 12 digits), retry
        // without equilibration, then at 10× the tolerance. The first certified
        // ("Solved") answer is the reference.
        let mut last = SolverStatus::Unsolved;
        let mut iterations = 0;
        let mut almost: Option<Vec<f64>> = None;
        let ladder = [(1.0, true), (1.0, false), (10.0, true), (10.0, false)];
        for (factor, equilibrate) in ladder {
            let settings = DefaultSettings {
                verbose: false,
                tol_gap_abs: self.tol_gap * factor,
                tol_gap_rel: self.tol_gap * factor,
                tol_feas: self.tol_feas * factor,
                max_iter: 200,
                equilibrate_enable: equilibrate,
                ..DefaultSettings::default()
            };
            let mut solver =
                DefaultSolver::new(&data.p, &data.q, &data.a, &data.b, &data.cones, settings)
                    .map_err(|_| SolveError::Numerical { iteration: 0 })?;
            solver.solve();
            let sol = &solver.solution;
            iterations += sol.iterations;
            last = sol.status;
            if sol.status == SolverStatus::Solved {
                return Ok(self.unshift(pr, data, &sol.x, iterations));
            }
            if sol.status == SolverStatus::AlmostSolved && almost.is_none() {
                almost = Some(sol.x.clone());
            }
        }
        if let (true, Some(x)) = (self.accept_almost_solved, almost.as_ref()) {
            return Ok(self.unshift(pr, data, x, iterations));
        }
        if std::env::var_os("CLARABEL_DEBUG").is_some() {
            eprintln!("clarabel status {last:?} after {iterations} iterations: {pr:?}");
        }
        Err(match last {
            SolverStatus::MaxIterations => SolveError::IterationLimit { iterations },
            _ => SolveError::Numerical {
                iteration: iterations,
            },
        })
    }

    fn unshift<const N: usize>(
        &self,
        pr: &SingleLaneProblem<f64, N>,
        data: &ConicData,
        x: &[f64],
        iterations: u32,
    ) -> Solution<f64, N> {
        let mut v = [0.0; N];
        let mut prev = 0.0;
        for ((vk, &dk), &zc) in v.iter_mut().zip(x.iter()).zip(data.shift.iter()) {
            let zk = dk + zc;
            *vk = zk - prev;
            prev = zk;
        }
        Solution {
            v,
            objective: pr.objective(&v),
            iterations,
            // Clarabel is an interior-point solver too.
            method: Method::InteriorPoint,
        }
    }
}

/// Clarabel kept resident across problems of one shape, as a user would run it in a
/// receding horizon: built once (setup, equilibration, the KKT system's symbolic
/// factorisation), then each new problem overwrites P, q, A and b in place (`update_P`,
/// `update_q`, `update_A`, `update_b`, which Clarabel 0.11 allows only with presolve off
/// and structural zeros kept) and is solved. Clarabel does not warm-start its iterates,
/// so what persists is the setup and the factorisation's structure; the equilibration
/// computed for the first problem scales the later ones.
pub struct PersistentClarabel {
    solver: Option<DefaultSolver<f64>>,
    settings: DefaultSettings<f64>,
    /// The nonzeros of P and A the resident solver holds: a receding horizon changes
    /// only q and b (P and A depend on h and the weights alone), and an update of what
    /// did not change would be time a user would not spend.
    held: (Vec<f64>, Vec<f64>),
}

impl PersistentClarabel {
    /// A resident solver with the duality-gap and feasibility tolerance `tol` (one try:
    /// no retry ladder, so that what is timed is one solve).
    pub fn new(tol: f64) -> Self {
        Self {
            solver: None,
            settings: DefaultSettings {
                verbose: false,
                tol_gap_abs: tol,
                tol_gap_rel: tol,
                tol_feas: tol,
                max_iter: 200,
                presolve_enable: false,
                input_sparse_dropzeros: false,
                ..DefaultSettings::default()
            },
            held: (Vec::new(), Vec::new()),
        }
    }

    /// Makes the resident solver hold `data`: in place when its shape matches the
    /// resident one (returns `true`), else by building a new solver (`false`).
    pub fn load(&mut self, data: &ConicData) -> Result<bool, SolveError> {
        if let Some(s) = self.solver.as_mut() {
            let same_p = self.held.0 == data.p.nzval;
            let same_a = self.held.1 == data.a.nzval;
            if (same_p || s.update_P(&data.p).is_ok())
                && (same_a || s.update_A(&data.a).is_ok())
                && s.update_q(&data.q).is_ok()
                && s.update_b(&data.b).is_ok()
            {
                if !same_p {
                    self.held.0.clone_from(&data.p.nzval);
                }
                if !same_a {
                    self.held.1.clone_from(&data.a.nzval);
                }
                return Ok(true);
            }
        }
        let s = DefaultSolver::new(
            &data.p,
            &data.q,
            &data.a,
            &data.b,
            &data.cones,
            self.settings.clone(),
        )
        .map_err(|_| SolveError::Numerical { iteration: 0 })?;
        self.solver = Some(s);
        self.held = (data.p.nzval.clone(), data.a.nzval.clone());
        Ok(false)
    }

    /// Solves what [`load`](Self::load) put in place; only a certified ("Solved")
    /// answer counts.
    pub fn solve_loaded<const N: usize>(
        &mut self,
        pr: &SingleLaneProblem<f64, N>,
        data: &ConicData,
    ) -> Result<Solution<f64, N>, SolveError> {
        let s = self
            .solver
            .as_mut()
            .ok_or(SolveError::Numerical { iteration: 0 })?;
        s.solve();
        let sol = &s.solution;
        match sol.status {
            SolverStatus::Solved => {
                Ok(ClarabelSolver::default().unshift(pr, data, &sol.x, sol.iterations))
            }
            SolverStatus::MaxIterations => Err(SolveError::IterationLimit {
                iterations: sol.iterations,
            }),
            _ => Err(SolveError::Numerical {
                iteration: sol.iterations,
            }),
        }
    }
}

impl<const N: usize> MpcSolver<f64, N> for ClarabelSolver {
    fn solve(
        &mut self,
        problem: &SingleLaneProblem<f64, N>,
        _warm_start: Option<&[f64; N]>,
    ) -> Result<Solution<f64, N>, SolveError> {
        let data = conic_data(problem);
        self.solve_conic(problem, &data)
    }
}
