//! Symmetric pentadiagonal matrices and their LDLᵀ factorisation, in fixed-size storage.
//!
//! Why pentadiagonal: in the prefix-sum variables z_k = Σ_{j≤k} v_j every constraint and
//! cost term of (10) involves at most three consecutive variables (see [`crate::solver`]),
//! so every Newton matrix of the interior-point method has bandwidth 2. LDLᵀ of such a
//! matrix costs O(N) and needs no pivoting when it is positive definite.

use crate::real::Real;

/// A symmetric N×N matrix with bandwidth 2: `d[j] = M[j][j]`, `e1[j] = M[j][j−1]`,
/// `e2[j] = M[j][j−2]` (entries e1[0], e2[0], e2[1] are unused and kept at 0).
#[derive(Debug, Clone, PartialEq)]
pub struct Penta<F, const N: usize> {
    /// Main diagonal.
    pub d: [F; N],
    /// First sub-diagonal, M[j][j−1].
    pub e1: [F; N],
    /// Second sub-diagonal, M[j][j−2].
    pub e2: [F; N],
    /// After [`Penta::factor`]: 1 / D[j] (multiplying is far cheaper than dividing).
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
    /// holds D, `e1[j]` = L[j][j−1], `e2[j]` = L[j][j−2].
    ///
    /// Dynamic regularisation: the matrices factorised here are positive definite in
    /// exact arithmetic, but interior-point weights λ/s reach 1e15 near the optimum and
    /// cancellation can leave a pivot tiny or negative. A pivot below `pivot_floor` times
    /// its original diagonal entry is raised to that value (as QDLDL and Clarabel do); the
    /// step is then slightly inexact, which the interior-point iteration absorbs.
    pub fn factor(&mut self, pivot_floor: F) -> Result<(), NotPositiveDefinite> {
        for j in 0..N {
            let (mut l1, mut l2) = (F::ZERO, F::ZERO);
            if j >= 2 {
                l2 = get(&self.e2, j) * get(&self.dinv, j - 2);
            }
            if j >= 1 {
                let mut m = get(&self.e1, j);
                if j >= 2 {
                    m -= l2 * get(&self.d, j - 2) * get(&self.e1, j - 1);
                }
                l1 = m * get(&self.dinv, j - 1);
            }
            let mut dj = get(&self.d, j);
            if j >= 1 {
                dj -= l1 * l1 * get(&self.d, j - 1);
            }
            if j >= 2 {
                dj -= l2 * l2 * get(&self.d, j - 2);
            }
            let floor = pivot_floor * get(&self.d, j).abs();
            // `!(x > floor)` also catches NaN, which then fails the check below.
            if !(dj > floor) {
                dj = floor;
            }
            if !(dj > F::ZERO) {
                return Err(NotPositiveDefinite);
            }
            set(&mut self.d, j, dj);
            set(&mut self.dinv, j, F::ONE / dj);
            set(&mut self.e1, j, l1);
            set(&mut self.e2, j, l2);
        }
        Ok(())
    }

    /// Solves L D Lᵀ x = b in place (after [`Penta::factor`]).
    pub fn solve(&self, b: &mut [F; N]) {
        for j in 0..N {
            let mut x = get(b, j);
            if j >= 1 {
                x -= get(&self.e1, j) * get(b, j - 1);
            }
            if j >= 2 {
                x -= get(&self.e2, j) * get(b, j - 2);
            }
            set(b, j, x);
        }
        for (bj, dj) in b.iter_mut().zip(self.dinv.iter()) {
            *bj *= *dj;
        }
        for j in (0..N).rev() {
            let x = get(b, j)
                - get(&self.e1, j + 1) * get(b, j + 1)
                - get(&self.e2, j + 2) * get(b, j + 2);
            set(b, j, x);
        }
    }
}

/// `a[i]`, or 0 out of range (out-of-range reads are the band's implicit zeros).
#[inline(always)]
pub(crate) fn get<F: Real>(a: &[F], i: usize) -> F {
    a.get(i).copied().unwrap_or(F::ZERO)
}

#[inline(always)]
pub(crate) fn set<F: Real>(a: &mut [F], i: usize, x: F) {
    if let Some(slot) = a.get_mut(i) {
        *slot = x;
    }
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
