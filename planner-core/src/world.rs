//! What a vehicle knows of the others: the latest V2V state message from each, with its
//! age. Data flows one way: messages → [`WorldView`] → planner → command.
//!
//! Bounded memory: at most `CAP` vehicles are tracked (a `heapless::Vec`); a message from
//! a new vehicle when the view is full is rejected with an error, never dropped silently.

use crate::lanes::Other;
use crate::planner::Vehicle;
use crate::real::Real;
use heapless::Vec;

/// A vehicle-state message (V2V): what each vehicle broadcasts every period.
/// Lanes are absolute indices, 0 = rightmost.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VehicleState<F> {
    /// Sender.
    pub id: u16,
    /// Centre position along the road x (m).
    pub x: F,
    /// Lateral position y (m).
    pub y: F,
    /// Heading θ relative to the road (rad).
    pub theta: F,
    /// Speed v (m/s).
    pub v: F,
    /// Yaw rate ω (rad/s).
    pub omega: F,
    /// Lane ℓ.
    pub lane: u8,
    /// Lane α being changed to, during a change.
    pub alpha: Option<u8>,
    /// Intended lane β, before a change.
    pub beta: Option<u8>,
    /// Time the state was measured, by the sender's clock (s).
    pub stamp: F,
    /// The sender follows the protocols (see [`Other::cooperative`]); a scripted or
    /// legacy vehicle says it does not.
    pub cooperative: bool,
}

/// Why a message was not taken into the view (the view is unchanged).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WorldError {
    /// A field is NaN or infinite.
    NotFinite,
    /// Speed negative.
    NegativeSpeed,
    /// Not newer than the state already held for that vehicle (duplicate or reordered).
    Stale,
    /// The view already tracks `CAP` vehicles.
    Full,
    /// The message is the receiver's own.
    OwnMessage,
}

/// A tracked vehicle: its latest state and when it was received.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Known<F> {
    /// Latest state.
    pub state: VehicleState<F>,
    /// Receive time by the receiver's clock (s).
    pub received: F,
}

/// The latest known state of up to `CAP` other vehicles.
#[derive(Debug, Clone)]
pub struct WorldView<F, const CAP: usize> {
    own_id: u16,
    known: Vec<Known<F>, CAP>,
}

impl<F: Real, const CAP: usize> WorldView<F, CAP> {
    /// An empty view for the vehicle `own_id`.
    pub fn new(own_id: u16) -> Self {
        Self {
            own_id,
            known: Vec::new(),
        }
    }

    /// Takes in a message received at `now`. Invalid, own, stale or duplicate messages
    /// are rejected with a typed error and change nothing.
    pub fn update(&mut self, msg: &VehicleState<F>, now: F) -> Result<(), WorldError> {
        if msg.id == self.own_id {
            return Err(WorldError::OwnMessage);
        }
        let fields = [msg.x, msg.y, msg.theta, msg.v, msg.omega, msg.stamp, now];
        if !fields.iter().all(|f| f.is_finite()) {
            return Err(WorldError::NotFinite);
        }
        if msg.v < F::ZERO {
            return Err(WorldError::NegativeSpeed);
        }
        match self.known.iter_mut().find(|k| k.state.id == msg.id) {
            Some(k) => {
                if !(msg.stamp > k.state.stamp) {
                    return Err(WorldError::Stale);
                }
                *k = Known {
                    state: *msg,
                    received: now,
                };
                Ok(())
            }
            None => self
                .known
                .push(Known {
                    state: *msg,
                    received: now,
                })
                .map_err(|_| WorldError::Full),
        }
    }

    /// Forgets vehicles whose latest state is older than `max_age` at `now` (by stamp).
    pub fn forget_older_than(&mut self, now: F, max_age: F) {
        self.known.retain(|k| !(now - k.state.stamp > max_age));
    }

    /// Every tracked vehicle.
    pub fn iter(&self) -> impl Iterator<Item = &Known<F>> {
        self.known.iter()
    }

    /// Number of tracked vehicles.
    pub fn len(&self) -> usize {
        self.known.len()
    }

    /// `true` when no vehicle is tracked.
    pub fn is_empty(&self) -> bool {
        self.known.is_empty()
    }

    /// Every tracked vehicle as the multi-lane planner wants it (all assumed `length`
    /// long), with the age of its data at `now` (by its stamp), into `out` (cleared
    /// first; at most `CAP`).
    pub fn others(&self, now: F, length: F, out: &mut Vec<Other<F>, CAP>) {
        out.clear();
        for k in self.known.iter() {
            let s = &k.state;
            // Cannot fail: `out` has the same capacity as `known`.
            let _ = out.push(Other {
                alpha: s.alpha,
                beta: s.beta,
                cooperative: s.cooperative,
                ..Other::v2v(s.id, s.x, s.v, length, s.lane, (now - s.stamp).max(F::ZERO))
            });
        }
    }

    /// The vehicles in `lane` (all assumed `length` long), as the single-lane planner
    /// wants them, into `out` (cleared first; at most `CAP`).
    pub fn lane_vehicles(&self, lane: u8, length: F, out: &mut Vec<Vehicle<F>, CAP>) {
        out.clear();
        for k in self.known.iter().filter(|k| k.state.lane == lane) {
            // Cannot fail: `out` has the same capacity as `known`.
            let _ = out.push(Vehicle {
                x: k.state.x,
                length,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(id: u16, x: f64, stamp: f64) -> VehicleState<f64> {
        VehicleState {
            id,
            x,
            y: 0.0,
            theta: 0.0,
            v: 10.0,
            omega: 0.0,
            lane: 0,
            alpha: None,
            beta: None,
            stamp,
            cooperative: true,
        }
    }

    #[test]
    fn keeps_latest_and_rejects_bad_messages() {
        let mut w = WorldView::<f64, 2>::new(7);
        assert_eq!(w.update(&msg(1, 10.0, 0.0), 0.0), Ok(()));
        assert_eq!(w.update(&msg(1, 11.0, 0.01), 0.01), Ok(()));
        assert_eq!(w.update(&msg(1, 9.0, 0.01), 0.02), Err(WorldError::Stale));
        assert_eq!(w.update(&msg(1, 9.0, 0.005), 0.02), Err(WorldError::Stale));
        assert_eq!(
            w.update(&msg(7, 9.0, 1.0), 1.0),
            Err(WorldError::OwnMessage)
        );
        assert_eq!(
            w.update(&msg(2, f64::NAN, 1.0), 1.0),
            Err(WorldError::NotFinite)
        );
        let mut neg = msg(2, 0.0, 1.0);
        neg.v = -1.0;
        assert_eq!(w.update(&neg, 1.0), Err(WorldError::NegativeSpeed));
        assert_eq!(w.update(&msg(2, 20.0, 1.0), 1.0), Ok(()));
        assert_eq!(w.update(&msg(3, 30.0, 1.0), 1.0), Err(WorldError::Full));
        assert_eq!(w.len(), 2);
        let x1 = w.iter().find(|k| k.state.id == 1).map(|k| k.state.x);
        assert_eq!(x1, Some(11.0));
        w.forget_older_than(1.0, 0.5);
        assert_eq!(w.len(), 1);
        let mut lane = Vec::new();
        w.lane_vehicles(0, 4.5, &mut lane);
        assert_eq!(lane.len(), 1);
    }
}
