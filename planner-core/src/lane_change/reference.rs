//! A lane change's reference path: the quintic S-curve of Lemma 12 from one lane's centre
//! line to the next, and the shorter one back to a centre line when a vehicle is off it.

use crate::real::Real;

/// Length (m) of the S-curve back to the centre line at speed `v`: two seconds of travel,
/// at least 8 m (a 0.6 m offset then needs a radius of ≥ 18 m, above ρmin).
pub fn recentre_length<F: Real>(v: F) -> F {
    (F::TWO * v).max(F::from_f64(8.0))
}

/// A lane change's reference path: a quintic S-curve from (x0, y0) to (x0 + len, y1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Reference<F> {
    pub(super) x0: F,
    pub(super) y0: F,
    pub(super) y1: F,
    pub(super) len: F,
}

impl<F: Real> Reference<F> {
    /// (y_ref, θ_ref) at x.
    pub(super) fn at(&self, x: F) -> (F, F) {
        let u = ((x - self.x0) / self.len).max(F::ZERO).min(F::ONE);
        let (u2, u3) = (u * u, u * u * u);
        let s = u3 * (F::from_f64(10.0) - F::from_f64(15.0) * u + F::from_f64(6.0) * u2);
        let ds = F::from_f64(30.0) * u2 * (F::ONE - u).sq();
        let dy = self.y1 - self.y0;
        (self.y0 + dy * s, (dy * ds / self.len).atan2(F::ONE))
    }
}
