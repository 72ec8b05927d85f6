//! Floating-point abstraction: the planner runs in `f32` on the Cortex-M4F FPU and in
//! `f64` on hosts; every numerical tolerance is a named constant of this trait, per precision.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A floating-point scalar the planner can compute with (`f32` or `f64`).
///
/// The constants are the *numerical margins* that keep the safety checks sound in the
/// chosen precision; each says why it has its value.
pub trait Real:
    Copy
    + Default
    + Debug
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + 'static
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// 2.
    const TWO: Self;
    /// 1/2.
    const HALF: Self;
    /// Machine epsilon of the type.
    const EPSILON: Self;
    /// Distance (m) by which the planner tightens the safety constraint x_{k+1} + dS(v_k) ≤ x̄.
    ///
    /// Why: the plan is computed and verified in this precision relative to the gap
    /// x̄ − x_t (≤ a few km); the rounding of the handful of operations in x_{k+1} + dS(v_k)
    /// is below 10 ulp of the gap. f32: 10 × 2⁻¹² m at 4 km ≈ 0.01 m, so 2 cm leaves
    /// head-room; f64: 1 µm is ~10⁹ ulp, far above any rounding.
    const SAFETY_MARGIN_M: Self;
    /// Slack (m) the verifier allows on the tightened safety constraint; strictly smaller
    /// than [`Real::SAFETY_MARGIN_M`], so a verified plan satisfies the exact constraint
    /// with at least `SAFETY_MARGIN_M − VERIFY_SLACK_M` to spare. It must exceed the
    /// feasibility error of any solver the planner is used with: f64 0.1 µm (Clarabel at
    /// 1e-10 leaves up to ~1e-8 m on 50 m gaps; ours ≤ 1e-10 m), f32 5 mm.
    const VERIFY_SLACK_M: Self;
    /// Relative stopping tolerance of the interior-point solver (primal residual,
    /// dual residual and duality gap); near √ε for f32, 1e-10 for f64.
    const SOLVER_TOL: Self;
    /// Relative dual-residual tolerance of the solver. Looser than [`Real::SOLVER_TOL`]
    /// because once λ/s passes ~1e13 the Newton systems are so ill-conditioned that steps
    /// stop reducing the dual residual (it floors between 1e-9 and 1e-7 in f64, 1e-2 in
    /// f32) while J has long converged. The objective accuracy this buys is measured, not
    /// assumed: the Clarabel cross-check asserts ≤ 1e-6 relative (f64).
    const SOLVER_DUAL_TOL: Self;
    /// Default penalty ρ of the solver's active-set step (`Settings::active_set_penalty`):
    /// the multipliers of the held constraints converge by about 1/(1 + ρσ) per Newton
    /// step (σ the smallest eigenvalue of the held constraints' Schur complement, ~1e-3
    /// here), while ρ times the constraint gradients must stay factorisable against the
    /// cost's own curvature in this precision. Measured on the firmware's scenarios and
    /// bench-planner's drives (Newton steps per solve, worst and mean): f32 1e4 (2,900
    /// converged linearly at 0.4 a step on the approach; 3e4 and up cost the N = 50 lane
    /// change 7 % more steps), f64 1e9 (6.7e7: 17 % more steps on the N = 50 drive; 1e10
    /// and 1e11 the same as 1e9).
    const ACTIVE_SET_PENALTY: Self;
    /// Largest coordinate magnitude (m) the planner accepts: positions, road ends and
    /// targets beyond it are refused (`InputError::OutOfRange`). The margins above hold
    /// only while one ulp of a coordinate is far below them: f32 10 km (ulp 1 mm, half
    /// of `SAFETY_MARGIN_M`'s 2 cm is 10 ulp); f64 1,000 km (ulp 1.2e-10 m, a thousandth
    /// of `VERIFY_SLACK_M`). Beyond, the spacing of representable positions alone can
    /// exceed the margins (at x ≈ 5.6e14 m f64 positions are 6 cm apart).
    const MAX_COORD_M: Self;
    /// Converts from `f64` (rounding to nearest).
    fn from_f64(x: f64) -> Self;
    /// Converts from a small count (horizon index).
    fn from_usize(n: usize) -> Self;
    /// Converts from a count (rounding to nearest): microseconds of a
    /// [`crate::time::Duration`].
    fn from_u64(n: u64) -> Self;
    /// Converts to `f64` (exact).
    fn to_f64(self) -> f64;
    /// Square root (NaN for negative input).
    fn sqrt(self) -> Self;
    /// `true` unless NaN or ±∞.
    fn is_finite(self) -> bool;
    /// Sine.
    fn sin(self) -> Self;
    /// Cosine.
    fn cos(self) -> Self;
    /// Four-quadrant arctangent of `self / x`.
    fn atan2(self, x: Self) -> Self;
    /// π/2.
    const FRAC_PI_2: Self;

    /// Absolute value.
    #[inline]
    fn abs(self) -> Self {
        if self < Self::ZERO {
            -self
        } else {
            self
        }
    }
    /// The smaller of two values (the other if one is NaN).
    #[inline]
    fn min(self, o: Self) -> Self {
        if o < self {
            o
        } else {
            self
        }
    }
    /// The larger of two values (the other if one is NaN).
    #[inline]
    fn max(self, o: Self) -> Self {
        if o > self {
            o
        } else {
            self
        }
    }
    /// `self²`.
    #[inline]
    fn sq(self) -> Self {
        self * self
    }
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const TWO: Self = 2.0;
    const HALF: Self = 0.5;
    const EPSILON: Self = f32::EPSILON;
    const SAFETY_MARGIN_M: Self = 0.02;
    const VERIFY_SLACK_M: Self = 0.005;
    const SOLVER_TOL: Self = 2e-4;
    const SOLVER_DUAL_TOL: Self = 2e-2;
    const ACTIVE_SET_PENALTY: Self = 1e4;
    const MAX_COORD_M: Self = 1e4;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    #[inline]
    fn from_usize(n: usize) -> Self {
        n as f32
    }
    #[inline]
    fn from_u64(n: u64) -> Self {
        n as f32
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrtf(self)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
    #[inline]
    fn sin(self) -> Self {
        if self.abs() <= F32_KERNEL_MAX {
            sin_kernel_f32(self)
        } else {
            libm::sinf(self)
        }
    }
    #[inline]
    fn cos(self) -> Self {
        if self.abs() <= F32_KERNEL_MAX {
            cos_kernel_f32(self)
        } else {
            libm::cosf(self)
        }
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        libm::atan2f(self, x)
    }
    const FRAC_PI_2: Self = core::f32::consts::FRAC_PI_2;
}

/// |x| up to which `f32` sine and cosine are the polynomials below (π/4); beyond it, libm.
///
/// Why not libm everywhere: `libm::sinf`/`cosf` evaluate their kernels in `f64`, which the
/// Cortex-M4F's single-precision FPU runs in software — about 1,200 instructions per call,
/// measured in the firmware — and a lane-change step calls them ~150 times (the lateral
/// QP's linearisation, the exact unicycle of the verification, the rectangle's extent).
/// Headings stay within ±π/6 < π/4, so no range reduction is needed there and the minimax
/// polynomials of Cephes' `sinf`/`cosf` (Moshier) for [−π/4, π/4], evaluated in `f32`,
/// cost ~24 instructions (measured in the firmware) and are within 2 ulp of the true value (unit test
/// `f32_kernels_are_within_two_ulp`). They are odd and even exactly (sin(±0) = ±0,
/// cos(0) = 1), which the straight-line shortcuts of the verification rely on. The
/// margins of [`Real`] for `f32` (millimetres) are far above a 2-ulp change of a sine.
const F32_KERNEL_MAX: f32 = core::f32::consts::FRAC_PI_4;

/// sin x for |x| ≤ π/4 (Cephes `sinf`'s polynomial). Below 2⁻¹² sin x rounds to x
/// itself (x³/6 < ½ ulp), returned as is, as libm does, which also keeps sin(−0) = −0.
#[inline]
fn sin_kernel_f32(x: f32) -> f32 {
    if x.abs() < 2.441_406_3e-4 {
        return x;
    }
    let z = x * x;
    ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * x + x
}

/// cos x for |x| ≤ π/4 (Cephes `cosf`'s polynomial).
#[inline]
fn cos_kernel_f32(x: f32) -> f32 {
    let z = x * x;
    ((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - 0.5 * z + 1.0
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const TWO: Self = 2.0;
    const HALF: Self = 0.5;
    const EPSILON: Self = f64::EPSILON;
    const SAFETY_MARGIN_M: Self = 1e-6;
    const VERIFY_SLACK_M: Self = 1e-7;
    const SOLVER_TOL: Self = 1e-10;
    const SOLVER_DUAL_TOL: Self = 1e-6;
    const ACTIVE_SET_PENALTY: Self = 1e9;
    const MAX_COORD_M: Self = 1e6;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x
    }
    #[inline]
    fn from_usize(n: usize) -> Self {
        n as f64
    }
    #[inline]
    fn from_u64(n: u64) -> Self {
        n as f64
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
    #[inline]
    fn sin(self) -> Self {
        libm::sin(self)
    }
    #[inline]
    fn cos(self) -> Self {
        libm::cos(self)
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        libm::atan2(self, x)
    }
    const FRAC_PI_2: Self = core::f64::consts::FRAC_PI_2;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between two finite `f32` of the same sign.
    fn ulps(a: f32, b: f32) -> u32 {
        if a == b {
            return 0;
        }
        assert!(a.signum() == b.signum(), "{a} vs {b}");
        a.to_bits().abs_diff(b.to_bits())
    }

    #[test]
    fn f32_kernels_are_within_two_ulp() {
        // Every 64th f32 in (0, π/4] and its negative, against the f64 libm value rounded
        // to f32 (itself within ½ ulp of the truth). Near 0, sin x rounds to x itself.
        let mut worst = (0, 0);
        let top = F32_KERNEL_MAX.to_bits();
        for bits in (1..=top).step_by(64).chain(core::iter::once(top)) {
            for x in [f32::from_bits(bits), -f32::from_bits(bits)] {
                let s = ulps(Real::sin(x), libm::sin(x as f64) as f32);
                let c = ulps(Real::cos(x), libm::cos(x as f64) as f32);
                worst = (worst.0.max(s), worst.1.max(c));
            }
        }
        assert!(
            worst.0 <= 2 && worst.1 <= 2,
            "worst ulps (sin, cos) = {worst:?}"
        );
    }

    #[test]
    fn f32_kernels_keep_the_exact_values_and_symmetries() {
        assert_eq!(Real::sin(0.0f32).to_bits(), 0.0f32.to_bits());
        assert_eq!(Real::sin(-0.0f32).to_bits(), (-0.0f32).to_bits());
        assert_eq!(Real::cos(0.0f32), 1.0);
        assert_eq!(Real::cos(-0.0f32), 1.0);
        for x in [1e-30f32, 1e-6, 0.1, 0.5, 0.78] {
            assert_eq!(Real::sin(-x), -Real::sin(x));
            assert_eq!(Real::cos(-x), Real::cos(x));
        }
        // Beyond π/4 and for non-finite input, libm answers.
        for x in [1.0f32, -2.5, 100.0] {
            assert_eq!(Real::sin(x), libm::sinf(x));
            assert_eq!(Real::cos(x), libm::cosf(x));
        }
        assert!(Real::sin(f32::NAN).is_nan() && Real::cos(f32::INFINITY).is_nan());
    }
}
