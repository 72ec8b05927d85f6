//! The active-set step: a warm start's answer in two or three Newton solves.
//!
//! # Why
//! In a receding horizon the constraints that bind at the optimum change little from one
//! step to the next: a follower's optimum rides the upper edge of V^k_t, the safety
//! constraints or the acceleration limit at the same indices as one step earlier, shifted
//! by one. The interior-point method cannot use that knowledge: its iterates must stay
//! strictly inside, so a warm start is pulled off the boundary (slacks floored at
//! [`Settings::warm_barrier`]) and needs 3–10 predictor-corrector iterations — two
//! pentadiagonal solves each — to return to it. That was the planner's whole cost in a
//! platoon (~8 iterations per follower step).
//!
//! Here the previous step's multipliers, shifted, name the constraints that bind, and the
//! KKT system of (10) with those held as equalities is solved by Newton's method: a
//! semismooth Newton, or primal-dual active-set, iteration (Hintermüller, Ito & Kunisch,
//! SIAM J. Optim. 13(3), 2003). With the right set, the linear constraints are met after
//! one step and the quadratic safety constraints converge quadratically: 2–3 steps of one
//! solve each. The set is corrected between steps by three rules:
//!
//! 1. *Drop*: a held constraint whose multiplier turned negative is released.
//! 2. *Swap*: where a released constraint is violated beyond the primal tolerance, the
//!    most violated one at that step k is held and the held constraints at k that bound
//!    v_k from the same side are released (their multiplier carried over). Why: each
//!    family's constraint k bounds v_k given the earlier speeds — v ≤ hi, the
//!    acceleration limit and the safety constraint from above, v ≥ lo and the
//!    deceleration limit from below — so a second bound of the same side at k
//!    over-determines v_k. Plain PDAS holds it anyway, and the regularised system answers
//!    an inconsistent set with multipliers of order ρ × inconsistency that flip signs
//!    everywhere (measured: the braking tail of the firmware's N = 50 lane change, where
//!    consecutive safety constraints and the deceleration limit are nearly one
//!    constraint, cycled to the cap in 11 of 254 steps; with the swap, in 1).
//! 3. *Redundant bounds are never held*: where hi_k ≥ v_{t−h} + (k+1) amax h the bound
//!    v_k ≤ hi_k is implied by the acceleration limits (and lo_k ≤ v_{t−h} + (k+1) amin h
//!    by the deceleration limits), so holding both is degenerate; the chain of
//!    acceleration limits carries the multiplier instead (D1_k = Σ_{j≤k} D2_j).
//!
//! # The Newton system, still pentadiagonal
//! With C the gradients of the held constraints, the step solves
//! [H_L  Cᵀ; C  −ρ⁻¹I] [Δz; Δλ] = −[r_d; g_A], H_L = ∇²J + Σ λ_i ∇²g_i. Eliminating
//! Δλ = ρ (C Δz + g_A) leaves (H_L + ρ CᵀC) Δz = −r_d − ρ Cᵀ g_A: the interior-point
//! method's Newton matrix with the weights λ_i/s_i replaced by ρ on the held set and 0
//! off it, so the same O(N) assembly and LDLᵀ serve. The −ρ⁻¹I term keeps the system
//! definite when held gradients are dependent and makes each step a method-of-multipliers
//! update whose fixed point has Δλ = 0, i.e. C Δz + g_A = 0 exactly
//! ([`Settings::active_set_penalty`], [`Real::ACTIVE_SET_PENALTY`] says how ρ was chosen).
//!
//! # When it gives up
//! Degenerate vertices where the optimum needs two bounds of one side at one step (a
//! kink: braking to a stop behind a stopped car, the horizon's end meeting a safety
//! constraint while accelerating) make the rules cycle. The step stops as soon as it sees
//! that — the held set repeats the one two steps earlier, or more than
//! [`MAX_CHANGES`] constraints change sides in one step — or at the cap
//! [`Settings::active_set_iter`], and the interior-point method takes over from the
//! step's last iterate (usually next to the optimum; its starting barrier adapts to how
//! far that point violates the constraints). After [`FAILS_BEFORE_BACKOFF`] failures in a
//! row the next [`BACKOFF`] warm starts go straight to the interior-point method: failures
//! come in runs (a vehicle braking to a stop behind a stopped one), successes in long
//! stretches (following, cruising, changing lanes).
//!
//! # Same answer, same guarantee
//! A plan is returned only when it passes the interior-point method's own stopping test —
//! primal residual, dual residual and complementarity within [`Settings::tol`] and
//! [`Settings::tol_dual`] — with every multiplier ≥ 0: a KKT point of the convex problem
//! (10), i.e. its optimum, to the same tolerances. The planner verifies every plan
//! against the exact constraints either way.

use super::{put, Family, IpmSolver, IterationInfo, Method, Settings, Solution, FAMILIES};
use crate::banded::get;
use crate::mpc::SingleLaneProblem;
use crate::real::Real;

/// Most constraints that may change sides in one step after the first: more means the
/// guess was far off (measured: a successful step changes 0–3 after its first; a step
/// braking to a stop behind a stopped car changed 20–50 and then cycled).
pub const MAX_CHANGES: u32 = 8;

/// Active-set failures in a row after which warm starts skip the step for a while.
pub const FAILS_BEFORE_BACKOFF: u8 = 2;

/// Warm starts that go straight to the interior-point method after
/// [`FAILS_BEFORE_BACKOFF`] failures in a row (measured on the firmware's approach to a
/// stopped car and bench-planner's stop-and-go drive: 4 cut the Newton steps of those
/// runs by 8–15 % against 0, and cost the lane change and the benchmark drive nothing,
/// whose failures come one at a time).
pub const BACKOFF: u8 = 4;

/// Family indices in [`IpmSolver`]'s order.
const UP: usize = 0;
const LO: usize = 1;

/// Whether each family bounds v_k from above (given the earlier speeds). It is also the
/// sign of the family's gradient on its stencil (+D1, −D1, +D2, −D2, +S): an upper bound
/// grows with v_k.
const UPPER: [bool; FAMILIES] = [true, false, true, false, true];

/// Constraint k of family `fam` is implied by the acceleration limits (rule 3 of the
/// module documentation).
fn redundant<F: Real, const N: usize>(pr: &SingleLaneProblem<F, N>, fam: usize, k: usize) -> bool {
    let steps = F::from_usize(k + 1);
    match fam {
        UP => get(&pr.hi, k) >= pr.v_prev + steps * pr.dv_max,
        LO => {
            let lo = get(&pr.lo, k);
            lo > F::ZERO && lo <= pr.v_prev + steps * pr.dv_min
        }
        _ => false,
    }
}

#[inline(always)]
fn held(a: &[bool], k: usize) -> bool {
    a.get(k).copied().unwrap_or(false)
}

#[inline(always)]
fn hold(a: &mut [bool], k: usize, on: bool) {
    if let Some(x) = a.get_mut(k) {
        *x = on;
    }
}

impl<F: Real, const N: usize> IpmSolver<F, N> {
    /// Whether this warm start tries the active-set step: it is on, the last solve left
    /// multipliers to guess the active set from, and no backoff is running (this call
    /// counts one warm start of it).
    pub(super) fn active_set_enabled(&mut self) -> bool {
        if self.skip > 0 {
            self.skip -= 1;
            return false;
        }
        self.settings.active_set_iter > 0 && self.have_duals
    }

    /// Tries the active-set step from `warm` with the previous solve's multipliers.
    /// When it gives up (module documentation) it returns the Newton steps it spent; the
    /// previous multipliers are then back in place and `v` holds where the
    /// interior-point method should start: the last iterate if it is finite, else `warm`.
    /// Why the last iterate: a failing step is mostly cycling between two active sets at
    /// a degenerate vertex, next to the optimum (measured on the firmware's N = 50 lane
    /// change in f32: its worst step fell from 6 + 9 to 6 + 2 Newton steps). `tol_p` is
    /// the primal tolerance the interior-point method uses.
    pub(super) fn active_set_solve(
        &mut self,
        pr: &SingleLaneProblem<F, N>,
        warm: &[F; N],
        tol_p: F,
        trace: &mut dyn FnMut(IterationInfo<F>),
    ) -> Result<Solution<F, N>, u32> {
        self.v = *warm;
        self.evaluate(pr);
        self.guess_active_set(pr);
        let spent = match self.active_set_iterate(pr, tol_p, trace) {
            Ok(sol) => {
                self.fails = 0;
                return Ok(sol);
            }
            Err(spent) => spent,
        };
        self.fails = self.fails.saturating_add(1);
        if self.fails >= FAILS_BEFORE_BACKOFF {
            self.skip = BACKOFF;
        }
        // The interior-point method warm-starts from the previous multipliers, which
        // `guess_active_set` kept in `dl`.
        for f in self.fam.iter_mut() {
            f.lam = f.dl;
        }
        if !self.v.iter().all(|x| x.is_finite()) {
            self.v = *warm;
        }
        Err(spent)
    }

    /// Keeps the previous multipliers in `dl` and puts them, shifted one step (the last
    /// repeated), in `lam`. A constraint is held where its shifted multiplier exceeds its
    /// slack at the warm start (the previous optimum's binding constraints, which the
    /// leader's motion may have loosened by its displacement), unless it is redundant;
    /// a redundant bound's multiplier moves onto the acceleration chain that implies it.
    fn guess_active_set(&mut self, pr: &SingleLaneProblem<F, N>) {
        let last = N.saturating_sub(1);
        for (i, f) in self.fam.iter_mut().enumerate() {
            f.dl = f.lam;
            for k in 0..N {
                let l = get(&f.dl, (k + 1).min(last));
                let binds = l > (-get(&f.g, k)).max(F::ZERO);
                let implied = redundant(pr, i, k);
                let on = binds && !implied;
                hold(&mut f.act, k, on);
                // A redundant bound's multiplier is kept, negated, in `ds` for the
                // transfer below (ds is free until the interior-point method runs).
                put(&mut f.ds, k, if binds && implied { -l } else { F::ZERO });
                put(&mut f.lam, k, if on { l } else { F::ZERO });
            }
        }
        let [up, lo, ac, de, _] = &mut self.fam;
        transfer(up, ac);
        transfer(lo, de);
    }

    /// The semismooth Newton iteration from the state `guess_active_set` left: the
    /// answer, or the Newton steps spent when it gives up.
    fn active_set_iterate(
        &mut self,
        pr: &SingleLaneProblem<F, N>,
        tol_p: F,
        trace: &mut dyn FnMut(IterationInfo<F>),
    ) -> Result<Solution<F, N>, u32> {
        let st = self.settings;
        let m = F::from_usize(FAMILIES * N);
        // Checksums of the held set one and two steps back, to see a 2-cycle.
        let (mut one_back, mut two_back) = (0u32, 0u32);
        // Under a deadline (`Settings::with_answer_at_cap`) these steps count toward it.
        let cap = if st.answer_at_cap() {
            st.active_set_iter.min(st.max_iter)
        } else {
            st.active_set_iter
        };
        for it in 0..cap {
            if it > 0 {
                self.evaluate(pr);
            }
            let changes = self.update_active_set(pr, tol_p);
            // An unchanged set keeps its checksum.
            let sum = if it == 0 || changes > 0 {
                self.held_checksum()
            } else {
                one_back
            };
            let cycling = it >= 2 && changes > 0 && sum == two_back;
            if (it > 0 && changes > MAX_CHANGES) || cycling {
                return Err(it);
            }
            (two_back, one_back) = (one_back, sum);
            let (max_rd, scale) = self.dual_residual(pr);
            let (max_rp, gap) = self.primal_and_gap();
            if !(max_rd.is_finite() && max_rp.is_finite() && gap.is_finite()) {
                return Err(it);
            }
            let mut info = IterationInfo {
                iteration: it,
                objective: F::ZERO,
                primal_residual: max_rp,
                dual_residual: max_rd,
                mu: gap / m,
                step: F::ONE,
                method: Method::ActiveSet,
            };
            if max_rp <= tol_p && max_rd <= st.tol_dual * scale {
                let obj = pr.objective(&self.v);
                if gap <= st.tol * (F::ONE + obj.abs()) {
                    info.objective = obj;
                    info.step = F::ZERO;
                    trace(info);
                    self.have_duals = true;
                    return Ok(Solution {
                        v: self.v,
                        objective: obj,
                        iterations: it,
                        method: Method::ActiveSet,
                    });
                }
            }
            trace(info);
            if self.newton_step(pr, &st).is_none() {
                return Err(it + 1);
            }
        }
        Err(cap)
    }

    /// A checksum of the held set (order-free: a sum of hashed indices), to recognise a
    /// set seen before.
    fn held_checksum(&self) -> u32 {
        let mut h = 0u32;
        for (i, f) in self.fam.iter().enumerate() {
            for (k, &a) in f.act.iter().enumerate() {
                if a {
                    h = h.wrapping_add(((i * N + k + 1) as u32).wrapping_mul(2_654_435_761));
                }
            }
        }
        h
    }

    /// Rules 1 and 2 of the module documentation, step by step; a released constraint is
    /// violated when it exceeds `threshold` (the primal tolerance, so that round-off does
    /// not toggle it). Returns the number of constraints that changed sides.
    fn update_active_set(&mut self, pr: &SingleLaneProblem<F, N>, threshold: F) -> u32 {
        // Most steps change nothing: one pass finds that without the per-step scan.
        let quiet = self.fam.iter().all(|f| {
            f.act
                .iter()
                .zip(f.lam.iter().zip(f.g.iter()))
                .all(|(&a, (&l, &g))| if a { !(l < F::ZERO) } else { !(g > threshold) })
        });
        if quiet {
            return 0;
        }
        let mut changes = 0;
        for k in 0..N {
            for f in self.fam.iter_mut() {
                if held(&f.act, k) && get(&f.lam, k) < F::ZERO {
                    hold(&mut f.act, k, false);
                    put(&mut f.lam, k, F::ZERO);
                    changes += 1;
                }
            }
            let mut worst: Option<(usize, F)> = None;
            for (i, f) in self.fam.iter().enumerate() {
                let g = get(&f.g, k);
                if !held(&f.act, k)
                    && g > threshold
                    && worst.is_none_or(|(_, w)| g > w)
                    && !redundant(pr, i, k)
                {
                    worst = Some((i, g));
                }
            }
            let Some((new, _)) = worst else { continue };
            let side = UPPER.get(new).copied().unwrap_or(true);
            let mut carried = F::ZERO;
            for (f, &upper) in self.fam.iter_mut().zip(UPPER.iter()) {
                if upper == side && held(&f.act, k) {
                    carried = carried.max(get(&f.lam, k));
                    hold(&mut f.act, k, false);
                    put(&mut f.lam, k, F::ZERO);
                    changes += 1;
                }
            }
            if let Some(f) = self.fam.get_mut(new) {
                hold(&mut f.act, k, true);
                put(&mut f.lam, k, carried);
                changes += 1;
            }
        }
        changes
    }

    /// The largest constraint violation max(g_i, 0) and the complementarity Σ s_i λ_i
    /// with slacks s_i = max(−g_i, 0) (multipliers are 0 off the held set).
    fn primal_and_gap(&self) -> (F, F) {
        let mut max_rp = F::ZERO;
        let mut gap = F::ZERO;
        for f in self.fam.iter() {
            for (&g, &l) in f.g.iter().zip(f.lam.iter()) {
                max_rp = max_rp.max(g);
                gap += (-g).max(F::ZERO) * l;
            }
        }
        (max_rp, gap)
    }

    /// One regularised Newton step on the KKT system of the held set (see the module
    /// documentation): v += Δv, λ_A += ρ (C Δz + g_A). `None` if the matrix does not
    /// factorise.
    fn newton_step(&mut self, pr: &SingleLaneProblem<F, N>, st: &Settings<F>) -> Option<()> {
        let rho = st.active_set_penalty;
        let two = F::TWO;
        let w = pr.weights;
        let inv_b = F::ONE / pr.brake;
        let pen = |f: &Family<F, N>, k: usize| if held(&f.act, k) { rho } else { F::ZERO };
        // The Newton matrix's weights per stencil, and ρ g_A projected on each stencil.
        let mut a1 = [F::ZERO; N];
        let mut a2 = [F::ZERO; N];
        let mut a3 = [F::ZERO; N];
        {
            let [up, lo, ac, de, sa] = &self.fam;
            for k in 0..N {
                let (hu, hl, ha, hd, hs) =
                    (pen(up, k), pen(lo, k), pen(ac, k), pen(de, k), pen(sa, k));
                put(
                    &mut self.w1,
                    k,
                    two * w.reference_speed + get(&sa.lam, k) * inv_b + hu + hl,
                );
                put(&mut self.w2, k, two * w.smoothness + ha + hd);
                put(&mut self.w3, k, hs);
                put(&mut a1, k, hu * get(&up.g, k) - hl * get(&lo.g, k));
                put(&mut a2, k, ha * get(&ac.g, k) - hd * get(&de.g, k));
                put(&mut a3, k, hs * get(&sa.g, k));
            }
        }
        self.assemble(two * w.target_position * pr.h * pr.h);
        for d in self.kkt.d.iter_mut() {
            *d += st.regularization;
        }
        self.kkt.factor(st.pivot_floor).ok()?;
        let mut cg = [F::ZERO; N];
        self.jt(&a1, &a2, &a3, &mut cg);
        for ((r, &c), &d) in self.rhs.iter_mut().zip(cg.iter()).zip(self.rd.iter()) {
            *r = -d - c;
        }
        self.newton_solve(0);
        // Δz projected on the three stencils, then the multiplier and plan updates.
        let (mut d1, mut d2, mut sd) = ([F::ZERO; N], [F::ZERO; N], [F::ZERO; N]);
        self.stencil_directions(&mut d1, &mut d2, &mut sd);
        for ((f, dir), &plus) in self
            .fam
            .iter_mut()
            .zip([&d1, &d1, &d2, &d2, &sd])
            .zip(UPPER.iter())
        {
            for (((l, &a), &g), &d) in f
                .lam
                .iter_mut()
                .zip(f.act.iter())
                .zip(f.g.iter())
                .zip(dir.iter())
            {
                if a {
                    *l += rho * (if plus { d } else { -d } + g);
                }
            }
        }
        for (v, &dv) in self.v.iter_mut().zip(d1.iter()) {
            *v += dv;
        }
        Some(())
    }
}

/// Moves the multipliers of redundant bounds (kept negated in `src.ds` by
/// `guess_active_set`) onto the acceleration limits that imply them: the bound at k has
/// gradient D1_k = Σ_{j≤k} D2_j, so its multiplier adds to the acceleration limit at every
/// j ≤ k (a suffix sum), and those are held.
fn transfer<F: Real, const N: usize>(src: &mut Family<F, N>, dst: &mut Family<F, N>) {
    let mut sum = F::ZERO;
    for k in (0..N).rev() {
        sum -= get(&src.ds, k);
        if sum > F::ZERO {
            let l = get(&dst.lam, k) + sum;
            put(&mut dst.lam, k, l);
            hold(&mut dst.act, k, true);
        }
    }
}
