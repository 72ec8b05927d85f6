//! Vehicle and road parameters (paper Table I, SPEC §1), validated on construction.

use crate::real::Real;

/// Raw parameter values, as a user writes them. Turn them into [`Params`] with
/// [`Params::new`], which checks every invariant the safety proofs rely on.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ParamsSpec<F> {
    /// Maximum speed vmax (m/s), > 0.
    pub v_max: F,
    /// Maximum acceleration amax (m/s²), > 0.
    pub a_max: F,
    /// Maximum deceleration amin (m/s²), < 0.
    pub a_min: F,
    /// Sampling period h (s), > 0.
    pub h: F,
    /// Vehicle length L (m), > 0.
    pub length: F,
    /// Vehicle width W (m), > 0.
    pub width: F,
    /// Lane width Wl (m), > W.
    pub lane_width: F,
    /// Minimum turning radius ρmin (m), > 0.
    pub rho_min: F,
    /// Minimum heading relative to the road θmin (rad), in (−π/2, 0).
    pub theta_min: F,
    /// Maximum heading relative to the road θmax (rad), in (0, π/2).
    pub theta_max: F,
    /// Standstill margin bumper to bumper d0 (m), ≥ 0.
    pub d0: F,
}

impl<F: Real> ParamsSpec<F> {
    /// Paper Table I values plus SPEC §1 choices (θ bounds ∓π/6, d0 = 0.5 m).
    pub fn table_i() -> Self {
        Self {
            v_max: F::from_f64(27.8),
            a_max: F::from_f64(3.8),
            a_min: F::from_f64(-7.9),
            h: F::from_f64(0.01),
            length: F::from_f64(4.5),
            width: F::from_f64(1.7),
            lane_width: F::from_f64(3.6),
            rho_min: F::from_f64(5.3),
            theta_min: F::from_f64(-core::f64::consts::FRAC_PI_6),
            theta_max: F::from_f64(core::f64::consts::FRAC_PI_6),
            d0: F::from_f64(0.5),
        }
    }
}

/// Which parameter is wrong, and how.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ParamsError {
    /// A value is NaN or infinite.
    NotFinite(ParamName),
    /// A value that must be positive is not.
    NotPositive(ParamName),
    /// amin must be negative.
    DecelerationNotNegative,
    /// Lane width must exceed vehicle width.
    LaneNarrowerThanVehicle,
    /// Heading bounds must satisfy −π/2 < θmin < 0 < θmax < π/2.
    HeadingBoundsInvalid,
    /// d0 must be ≥ 0.
    NegativeStandstillMargin,
}

impl core::error::Error for ParamsError {}

/// Names of [`ParamsSpec`] fields, for error reporting.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[allow(missing_docs)]
#[non_exhaustive]
pub enum ParamName {
    VMax,
    AMax,
    AMin,
    H,
    Length,
    Width,
    LaneWidth,
    RhoMin,
    ThetaMin,
    ThetaMax,
    D0,
}

impl core::fmt::Display for ParamsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotFinite(n) => write!(f, "parameter {n:?} is not finite"),
            Self::NotPositive(n) => write!(f, "parameter {n:?} must be > 0"),
            Self::DecelerationNotNegative => write!(f, "a_min must be < 0"),
            Self::LaneNarrowerThanVehicle => write!(f, "lane_width must exceed width"),
            Self::HeadingBoundsInvalid => {
                write!(
                    f,
                    "heading bounds must satisfy -pi/2 < theta_min < 0 < theta_max < pi/2"
                )
            }
            Self::NegativeStandstillMargin => write!(f, "d0 must be >= 0"),
        }
    }
}

/// Validated parameters. Construct with [`Params::new`] or [`Params::table_i`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Params<F> {
    spec: ParamsSpec<F>,
    /// |amin|, cached: it appears in every safety quantity.
    brake: F,
}

impl<F: Real> Params<F> {
    /// All zeros, *not* valid parameters: the placeholder of a planner in a
    /// [`crate::slot`] before its `init` gives it real ones (a slot hands out no planner
    /// before that).
    pub(crate) const fn unset() -> Self {
        let z = F::ZERO;
        Self {
            spec: ParamsSpec {
                v_max: z,
                a_max: z,
                a_min: z,
                h: z,
                length: z,
                width: z,
                lane_width: z,
                rho_min: z,
                theta_min: z,
                theta_max: z,
                d0: z,
            },
            brake: z,
        }
    }

    /// Validates `spec`: amin < 0 < amax, h > 0, vmax > 0, L, W, ρmin > 0, Wl > W,
    /// −π/2 < θmin < 0 < θmax < π/2, d0 ≥ 0, everything finite.
    pub fn new(spec: ParamsSpec<F>) -> Result<Self, ParamsError> {
        use ParamName as N;
        let all = [
            (spec.v_max, N::VMax),
            (spec.a_max, N::AMax),
            (spec.a_min, N::AMin),
            (spec.h, N::H),
            (spec.length, N::Length),
            (spec.width, N::Width),
            (spec.lane_width, N::LaneWidth),
            (spec.rho_min, N::RhoMin),
            (spec.theta_min, N::ThetaMin),
            (spec.theta_max, N::ThetaMax),
            (spec.d0, N::D0),
        ];
        for (value, name) in all {
            if !value.is_finite() {
                return Err(ParamsError::NotFinite(name));
            }
        }
        let positive = [
            (spec.v_max, N::VMax),
            (spec.a_max, N::AMax),
            (spec.h, N::H),
            (spec.length, N::Length),
            (spec.width, N::Width),
            (spec.lane_width, N::LaneWidth),
            (spec.rho_min, N::RhoMin),
        ];
        for (value, name) in positive {
            if !(value > F::ZERO) {
                return Err(ParamsError::NotPositive(name));
            }
        }
        if !(spec.a_min < F::ZERO) {
            return Err(ParamsError::DecelerationNotNegative);
        }
        if !(spec.lane_width > spec.width) {
            return Err(ParamsError::LaneNarrowerThanVehicle);
        }
        let half_pi = F::from_f64(core::f64::consts::FRAC_PI_2);
        if !(spec.theta_min > -half_pi
            && spec.theta_min < F::ZERO
            && spec.theta_max > F::ZERO
            && spec.theta_max < half_pi)
        {
            return Err(ParamsError::HeadingBoundsInvalid);
        }
        if !(spec.d0 >= F::ZERO) {
            return Err(ParamsError::NegativeStandstillMargin);
        }
        Ok(Self {
            spec,
            brake: -spec.a_min,
        })
    }

    /// Table I defaults (SPEC §1). Infallible: the values are checked by a unit test.
    pub fn table_i() -> Self {
        let spec = ParamsSpec::table_i();
        Self {
            spec,
            brake: -spec.a_min,
        }
    }

    /// The raw values.
    pub fn spec(&self) -> &ParamsSpec<F> {
        &self.spec
    }
    /// vmax.
    #[inline]
    pub fn v_max(&self) -> F {
        self.spec.v_max
    }
    /// amax (> 0).
    #[inline]
    pub fn a_max(&self) -> F {
        self.spec.a_max
    }
    /// amin (< 0).
    #[inline]
    pub fn a_min(&self) -> F {
        self.spec.a_min
    }
    /// |amin| (> 0).
    #[inline]
    pub fn brake(&self) -> F {
        self.brake
    }
    /// h.
    #[inline]
    pub fn h(&self) -> F {
        self.spec.h
    }
    /// Vehicle length L.
    #[inline]
    pub fn length(&self) -> F {
        self.spec.length
    }
    /// Vehicle width W.
    #[inline]
    pub fn width(&self) -> F {
        self.spec.width
    }
    /// d0.
    #[inline]
    pub fn d0(&self) -> F {
        self.spec.d0
    }
    /// Lane width Wl.
    #[inline]
    pub fn lane_width(&self) -> F {
        self.spec.lane_width
    }
    /// Minimum turning radius ρmin.
    #[inline]
    pub fn rho_min(&self) -> F {
        self.spec.rho_min
    }
    /// θmin (< 0).
    #[inline]
    pub fn theta_min(&self) -> F {
        self.spec.theta_min
    }
    /// θmax (> 0).
    #[inline]
    pub fn theta_max(&self) -> F {
        self.spec.theta_max
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_i_is_valid() {
        let p = ParamsSpec::<f64>::table_i();
        assert_eq!(Params::new(p), Ok(Params::<f64>::table_i()));
        let p = ParamsSpec::<f32>::table_i();
        assert_eq!(Params::new(p), Ok(Params::<f32>::table_i()));
    }

    #[test]
    fn rejects_bad_values() {
        let ok = ParamsSpec::<f64>::table_i();
        let e = |s: ParamsSpec<f64>| Params::new(s).err();
        assert_eq!(
            e(ParamsSpec { a_min: 1.0, ..ok }),
            Some(ParamsError::DecelerationNotNegative)
        );
        assert_eq!(
            e(ParamsSpec { a_max: 0.0, ..ok }),
            Some(ParamsError::NotPositive(ParamName::AMax))
        );
        assert_eq!(
            e(ParamsSpec { h: -0.01, ..ok }),
            Some(ParamsError::NotPositive(ParamName::H))
        );
        assert_eq!(
            e(ParamsSpec {
                v_max: f64::NAN,
                ..ok
            }),
            Some(ParamsError::NotFinite(ParamName::VMax))
        );
        assert_eq!(
            e(ParamsSpec {
                lane_width: 1.0,
                ..ok
            }),
            Some(ParamsError::LaneNarrowerThanVehicle)
        );
        assert_eq!(
            e(ParamsSpec {
                theta_min: 0.1,
                ..ok
            }),
            Some(ParamsError::HeadingBoundsInvalid)
        );
        assert_eq!(
            e(ParamsSpec { d0: -1.0, ..ok }),
            Some(ParamsError::NegativeStandstillMargin)
        );
        assert_eq!(
            e(ParamsSpec {
                d0: f64::INFINITY,
                ..ok
            }),
            Some(ParamsError::NotFinite(ParamName::D0))
        );
    }
}
