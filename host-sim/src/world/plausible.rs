//! Plausibility of what a vehicle says of itself: every state and crossing
//! report is checked against the last one accepted from the same sender, in the same
//! frame, before it enters a view. Authentication (SecOC) proves who sent a message, not
//! that it is true; a sender with a valid key can still lie about where it is. Physics
//! bounds the lie: between two messages Δt apart a vehicle of Table I moves forward by at
//! most vmax·Δt, across by at most vmax·Δt, changes its speed by at most amax·Δt (up) or
//! |amin|·Δt (down), never exceeds vmax, and changes lanes one at a time into the lane it
//! declared (α).
//!
//! A state outside those bounds, each widened by a stated margin, is refused with its
//! [`Implausible`] reason and changes nothing: the receiver keeps the last trusted record,
//! whose age then grows, so planner-core takes the vehicle at the worst case reachable
//! from it (a vehicle ahead never behind its stamped position since v ≥ 0; a vehicle
//! behind inflated by `unaware_reach` at amax for the age; stale data blocks lane-change
//! starts). The sender becomes a suspect whose later messages are refused
//! ([`super::heard::View::take`]).
//!
//! The margins: CAN rounds positions to 0.01 m, speeds to 0.02 m/s and the sender's clock
//! to 1 ms (docs/can.md); 0.5 m and 0.5 m/s are far above that rounding and far below the
//! "few metres" of a lie that matters.

use planner_core::crossing::CrossingReport;
use planner_core::{Instant, Params, VehicleState};

/// Slack (m) on position jumps, forward, backward and across.
pub const POSITION_MARGIN_M: f64 = 0.5;
/// Slack (m/s) on speeds and speed changes.
pub const SPEED_MARGIN_MPS: f64 = 0.5;

/// Why a message was judged implausible.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Implausible {
    /// It moved further than vmax·Δt + margin since its last accepted message, went
    /// backwards by more than the margin, or changed its route at a junction.
    Jump,
    /// Its speed is above vmax + margin.
    Speed,
    /// Its speed changed by more than amax·Δt (faster) or |amin|·Δt (slower), + margin.
    Acceleration,
    /// It is more than one lane from its last lane, or in the next lane without having
    /// declared the change into it.
    LaneJump,
}

/// The physical bounds every vehicle keeps (Table I: the loaders refuse faster limits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// vmax (m/s).
    pub v_max: f64,
    /// amax (m/s²).
    pub a_max: f64,
    /// amin (m/s², negative).
    pub a_min: f64,
}

impl Bounds {
    /// Table I's.
    pub fn table_i() -> Self {
        let p = Params::<f64>::table_i();
        Self {
            v_max: p.v_max(),
            a_max: p.a_max(),
            a_min: p.a_min(),
        }
    }

    /// A speed and its change over `dt` from `last`.
    fn speed(&self, last: f64, v: f64, dt: f64) -> Result<(), Implausible> {
        if v > self.v_max + SPEED_MARGIN_MPS {
            return Err(Implausible::Speed);
        }
        let dv = v - last;
        if dv > self.a_max * dt + SPEED_MARGIN_MPS || dv < self.a_min * dt - SPEED_MARGIN_MPS {
            return Err(Implausible::Acceleration);
        }
        Ok(())
    }

    /// A move of `ds` along and `dy` across over `dt`.
    fn moved(&self, ds: f64, dy: f64, dt: f64) -> Result<(), Implausible> {
        let reach = self.v_max * dt + POSITION_MARGIN_M;
        if ds > reach || ds < -POSITION_MARGIN_M || dy.abs() > reach {
            return Err(Implausible::Jump);
        }
        Ok(())
    }

    /// `new` against `last`, the last state accepted from the same sender in the same
    /// frame (`None`: nothing to compare with but vmax). `new` is newer than `last`.
    pub fn state(
        &self,
        last: Option<&VehicleState<f64>>,
        new: &VehicleState<f64>,
    ) -> Result<(), Implausible> {
        let Some(last) = last else {
            return self.speed(new.v, new.v, 0.0);
        };
        let dt = new.stamp.since(last.stamp).as_secs();
        self.speed(last.v, new.v, dt)?;
        self.moved(new.x - last.x, new.y - last.y, dt)?;
        let declared = last.alpha == Some(new.lane);
        if new.lane != last.lane && (new.lane.abs_diff(last.lane) > 1 || !declared) {
            return Err(Implausible::LaneJump);
        }
        Ok(())
    }

    /// A crossing report stamped `stamp` against the last accepted at the same junction
    /// (`last`, with its stamp).
    pub fn report(
        &self,
        last: Option<(&CrossingReport<f64>, Instant)>,
        new: &CrossingReport<f64>,
        stamp: Instant,
    ) -> Result<(), Implausible> {
        let Some((last, at)) = last else {
            return self.speed(new.v, new.v, 0.0);
        };
        if new.route != last.route {
            return Err(Implausible::Jump);
        }
        let dt = stamp.since(at).as_secs();
        self.speed(last.v, new.v, dt)?;
        self.moved(new.s - last.s, 0.0, dt)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `s` seconds after the epoch.
    fn secs(s: f64) -> Instant {
        Instant::from_micros((s * 1e6).round() as u64)
    }

    fn state(x: f64, v: f64, lane: u8, stamp: f64) -> VehicleState<f64> {
        let stamp = secs(stamp);
        VehicleState {
            id: 7,
            x,
            y: 1.8 + 3.6 * f64::from(lane),
            theta: 0.0,
            v,
            omega: 0.0,
            lane,
            alpha: None,
            beta: None,
            stamp,
            cooperative: true,
            brake: None,
            length: None,
        }
    }

    #[test]
    fn each_bound_holds_to_its_margin_and_not_beyond() {
        let b = Bounds::table_i();
        let last = state(100.0, 20.0, 0, 1.0);
        let ok = |s: VehicleState<f64>| b.state(Some(&last), &s);
        // 0.1 s later: up to 2.78 m + 0.5 m forward, 0.5 m back.
        let far = 100.0 + 2.78 + POSITION_MARGIN_M;
        assert_eq!(ok(state(far - 1e-6, 20.0, 0, 1.1)), Ok(()));
        assert_eq!(ok(state(far + 1e-3, 20.0, 0, 1.1)), Err(Implausible::Jump));
        assert_eq!(ok(state(99.5 + 1e-6, 20.0, 0, 1.1)), Ok(()));
        assert_eq!(ok(state(99.4, 20.0, 0, 1.1)), Err(Implausible::Jump));
        let mut across = state(101.0, 20.0, 0, 1.1);
        across.y += 3.3;
        assert_eq!(ok(across), Err(Implausible::Jump));
        across.y -= 0.1;
        assert_eq!(ok(across), Ok(()));
        // Speed: vmax + 0.5 m/s at most; a change of 0.38 + 0.5 up, 0.79 + 0.5 down.
        let fast = Bounds { a_max: 1e3, ..b };
        assert_eq!(
            fast.state(Some(&last), &state(101.0, 28.29, 0, 1.1)),
            Ok(())
        );
        assert_eq!(
            fast.state(Some(&last), &state(101.0, 28.31, 0, 1.1)),
            Err(Implausible::Speed)
        );
        assert_eq!(
            b.state(None, &state(0.0, 28.31, 0, 1.1)),
            Err(Implausible::Speed)
        );
        assert_eq!(ok(state(101.0, 20.87, 0, 1.1)), Ok(()));
        assert_eq!(
            ok(state(101.0, 20.89, 0, 1.1)),
            Err(Implausible::Acceleration)
        );
        assert_eq!(ok(state(101.0, 18.72, 0, 1.1)), Ok(()));
        assert_eq!(
            ok(state(101.0, 18.70, 0, 1.1)),
            Err(Implausible::Acceleration)
        );
    }

    #[test]
    fn lanes_change_one_at_a_time_into_the_declared_one() {
        let b = Bounds::table_i();
        let mut last = state(100.0, 20.0, 1, 1.0);
        // The same y throughout: the lane field alone is judged here.
        let next = |lane: u8| VehicleState {
            y: last.y,
            ..state(101.0, 20.0, lane, 1.1)
        };
        assert_eq!(b.state(Some(&last), &next(1)), Ok(()));
        assert_eq!(b.state(Some(&last), &next(2)), Err(Implausible::LaneJump));
        last.alpha = Some(2);
        assert_eq!(b.state(Some(&last), &next(2)), Ok(()));
        assert_eq!(b.state(Some(&last), &next(0)), Err(Implausible::LaneJump));
        last.alpha = Some(3);
        assert_eq!(b.state(Some(&last), &next(3)), Err(Implausible::LaneJump));
    }

    #[test]
    fn a_report_keeps_its_route_and_moves_along_it_as_a_state_does() {
        let b = Bounds::table_i();
        let r = |route: u8, s: f64, v: f64| CrossingReport {
            id: 7,
            route,
            s,
            v,
            length: 4.5,
            brake: None,
        };
        let last = r(2, 10.0, 10.0);
        assert_eq!(
            b.report(Some((&last, secs(1.0))), &r(2, 11.0, 10.0), secs(1.1)),
            Ok(())
        );
        assert_eq!(
            b.report(Some((&last, secs(1.0))), &r(3, 11.0, 10.0), secs(1.1)),
            Err(Implausible::Jump)
        );
        assert_eq!(
            b.report(Some((&last, secs(1.0))), &r(2, 14.0, 10.0), secs(1.1)),
            Err(Implausible::Jump)
        );
        assert_eq!(
            b.report(Some((&last, secs(1.0))), &r(2, 11.0, 12.0), secs(1.1)),
            Err(Implausible::Acceleration)
        );
        assert_eq!(
            b.report(None, &r(2, 11.0, 30.0), secs(1.1)),
            Err(Implausible::Speed)
        );
    }
}
