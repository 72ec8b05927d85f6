//! The unicycle model (1) with exact integration over one period (SPEC §2).
//!
//! Written in chord form: over [t, t+h) with constant (v, ω) the vehicle moves along an
//! arc whose chord has length D(v, ω) = v h · sinc(ωh/2) and direction θ + ωh/2. This is
//! algebraically equal to the paper's (v/ω)(sin(θ+ωh) − sin θ), −(v/ω)(cos(θ+ωh) − cos θ)
//! and, unlike it, loses no precision as ω → 0.

use crate::real::Real;

/// Position and heading of a vehicle's reference point (its centre).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pose<F> {
    /// x along the road (m).
    pub x: F,
    /// y across the road (m), 0 at the right edge of lane 0.
    pub y: F,
    /// Heading θ relative to the road (rad).
    pub theta: F,
}

/// |φ| below which sinc(φ) is evaluated by its Taylor series 1 − φ²/6 (+ φ⁴/120):
/// there the series' truncation error (φ⁶/5040 < 1e-24) is far below either precision's
/// rounding, while sin(φ)/φ would lose digits to cancellation.
pub const SINC_SERIES_BELOW: f64 = 1e-3;

/// sin(φ)/φ, with sinc(0) = 1.
#[inline]
pub fn sinc<F: Real>(phi: F) -> F {
    if phi.abs() < F::from_f64(SINC_SERIES_BELOW) {
        let p2 = phi * phi;
        F::ONE - p2 / F::from_f64(6.0) + p2 * p2 / F::from_f64(120.0)
    } else {
        phi.sin() / phi
    }
}

/// D(v, ω): the straight-line distance covered in one period h with input (v, ω)
/// (Lemma 6: D(v, ω) = D(v, 0) · sinc(ωh/2) ≤ D(v, 0) = v h).
#[inline]
pub fn chord<F: Real>(v: F, omega: F, h: F) -> F {
    v * h * sinc(F::HALF * omega * h)
}

/// The exact state after one period h of constant input (v, ω), eq. (1).
#[inline]
pub fn step<F: Real>(pose: Pose<F>, v: F, omega: F, h: F) -> Pose<F> {
    let d = chord(v, omega, h);
    let dir = pose.theta + F::HALF * omega * h;
    Pose {
        x: pose.x + d * dir.cos(),
        y: pose.y + d * dir.sin(),
        theta: pose.theta + omega * h,
    }
}

/// The lateral half-extent of an L × W rectangle at heading θ:
/// (L/2)|sin θ| + (W/2)|cos θ|, the distance from its centre line to its farthest corner
/// across the road.
#[inline]
pub fn lateral_half_extent<F: Real>(length: F, width: F, theta: F) -> F {
    F::HALF * (length * theta.sin().abs() + width * theta.cos().abs())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_papers_formula() {
        let p = Pose {
            x: 1.0,
            y: 2.0,
            theta: 0.3,
        };
        let (v, w, h) = (12.0f64, 0.7, 0.01);
        let q = step(p, v, w, h);
        let x = p.x + v / w * ((p.theta + w * h).sin() - p.theta.sin());
        let y = p.y - v / w * ((p.theta + w * h).cos() - p.theta.cos());
        assert!((q.x - x).abs() < 1e-12 && (q.y - y).abs() < 1e-12);
        assert!((q.theta - 0.307).abs() < 1e-12);
        let s = step(p, v, 0.0, h);
        assert!((s.x - (1.0 + 0.12 * 0.3f64.cos())).abs() < 1e-15);
        assert!((s.y - (2.0 + 0.12 * 0.3f64.sin())).abs() < 1e-15);
    }
}
