//! Symmetric pentadiagonal matrices and their LDLᵀ factorisation, in fixed-size storage.
//!
//! Why pentadiagonal: in the prefix-sum variables z_k = Σ_{j≤k} v_j every constraint and
//! cost term of (10) involves at most three consecutive variables (see [`crate::solver`]),
//! so every Newton matrix of the interior-point method has bandwidth 2. LDLᵀ of such a
//! matrix costs O(N) and needs no pivoting when it is positive definite.

use crate::real::Real;

/// A symmetric N×N matrix with bandwidth 2: `d[j] = M[j][j]`, `e1[j] = M[j][j−1]`,
/// `e2[j] = M[j][j−2]` (entries `e1[0]`, `e2[0]`, `e2[1]` are unused and kept at 0).
#[derive(Debug, Clone, PartialEq)]
pub struct Penta<F, const N: usize> {
    /// Main diagonal.
    pub d: [F; N],
    /// First sub-diagonal, `M[j][j−1]`.
    pub e1: [F; N],
    /// Second sub-diagonal, `M[j][j−2]`.
    pub e2: [F; N],
    /// After [`Penta::factor`]: `1 / D[j]` (multiplying is far cheaper than dividing).
    pub dinv: [F; N],
}

impl<F: Real, const N: usize> Penta<F, N> {
    /// All zeros (a `const`, so that a solver holding it can be built at compile time).
    pub const fn zeros() -> Self {
        Self {
            d: [F::ZERO; N],
            e1: [F::ZERO; N],
            e2: [F::ZERO; N],
            dinv: [F::ZERO; N],
        }
    }
}

impl<F: Real, const N: usize> Default for Penta<F, N> {
    fn default() -> Self {
        Self::zeros()
    }
}

/// The factorisation failed: a pivot was not positive (matrix not positive definite to
/// working precision, or it held NaN).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NotPositiveDefinite;

impl<F: Real, const N: usize> Penta<F, N> {
    /// Sets every entry to zero.
    pub fn clear(&mut self) {
        *self = Self::default();
    }

    /// Adds w · c cᵀ where c has entries `c[0]` at row k, `c[1]` at k−1, `c[2]` at k−2
    /// (entries falling before row 0 are dropped: they belong to fixed quantities).
    #[inline]
    pub fn add_stencil(&mut self, k: usize, c: [F; 3], w: F) {
        let [c0, c1, c2] = c;
        add(&mut self.d, Some(k), w * c0 * c0);
        add(&mut self.d, k.checked_sub(1), w * c1 * c1);
        add(&mut self.d, k.checked_sub(2), w * c2 * c2);
        if k >= 1 {
            add(&mut self.e1, Some(k), w * c0 * c1);
        }
        if k >= 2 {
            add(&mut self.e1, Some(k - 1), w * c1 * c2);
            add(&mut self.e2, Some(k), w * c0 * c2);
        }
    }

    /// y = M x.
    pub fn mul(&self, x: &[F; N], y: &mut [F; N]) {
        for (j, yj) in y.iter_mut().enumerate() {
            let mut acc = get(&self.d, j) * get(x, j);
            if let Some(i) = j.checked_sub(1) {
                acc += get(&self.e1, j) * get(x, i);
            }
            if let Some(i) = j.checked_sub(2) {
                acc += get(&self.e2, j) * get(x, i);
            }
            acc += get(&self.e1, j + 1) * get(x, j + 1);
            acc += get(&self.e2, j + 2) * get(x, j + 2);
            *yj = acc;
        }
    }

    /// Factorises in place into L D Lᵀ (unit lower L with bandwidth 2): afterwards `d`
    /// holds D, `e1[j]` = `L[j][j−1]`, `e2[j]` = `L[j][j−2]`.
    ///
    /// Dynamic regularisation: the matrices factorised here are positive definite in
    /// exact arithmetic, but interior-point weights λ/s reach 1e15 near the optimum and
    /// cancellation can leave a pivot tiny or negative. A pivot below `pivot_floor` times
    /// its original diagonal entry is raised to that value (as QDLDL and Clarabel do); the
    /// step is then slightly inexact, which the interior-point iteration absorbs.
    pub fn factor(&mut self, pivot_floor: F) -> Result<(), NotPositiveDefinite> {
        // One pass over the rows, the two previous rows' D, 1/D and L[j−1][j−2] carried
        // along (no indexing: the hot loop of every Newton step).
        let (mut d1, mut dinv1, mut lprev) = (F::ZERO, F::ZERO, F::ZERO);
        let (mut d2, mut dinv2) = (F::ZERO, F::ZERO);
        let rows = self
            .d
            .iter_mut()
            .zip(self.dinv.iter_mut())
            .zip(self.e1.iter_mut().zip(self.e2.iter_mut()));
        for (j, ((d, dinv), (e1, e2))) in rows.enumerate() {
            let (mut l1, mut l2) = (F::ZERO, F::ZERO);
            if j >= 2 {
                l2 = *e2 * dinv2;
            }
            if j >= 1 {
                let mut m = *e1;
                if j >= 2 {
                    m -= l2 * d2 * lprev;
                }
                l1 = m * dinv1;
            }
            let mut dj = *d;
            if j >= 1 {
                dj -= l1 * l1 * d1;
            }
            if j >= 2 {
                dj -= l2 * l2 * d2;
            }
            let floor = pivot_floor * d.abs();
            // `!(x > floor)` also catches NaN, which then fails the check below.
            if !(dj > floor) {
                dj = floor;
            }
            if !(dj > F::ZERO) {
                return Err(NotPositiveDefinite);
            }
            let inv = F::ONE / dj;
            (*d, *dinv, *e1, *e2) = (dj, inv, l1, l2);
            (d2, dinv2) = (d1, dinv1);
            (d1, dinv1, lprev) = (dj, inv, l1);
        }
        Ok(())
    }

    /// Solves L D Lᵀ x = b in place (after [`Penta::factor`]).
    pub fn solve(&self, b: &mut [F; N]) {
        // Forward: x_j = b_j − L[j][j−1] x_{j−1} − L[j][j−2] x_{j−2}.
        let (mut x1, mut x2) = (F::ZERO, F::ZERO);
        for (j, (bj, (&e1, &e2))) in b
            .iter_mut()
            .zip(self.e1.iter().zip(self.e2.iter()))
            .enumerate()
        {
            let mut x = *bj;
            if j >= 1 {
                x -= e1 * x1;
            }
            if j >= 2 {
                x -= e2 * x2;
            }
            *bj = x;
            (x2, x1) = (x1, x);
        }
        for (bj, dj) in b.iter_mut().zip(self.dinv.iter()) {
            *bj *= *dj;
        }
        // Backward: x_j −= L[j+1][j] x_{j+1} + L[j+2][j] x_{j+2}.
        let (mut x1, mut x2) = (F::ZERO, F::ZERO);
        let (mut l1, mut l2) = (F::ZERO, F::ZERO);
        let (mut l2next, mut j) = (F::ZERO, N);
        for (bj, (&e1, &e2)) in b.iter_mut().zip(self.e1.iter().zip(self.e2.iter())).rev() {
            j -= 1;
            // L[j+1][j] = e1[j+1], L[j+2][j] = e2[j+2]: the rows after this one.
            let x = *bj - l1 * x1 - l2 * x2;
            *bj = x;
            (x2, x1) = (x1, x);
            // For row j−1: L[j][j−1] = e1[j], L[j+1][j−1] = e2[j+1].
            l2 = l2next;
            l1 = if j >= 1 { e1 } else { F::ZERO };
            l2next = if j >= 2 { e2 } else { F::ZERO };
        }
    }
}

/// `a[i]`, or 0 out of range (out-of-range reads are the band's implicit zeros).
#[inline(always)]
pub(crate) fn get<F: Real>(a: &[F], i: usize) -> F {
    a.get(i).copied().unwrap_or(F::ZERO)
}

#[inline(always)]
fn add<F: Real>(a: &mut [F], i: Option<usize>, x: F) {
    if let Some(slot) = i.and_then(|i| a.get_mut(i)) {
        *slot += x;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factor_solve_matches_dense() {
        // M = sum of random stencils + identity; check M x = b after solve.
        let mut m = Penta::<f64, 7>::default();
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64) / ((1u64 << 53) as f64) - 0.5
        };
        for k in 0..7 {
            m.add_stencil(k, [rnd(), rnd(), rnd()], 1.0 + rnd());
            m.d[k] += 1.0;
        }
        let b = [1.0, -2.0, 3.0, 0.5, 0.0, 4.0, -1.0];
        let mut x = b;
        let mut f = m.clone();
        f.factor(1e-14).unwrap();
        f.solve(&mut x);
        let mut mx = [0.0; 7];
        m.mul(&x, &mut mx);
        for i in 0..7 {
            assert!((mx[i] - b[i]).abs() < 1e-12, "{i}: {} vs {}", mx[i], b[i]);
        }
    }

    #[test]
    fn rejects_indefinite() {
        let mut m = Penta::<f64, 3> {
            d: [1.0, -1.0, 1.0],
            ..Default::default()
        };
        assert_eq!(m.factor(0.0), Err(NotPositiveDefinite));
        let mut m = Penta::<f64, 3> {
            d: [1.0, f64::NAN, 1.0],
            ..Default::default()
        };
        assert_eq!(m.factor(1e-14), Err(NotPositiveDefinite));
    }
}
