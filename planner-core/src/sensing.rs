//! Onboard range sensing: the second source of what a vehicle knows, besides V2V
//! (the paper's future work, SPEC §9: "bounded measurement error: shrink free space by
//! the error bound").
//!
//! The paper's safety argument rests on every vehicle hearing every other: a message
//! lost, late, or never sent (a silent transmitter, a legacy vehicle) leaves a vehicle
//! planning on a world that is emptier than the real one. Real vehicles also measure
//! their surroundings. A [`Sensing`] describes what the ego's own sensors cover, and the
//! planners take their returns as [`Other`](crate::lanes::Other)s with `sensed = true`
//! beside the V2V records, each at its worst case within the stated error bounds:
//!
//! - a vehicle **ahead** is taken `position_error_m` closer (its rear may be that much
//!   nearer than measured);
//! - a vehicle **behind** is taken `position_error_m` closer and `speed_error_mps`
//!   faster;
//! - space the sensors do not cover is **not** taken as free: ahead, beyond `ahead_m`,
//!   the lane is taken as blocked at the edge of the range (a stopped vehicle just out of
//!   sight); behind, beyond `behind_m`, a vehicle may be closing in at vmax.
//!
//! With `ahead_m` above dS(vmax) + d0 the range edge never limits a vehicle's speed, and
//! with `behind_m` above dS(vmax) + d0 plus one period at vmax the vehicle assumed
//! beyond the rear range never blocks a lane change ([`Sensing::validate`] requires
//! both): the sensors then cost nothing on the paper's perfect bus but the error bounds,
//! and keep every vehicle safe when the bus fails.
//!
//! The sensor model itself (what a return is, given the truth) lives in the simulator;
//! this module only says how returns are used.

use crate::params::Params;
use crate::planner::ConfigError;
use crate::real::Real;
use crate::safety;

/// What the ego's range sensors cover and how well.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sensing<F> {
    /// Forward range (m), from the ego's front bumper: every vehicle whose rectangle
    /// overlaps the ego's lanes ahead within it is returned.
    pub ahead_m: F,
    /// Rear and side range (m), from the ego's rear bumper: every vehicle behind in the
    /// ego's lane and the lanes next to it within it is returned.
    pub behind_m: F,
    /// Bound on the error of a returned position (m).
    pub position_error_m: F,
    /// Bound on the error of a returned speed (m/s).
    pub speed_error_mps: F,
}

impl<F: Real> Sensing<F> {
    /// A radar-like default: 150 m ahead, 100 m behind, ±0.1 m and ±0.1 m/s.
    pub fn radar() -> Self {
        Self {
            ahead_m: F::from_f64(150.0),
            behind_m: F::from_f64(100.0),
            position_error_m: F::from_f64(0.1),
            speed_error_mps: F::from_f64(0.1),
        }
    }

    /// The least range (m) either way that keeps the sensors from limiting the planner
    /// (see the module docs): dS(vmax) + d0 + one period at vmax, plus 1 m.
    pub fn min_range(p: &Params<F>) -> F {
        safety::d_s(p, p.v_max()) + p.d0() + p.v_max() * p.h() + F::ONE
    }

    /// Checks the values: finite; both ranges at least [`Sensing::min_range`]; error
    /// bounds non-negative and below 1 m (m/s).
    pub fn validate(&self, p: &Params<F>) -> Result<(), ConfigError> {
        let all = [
            self.ahead_m,
            self.behind_m,
            self.position_error_m,
            self.speed_error_mps,
        ];
        let errors_ok = |e: F| e >= F::ZERO && e < F::ONE;
        let ranges_ok = self.ahead_m >= Self::min_range(p) && self.behind_m >= Self::min_range(p);
        let finite = all.iter().all(|x| x.is_finite());
        if !(finite
            && ranges_ok
            && errors_ok(self.position_error_m)
            && errors_ok(self.speed_error_mps))
        {
            return Err(ConfigError::InvalidSensing);
        }
        Ok(())
    }
}

/// `true` while a vehicle that has planned `steps` periods of `h` may not yet have heard
/// of every vehicle near it, given that messages take up to `notify` (≥ h, the time from
/// sending to being known at the next period) to arrive: a message sent at the first
/// step arrives by then `notify − h` later. Half a period of slack covers clocks that
/// add up h in floating point (ten steps of 0.01 s fall just short of 0.1 s). On the
/// paper's bus (`notify` = h) this is never the case.
pub fn still_unheard<F: Real>(steps: u32, h: F, notify: F) -> bool {
    let elapsed = F::from_f64(f64::from(steps)) * h;
    notify > h + F::from_f64(1e-9) && elapsed < notify - F::HALF * h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unheard_until_the_first_messages_can_have_arrived() {
        let h = 0.01;
        assert!(!still_unheard(0, h, h), "the paper's bus: heard at once");
        // 0.1 s of delay: the first messages arrive at step 10 (or 11, by rounding).
        assert!(still_unheard(0, h, h + 0.1) && still_unheard(10, h, h + 0.1));
        assert!(!still_unheard(11, h, h + 0.1));
    }

    #[test]
    fn validation() {
        let p = Params::<f64>::table_i();
        assert_eq!(Sensing::<f64>::radar().validate(&p), Ok(()));
        let short = Sensing {
            ahead_m: Sensing::min_range(&p) - 0.01,
            ..Sensing::radar()
        };
        assert!(short.validate(&p).is_err());
        let bad = Sensing {
            position_error_m: f64::NAN,
            ..Sensing::radar()
        };
        assert!(bad.validate(&p).is_err());
        let neg = Sensing {
            speed_error_mps: -0.1,
            ..Sensing::radar()
        };
        assert!(neg.validate(&p).is_err());
    }
}
