//! The lateral part of the lane-change MPC (13), linearised, and the small dense
//! interior-point solver that solves it.
//!
//! (13) couples speed and steering through the unicycle (1). We solve it in two stages
//! per step, the longitudinal one exactly convex (the speed problem of [`crate::mpc`]
//! with dH, see [`crate::lane_change`]) and, given those speeds, this lateral QP in the
//! yaw rates ω: the dynamics are linearised about the previous plan (one SQP iteration
//! per control step, i.e. a real-time iteration), with
//! - θ_{k+1} = θ_k + h ω_k (exact: linear already),
//! - y_{k+1} = y_k + v_k h sin(θ_k + ω_k h/2) (chord form of (1), sinc ≈ 1), linearised
//!   about the nominal heading.
//!
//! ω is blocked into [`BLOCKS`] piecewise-constant pieces over the horizon (move
//! blocking keeps the QP at 4 variables whatever N is); θ bounds and the band are
//! imposed at [`CHECKS`] points. Nothing here is trusted for safety: the planner
//! simulates the result on the exact model and verifies every constraint of (13).
//!
//! Constraints: ω_k ∈ Ω^k_t (31); θmin ≤ θ_{k+1} ≤ θmax; and the vehicle's rectangle in
//! the band, conservatively linear: y ± (W/2 + (L/2)|θ|) within [y̲, ȳ], using
//! (L/2)|sin θ| + (W/2) cos θ ≤ W/2 + (L/2)|θ| and |θ| = max(θ, −θ).

// Dense linear algebra on fixed-size arrays: every index below runs over the array's own
// const length (BLOCKS, ROWS, CHECKS, N) or is proven in range where it is formed
// (2b+1 < 2·BLOCKS, 2·BLOCKS + 6c + 5 < ROWS), so none can panic; iterator forms of the
// triangular solves would obscure that more than they would check it.
#![allow(clippy::indexing_slicing, clippy::needless_range_loop)]

use crate::real::Real;

/// Piecewise-constant pieces of ω over the horizon (the QP's variables).
pub const BLOCKS: usize = 4;
/// Points of the horizon at which θ and the band are constrained.
pub const CHECKS: usize = 10;
/// Inequality rows: ω box (2 per block), θ (2 per check), band (4 per check).
pub const ROWS: usize = 2 * BLOCKS + 6 * CHECKS;
/// Iteration cap of the dense interior-point method.
pub const MAX_ITER: u32 = 50;

/// Why the lateral QP has no answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum LateralError {
    /// No convergence within [`MAX_ITER`] (e.g. the linearised band is infeasible).
    NotConverged,
    /// A non-finite number appeared.
    NotFinite,
    /// The reduced Newton matrix lost positive definiteness.
    Singular,
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for LateralError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotConverged => f.write_str("no convergence within MAX_ITER iterations"),
            Self::NotFinite => f.write_str("a non-finite number appeared"),
            Self::Singular => f.write_str("the reduced Newton matrix lost positive definiteness"),
        }
    }
}

impl core::error::Error for LateralError {}

/// Weights of the lateral cost, per step of the horizon.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LateralWeights<F> {
    /// (y_{k+1} − y_ref)² (1/m²).
    pub position: F,
    /// (θ_{k+1} − θ_ref)² (1/rad²).
    pub heading: F,
    /// ω_k² (s²/rad²), > 0 (keeps the QP strictly convex).
    pub rate: F,
    /// (u_b − u_{b−1})² between blocks, u_{−1} = ω_{t−h} (s²/rad²).
    pub rate_change: F,
}

impl<F: Real> Default for LateralWeights<F> {
    fn default() -> Self {
        Self {
            position: F::ONE,
            heading: F::from_f64(100.0),
            rate: F::from_f64(0.5),
            rate_change: F::from_f64(2.0),
        }
    }
}

/// A dense QP min ½ uᵀPu + qᵀu s.t. G u ≤ g with [`BLOCKS`] variables and [`ROWS`] rows.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseQp<F> {
    /// P (symmetric positive definite).
    pub p: [[F; BLOCKS]; BLOCKS],
    /// q.
    pub q: [F; BLOCKS],
    /// G.
    pub g_mat: [[F; BLOCKS]; ROWS],
    /// g.
    pub g: [F; ROWS],
}

/// Relative tolerance of the dense solver (residuals and complementarity).
fn tol<F: Real>() -> F {
    F::SOLVER_TOL * F::from_f64(10.0)
}

fn dot<F: Real>(a: &[F; BLOCKS], b: &[F; BLOCKS]) -> F {
    a.iter()
        .zip(b.iter())
        .fold(F::ZERO, |acc, (x, y)| acc + *x * *y)
}

/// Solves `m x = b` in place by Cholesky; `m` is overwritten.
fn cholesky_solve<F: Real>(
    m: &mut [[F; BLOCKS]; BLOCKS],
    b: &mut [F; BLOCKS],
) -> Result<(), LateralError> {
    for j in 0..BLOCKS {
        let mut d = m[j][j];
        for k in 0..j {
            d -= m[j][k] * m[j][k];
        }
        if !(d > F::EPSILON) {
            return Err(LateralError::Singular);
        }
        let d = d.sqrt();
        m[j][j] = d;
        for i in (j + 1)..BLOCKS {
            let mut s = m[i][j];
            for k in 0..j {
                s -= m[i][k] * m[j][k];
            }
            m[i][j] = s / d;
        }
    }
    for i in 0..BLOCKS {
        let mut s = b[i];
        for k in 0..i {
            s -= m[i][k] * b[k];
        }
        b[i] = s / m[i][i];
    }
    for i in (0..BLOCKS).rev() {
        let mut s = b[i];
        for k in (i + 1)..BLOCKS {
            s -= m[k][i] * b[k];
        }
        b[i] = s / m[i][i];
    }
    Ok(())
}

/// The working vectors of [`DenseQp::solve_with`] (~1.9 KB in `f32`), apart from the
/// QP so that a planner can keep both in its own storage rather than on the stack.
#[derive(Debug, Clone, PartialEq)]
pub struct IpmWork<F> {
    s: [F; ROWS],
    lam: [F; ROWS],
    rp: [F; ROWS],
    d: [F; ROWS],
    rc: [F; ROWS],
    ds: [F; ROWS],
    dl: [F; ROWS],
}

impl<F: Real> IpmWork<F> {
    /// Zeroed vectors (every solve overwrites them before reading).
    pub const fn new() -> Self {
        let z = [F::ZERO; ROWS];
        Self {
            s: z,
            lam: z,
            rp: z,
            d: z,
            rc: z,
            ds: z,
            dl: z,
        }
    }
}

impl<F: Real> Default for IpmWork<F> {
    fn default() -> Self {
        Self::new()
    }
}

impl<F: Real> DenseQp<F> {
    /// A QP of zeros (its builder fills every entry).
    pub const fn zeros() -> Self {
        Self {
            p: [[F::ZERO; BLOCKS]; BLOCKS],
            q: [F::ZERO; BLOCKS],
            g_mat: [[F::ZERO; BLOCKS]; ROWS],
            g: [F::ZERO; ROWS],
        }
    }

    /// Zeroes every entry in place (the builder then adds into them).
    fn clear(&mut self) {
        self.p = [[F::ZERO; BLOCKS]; BLOCKS];
        self.q = [F::ZERO; BLOCKS];
        for row in self.g_mat.iter_mut() {
            *row = [F::ZERO; BLOCKS];
        }
        self.g.fill(F::ZERO);
    }

    /// [`DenseQp::solve_with`] with its working vectors on the stack.
    pub fn solve(&self) -> Result<([F; BLOCKS], u32), LateralError> {
        self.solve_with(&mut IpmWork::new())
    }

    /// Mehrotra predictor–corrector interior-point method; at most [`MAX_ITER`]
    /// iterations, in the working vectors `w` (their contents on entry do not matter).
    /// Returns the minimiser and the iterations used.
    ///
    /// The predictor's directions are overwritten by the corrector's once they have gone
    /// into its right-hand side, so one set of them is kept.
    pub fn solve_with(&self, w: &mut IpmWork<F>) -> Result<([F; BLOCKS], u32), LateralError> {
        let IpmWork {
            s,
            lam,
            rp,
            d,
            rc,
            ds,
            dl,
        } = w;
        let mut u = [F::ZERO; BLOCKS];
        lam.fill(F::ONE);
        for i in 0..ROWS {
            let r = self.g[i] - dot(&self.g_mat[i], &u);
            s[i] = r.max(F::ONE);
        }
        let scale_g = self.g.iter().fold(F::ONE, |a, x| a.max(x.abs()));
        let scale_q = self.q.iter().fold(F::ONE, |a, x| a.max(x.abs()));
        let n = F::from_usize(ROWS);
        for it in 0..MAX_ITER {
            // Residuals.
            let mut rd = self.q;
            for (i, row) in self.p.iter().enumerate() {
                rd[i] += dot(row, &u);
            }
            for r in 0..ROWS {
                for i in 0..BLOCKS {
                    rd[i] += self.g_mat[r][i] * lam[r];
                }
            }
            let mut mu = F::ZERO;
            for r in 0..ROWS {
                rp[r] = dot(&self.g_mat[r], &u) + s[r] - self.g[r];
                mu += s[r] * lam[r];
            }
            mu = mu / n;
            let rp_max = rp.iter().fold(F::ZERO, |a, x| a.max(x.abs()));
            let rd_max = rd.iter().fold(F::ZERO, |a, x| a.max(x.abs()));
            if !(rp_max.is_finite() && rd_max.is_finite() && mu.is_finite()) {
                return Err(LateralError::NotFinite);
            }
            if rp_max <= tol::<F>() * scale_g && rd_max <= tol::<F>() * scale_q && mu <= tol::<F>()
            {
                return Ok((u, it));
            }
            // Reduced matrix K = P + Gᵀ D G, D = λ/s.
            let mut k = self.p;
            for r in 0..ROWS {
                d[r] = lam[r] / s[r];
                let row = &self.g_mat[r];
                for i in 0..BLOCKS {
                    for j in 0..BLOCKS {
                        k[i][j] += row[i] * d[r] * row[j];
                    }
                }
            }
            let newton = Newton {
                qp: self,
                k: &k,
                rd: &rd,
                rp,
                s,
                d,
            };
            // Predictor (affine scaling).
            for r in 0..ROWS {
                rc[r] = -s[r] * lam[r];
            }
            newton.direction(rc, ds, dl)?;
            let a_aff = step_to_boundary(s, lam, ds, dl);
            let mut mu_aff = F::ZERO;
            for r in 0..ROWS {
                mu_aff += (s[r] + a_aff * ds[r]) * (lam[r] + a_aff * dl[r]);
            }
            mu_aff = mu_aff / n;
            let sigma = {
                let ratio = mu_aff / mu;
                ratio * ratio * ratio
            };
            // Corrector (its directions replace the predictor's).
            for r in 0..ROWS {
                rc[r] = -s[r] * lam[r] + sigma * mu - ds[r] * dl[r];
            }
            let du = newton.direction(rc, ds, dl)?;
            let a = (step_to_boundary(s, lam, ds, dl) * F::from_f64(0.99)).min(F::ONE);
            for i in 0..BLOCKS {
                u[i] += a * du[i];
            }
            for r in 0..ROWS {
                s[r] += a * ds[r];
                lam[r] += a * dl[r];
            }
        }
        Err(LateralError::NotConverged)
    }
}

/// One iteration's Newton system of [`DenseQp::solve`], borrowed.
struct Newton<'a, F> {
    qp: &'a DenseQp<F>,
    /// The reduced matrix P + Gᵀ D G.
    k: &'a [[F; BLOCKS]; BLOCKS],
    rd: &'a [F; BLOCKS],
    rp: &'a [F; ROWS],
    s: &'a [F; ROWS],
    d: &'a [F; ROWS],
}

impl<F: Real> Newton<'_, F> {
    /// (P + GᵀDG) du = −r_d − Gᵀ(r_c/s + D r_p); ds, dλ into `ds`, `dl`; returns du.
    fn direction(
        &self,
        rc: &[F; ROWS],
        ds: &mut [F; ROWS],
        dl: &mut [F; ROWS],
    ) -> Result<[F; BLOCKS], LateralError> {
        let (g_mat, s, d, rp) = (&self.qp.g_mat, self.s, self.d, self.rp);
        let mut rhs = self.rd.map(|x| -x);
        for r in 0..ROWS {
            let w = rc[r] / s[r] + d[r] * rp[r];
            for i in 0..BLOCKS {
                rhs[i] -= g_mat[r][i] * w;
            }
        }
        let mut m = *self.k;
        cholesky_solve(&mut m, &mut rhs)?;
        let du = rhs;
        for r in 0..ROWS {
            ds[r] = -rp[r] - dot(&g_mat[r], &du);
            dl[r] = rc[r] / s[r] - d[r] * ds[r];
        }
        Ok(du)
    }
}

/// The largest step α ≤ 1 keeping s + α ds ≥ 0 and λ + α dλ ≥ 0.
fn step_to_boundary<F: Real>(s: &[F; ROWS], lam: &[F; ROWS], ds: &[F; ROWS], dl: &[F; ROWS]) -> F {
    let mut a = F::ONE;
    for r in 0..ROWS {
        if ds[r] < F::ZERO {
            a = a.min(-s[r] / ds[r]);
        }
        if dl[r] < F::ZERO {
            a = a.min(-lam[r] / dl[r]);
        }
    }
    a
}

/// Which block step k of an N-step horizon belongs to.
#[inline]
pub fn block_of(k: usize, n: usize) -> usize {
    (k * BLOCKS).checked_div(n).unwrap_or(0).min(BLOCKS - 1)
}

/// The steps at which θ and the band are constrained (spread evenly, last one at N−1).
#[inline]
pub fn check_step(i: usize, n: usize) -> usize {
    ((i + 1) * n / CHECKS).max(1) - 1
}

/// Everything the lateral QP is built from.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LateralInput<'a, F, const N: usize> {
    /// h (s).
    pub h: F,
    /// y_t (m).
    pub y: F,
    /// θ_t (rad).
    pub theta: F,
    /// ω_{t−h} (rad/s).
    pub omega_prev: F,
    /// The planned speeds v_k.
    pub v: &'a [F; N],
    /// The nominal yaw rates to linearise about (the previous plan, shifted).
    pub omega_nominal: &'a [F; N],
    /// Reference y at step k+1.
    pub y_ref: &'a [F; N],
    /// Reference θ at step k+1.
    pub theta_ref: &'a [F; N],
    /// Ω^k_t lower ends.
    pub omega_lo: &'a [F; N],
    /// Ω^k_t upper ends.
    pub omega_hi: &'a [F; N],
    /// θ bounds, tightened.
    pub theta_bounds: (F, F),
    /// Band edges the rectangle must stay within (lane edges, tightened).
    pub band: (F, F),
    /// L/2 and W/2 (m).
    pub half_length: F,
    /// W/2 (m).
    pub half_width: F,
    /// Weights.
    pub weights: LateralWeights<F>,
}

/// The lateral QP and its solver's working vectors: ~3.3 KB in `f32`, which a
/// [`crate::LanePlanner`] keeps in its own storage so that a lane-change step does not
/// need them on the stack (on the Cortex-M4F).
#[derive(Debug, Clone, PartialEq)]
pub struct LateralWork<F> {
    qp: DenseQp<F>,
    ipm: IpmWork<F>,
}

impl<F: Real> LateralWork<F> {
    /// Zeroed storage (every solve rebuilds the QP and overwrites the vectors).
    pub const fn new() -> Self {
        Self {
            qp: DenseQp::zeros(),
            ipm: IpmWork::new(),
        }
    }
}

impl<F: Real> LateralWork<F> {
    /// Zeroes the storage in place (what [`LateralWork::new`] builds; no temporary).
    pub fn clear(&mut self) {
        let LateralWork { qp, ipm } = self;
        qp.clear();
        for a in [
            &mut ipm.s,
            &mut ipm.lam,
            &mut ipm.rp,
            &mut ipm.d,
            &mut ipm.rc,
            &mut ipm.ds,
            &mut ipm.dl,
        ] {
            a.fill(F::ZERO);
        }
    }
}

impl<F: Real> Default for LateralWork<F> {
    fn default() -> Self {
        Self::new()
    }
}

/// Builds the lateral QP and solves it; returns ω_0..ω_{N−1} and the iterations used.
/// Its working storage is on the stack: [`solve_lateral_in`] takes a caller's.
pub fn solve_lateral<F: Real, const N: usize>(
    inp: &LateralInput<'_, F, N>,
) -> Result<([F; N], u32), LateralError> {
    solve_lateral_in(&mut LateralWork::new(), inp)
}

/// [`solve_lateral`] in the working storage `work` (its contents on entry do not matter).
pub fn solve_lateral_in<F: Real, const N: usize>(
    work: &mut LateralWork<F>,
    inp: &LateralInput<'_, F, N>,
) -> Result<([F; N], u32), LateralError> {
    if N == 0 {
        return Ok(([F::ZERO; N], 0));
    }
    let LateralWork { qp, ipm } = work;
    // Cleared in place, field by field (no QP-sized temporary); `ipm` is overwritten.
    qp.clear();
    let maps = tracking_terms(qp, inp);
    rate_terms_and_bounds(qp, inp, &maps);
    check_constraints(qp, inp, &maps);
    let (u, iters) = qp.solve_with(ipm)?;
    let mut omega = [F::ZERO; N];
    for (k, o) in omega.iter_mut().enumerate() {
        *o = u[block_of(k, N)];
    }
    Ok((omega, iters))
}

/// What the linearised dynamics give the constraints: the affine maps of θ and y at each
/// checked step, and per block the ω bounds and the number of steps it covers.
struct Maps<F> {
    theta: [[F; BLOCKS]; CHECKS],
    y: [[F; BLOCKS]; CHECKS],
    y_const: [F; CHECKS],
    lo: [F; BLOCKS],
    hi: [F; BLOCKS],
    count: [F; BLOCKS],
}

/// weight (a·u + c)² added to the cost: P += 2w a aᵀ, q += 2w c a.
fn add_square<F: Real>(qp: &mut DenseQp<F>, a: &[F; BLOCKS], c: F, weight: F) {
    for i in 0..BLOCKS {
        for j in 0..BLOCKS {
            qp.p[i][j] += F::TWO * weight * a[i] * a[j];
        }
        qp.q[i] += F::TWO * weight * c * a[i];
    }
}

/// The dynamics linearised step by step along the nominal ω, the position and heading
/// tracking terms of the cost, and the maps the constraints need.
fn tracking_terms<F: Real, const N: usize>(
    qp: &mut DenseQp<F>,
    inp: &LateralInput<'_, F, N>,
) -> Maps<F> {
    let h = inp.h;
    let w = inp.weights;
    let per_step = F::ONE / F::from_usize(N);
    // Affine maps θ_{k+1} = cθ·u + θ0, y_{k+1} = cy·u + y_c, built step by step.
    let mut c_theta = [F::ZERO; BLOCKS];
    let mut c_y = [F::ZERO; BLOCKS];
    let mut y_c = inp.y;
    let mut theta_nom = inp.theta;
    let mut maps = Maps {
        theta: [[F::ZERO; BLOCKS]; CHECKS],
        y: [[F::ZERO; BLOCKS]; CHECKS],
        y_const: [F::ZERO; CHECKS],
        lo: [F::from_f64(-1e9); BLOCKS],
        hi: [F::from_f64(1e9); BLOCKS],
        count: [F::ZERO; BLOCKS],
    };
    let mut next_check = 0usize;
    for k in 0..N {
        let b = block_of(k, N);
        let omega_nom = inp.omega_nominal[k];
        let phi_nom = theta_nom + F::HALF * h * omega_nom;
        let (sn, cs) = (phi_nom.sin(), phi_nom.cos());
        let vh = inp.v[k] * h;
        // φ_k = θ_k + (h/2) u_b; y_{k+1} = y_k + vh (sin φ̂ + cos φ̂ (φ − φ̂)).
        let mut c_phi = c_theta;
        c_phi[b] += F::HALF * h;
        for i in 0..BLOCKS {
            c_y[i] += vh * cs * c_phi[i];
        }
        y_c += vh * (sn + cs * (inp.theta - phi_nom));
        c_theta[b] += h;
        theta_nom += h * omega_nom;
        maps.lo[b] = maps.lo[b].max(inp.omega_lo[k]);
        maps.hi[b] = maps.hi[b].min(inp.omega_hi[k]);
        maps.count[b] += F::ONE;
        add_square(qp, &c_y, y_c - inp.y_ref[k], w.position * per_step);
        add_square(
            qp,
            &c_theta,
            inp.theta - inp.theta_ref[k],
            w.heading * per_step,
        );
        while next_check < CHECKS && check_step(next_check, N) == k {
            maps.theta[next_check] = c_theta;
            maps.y[next_check] = c_y;
            maps.y_const[next_check] = y_c;
            next_check += 1;
        }
    }
    maps
}

/// Per block: the rate and rate-change terms of the cost, and the bounds on ω.
fn rate_terms_and_bounds<F: Real, const N: usize>(
    qp: &mut DenseQp<F>,
    inp: &LateralInput<'_, F, N>,
    maps: &Maps<F>,
) {
    let w = inp.weights;
    let per_step = F::ONE / F::from_usize(N);
    for b in 0..BLOCKS {
        let mut e = [F::ZERO; BLOCKS];
        e[b] = F::ONE;
        // Σ_k ω_k² over the block.
        add_square(
            qp,
            &e,
            F::ZERO,
            w.rate * per_step * maps.count[b].max(F::ONE),
        );
        let mut d = e;
        let c = if b == 0 {
            -inp.omega_prev
        } else {
            d[b - 1] = -F::ONE;
            F::ZERO
        };
        add_square(qp, &d, c, w.rate_change);
        // Empty Ω (rounding) or unused block: pin to the middle, with a sliver of room.
        let (lo, hi) = if maps.hi[b] >= maps.lo[b] {
            (maps.lo[b], maps.hi[b])
        } else {
            let m = F::HALF * (maps.lo[b] + maps.hi[b]);
            (m, m)
        };
        let room = F::from_f64(1e-9);
        qp.g_mat[2 * b] = e;
        qp.g[2 * b] = hi + room;
        qp.g_mat[2 * b + 1] = e.map(|x| -x);
        qp.g[2 * b + 1] = -lo + room;
    }
}

/// At each checked step: the heading bounds and the four corners inside the band.
fn check_constraints<F: Real, const N: usize>(
    qp: &mut DenseQp<F>,
    inp: &LateralInput<'_, F, N>,
    maps: &Maps<F>,
) {
    let (tmin, tmax) = inp.theta_bounds;
    let (ylo, yhi) = inp.band;
    let (hl, hw) = (inp.half_length, inp.half_width);
    for c in 0..CHECKS {
        let base = 2 * BLOCKS + 6 * c;
        let at = maps.theta[c];
        let ay = maps.y[c];
        let cy = maps.y_const[c];
        let th0 = inp.theta;
        let neg = |a: [F; BLOCKS]| a.map(|x| -x);
        let comb = |s: F| {
            let mut r = ay;
            for i in 0..BLOCKS {
                r[i] += s * hl * at[i];
            }
            r
        };
        // θ ≤ θmax, −θ ≤ −θmin.
        qp.g_mat[base] = at;
        qp.g[base] = tmax - th0;
        qp.g_mat[base + 1] = neg(at);
        qp.g[base + 1] = th0 - tmin;
        // y ± (L/2)θ + W/2 ≤ ȳ.
        qp.g_mat[base + 2] = comb(F::ONE);
        qp.g[base + 2] = yhi - hw - cy - hl * th0;
        qp.g_mat[base + 3] = comb(-F::ONE);
        qp.g[base + 3] = yhi - hw - cy + hl * th0;
        // y ± (L/2)θ − W/2 ≥ y̲.
        qp.g_mat[base + 4] = neg(comb(F::ONE));
        qp.g[base + 4] = -(ylo + hw) + cy + hl * th0;
        qp.g_mat[base + 5] = neg(comb(-F::ONE));
        qp.g[base + 5] = -(ylo + hw) + cy - hl * th0;
    }
}
