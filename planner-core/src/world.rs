//! What a vehicle knows of the others: the latest V2V state message from each, with its
//! age. Data flows one way: messages → [`WorldView`] → planner → command.
//!
//! Bounded memory: at most `CAP` vehicles are tracked (a `heapless::Vec`); a message from
//! a new vehicle when the view is full is rejected with an error, never dropped silently.

use crate::lanes::Other;
use crate::planner::Vehicle;
use crate::real::Real;
use crate::time::{Duration, Instant};
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
    /// When the state was measured, by the sender's clock ([`crate::time`]).
    pub stamp: Instant,
    /// The sender follows the protocols (see [`Other::cooperative`]); a scripted or
    /// legacy vehicle says it does not.
    pub cooperative: bool,
    /// Its braking limit |amin| (m/s²), if it declares one: what a follower keeping the
    /// leader-aware invariant ([`crate::safety::Invariant::LeaderAware`]) credits it with.
    pub brake: Option<crate::safety::BrakeLimit>,
    /// Its length (m), if it declares one; a receiver takes a vehicle that declares
    /// none at the length it assumes for every such vehicle (the longest it expects:
    /// [`WorldView::others`]).
    pub length: Option<BodyLength>,
}

/// A vehicle's length as it declares it over V2V: in steps of 0.1 m, from 0.1 to 25.5 m
/// (a 16.5 m articulated truck fits) — one byte, as a CAN signal carries it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BodyLength(u8);

impl BodyLength {
    /// The step (m).
    pub const STEP_M: f64 = 0.1;

    /// `l` m rounded *up* to the next step (within 1e-4 m, so that 4.5 in f32 stays
    /// 4.5): a vehicle taken longer than it is only keeps more room. `None` unless
    /// 0 < l ≤ 25.5 m.
    pub fn from_m<F: Real>(l: F) -> Option<Self> {
        let tenths = l.to_f64() / Self::STEP_M;
        if !(tenths > 0.0 && tenths <= 255.0 + 1e-3) {
            return None;
        }
        // Truncation toward zero, then up unless already (all but) on a step.
        let down = tenths as u32;
        let up = if tenths - f64::from(down) > 1e-3 {
            down + 1
        } else {
            down
        };
        u8::try_from(up).ok().filter(|&t| t > 0).map(Self)
    }

    /// From its wire value, tenths of a metre; `None` for 0 (no length declared).
    pub fn from_tenths(tenths: u8) -> Option<Self> {
        (tenths > 0).then_some(Self(tenths))
    }

    /// Its wire value, tenths of a metre (1–255).
    pub fn tenths(self) -> u8 {
        self.0
    }

    /// In metres.
    pub fn m<F: Real>(self) -> F {
        F::from_f64(f64::from(self.0) * Self::STEP_M)
    }
}

/// The length (m) a receiver takes the sender of `s` at: its declared length, else
/// `undeclared`.
fn length_of<F: Real>(s: &VehicleState<F>, undeclared: F) -> F {
    s.length.map_or(undeclared, BodyLength::m)
}

impl<F> VehicleState<F> {
    /// The same state with its numbers converted by `f`, e.g. `f64` → `f32` for an MCU's
    /// codec, or `f32` → `f64` for a host that mirrors one.
    pub fn map<G>(self, f: impl Fn(F) -> G) -> VehicleState<G> {
        VehicleState {
            id: self.id,
            x: f(self.x),
            y: f(self.y),
            theta: f(self.theta),
            v: f(self.v),
            omega: f(self.omega),
            lane: self.lane,
            alpha: self.alpha,
            beta: self.beta,
            stamp: self.stamp,
            cooperative: self.cooperative,
            brake: self.brake,
            length: self.length,
        }
    }
}

/// Why a message was not taken into the view (the view is unchanged).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
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

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for WorldError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotFinite => f.write_str("a field is NaN or infinite"),
            Self::NegativeSpeed => f.write_str("speed negative"),
            Self::Stale => f.write_str(
                "not newer than the state already held for that vehicle (duplicate or reordered)",
            ),
            Self::Full => f.write_str("the view already tracks CAP vehicles"),
            Self::OwnMessage => f.write_str("the message is the receiver's own"),
        }
    }
}

impl core::error::Error for WorldError {}

/// A tracked vehicle: its latest state and when it was received.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Known<F> {
    /// Latest state.
    pub state: VehicleState<F>,
    /// When it was received, by the receiver's clock.
    pub received: Instant,
}

/// The latest known state of up to `CAP` other vehicles.
///
/// # Examples
///
/// ```
/// use planner_core::heapless::Vec;
/// use planner_core::{Instant, VehicleState, WorldError, WorldView};
///
/// let mut view = WorldView::<f32, 4>::new(2);
/// let now = Instant::from_secs(60 * 86_400); // 60 days of uptime: integer time
/// let car = VehicleState {
///     id: 1, x: 50.0, y: 1.8, theta: 0.0, v: 12.0, omega: 0.0, lane: 0,
///     alpha: None, beta: None, stamp: now, cooperative: true, brake: None, length: None,
/// };
/// view.update(&car, now)?;
/// // The same stamp again is refused and changes nothing.
/// assert_eq!(view.update(&car, now), Err(WorldError::Stale));
/// let mut ahead = Vec::new();
/// view.lane_vehicles(0, 4.5, &mut ahead);
/// assert_eq!(ahead.len(), 1);
/// # Ok::<(), WorldError>(())
/// ```
#[derive(Debug, Clone)]
pub struct WorldView<F, const CAP: usize> {
    own_id: u16,
    known: Vec<Known<F>, CAP>,
}

impl<F: Real, const CAP: usize> WorldView<F, CAP> {
    /// An empty view for the vehicle `own_id` (`const`: a `static` can hold one, off the
    /// stack).
    pub const fn new(own_id: u16) -> Self {
        Self {
            own_id,
            known: Vec::new(),
        }
    }

    /// Takes in a message received at `now`. Invalid, own, stale or duplicate messages
    /// are rejected with a typed error and change nothing.
    pub fn update(&mut self, msg: &VehicleState<F>, now: Instant) -> Result<(), WorldError> {
        if msg.id == self.own_id {
            return Err(WorldError::OwnMessage);
        }
        let fields = [msg.x, msg.y, msg.theta, msg.v, msg.omega];
        if !fields.iter().all(|f| f.is_finite()) {
            return Err(WorldError::NotFinite);
        }
        if msg.v < F::ZERO {
            return Err(WorldError::NegativeSpeed);
        }
        match self.known.iter_mut().find(|k| k.state.id == msg.id) {
            Some(k) => {
                if msg.stamp <= k.state.stamp {
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
    pub fn forget_older_than(&mut self, now: Instant, max_age: Duration) {
        self.known.retain(|k| now.since(k.state.stamp) <= max_age);
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

    /// Every tracked vehicle as the multi-lane planner wants it (its declared length, or
    /// `length` if it declares none), with the age of its data at `now` (by its stamp), into `out` (cleared
    /// first; at most `CAP`).
    pub fn others(&self, now: Instant, length: F, out: &mut Vec<Other<F>, CAP>) {
        out.clear();
        for k in self.known.iter() {
            let s = &k.state;
            // Cannot fail: `out` has the same capacity as `known`.
            let _ = out.push(Other {
                alpha: s.alpha,
                beta: s.beta,
                cooperative: s.cooperative,
                // Only a cooperating vehicle's limit bounds where it can stop.
                brake: s.brake.filter(|_| s.cooperative),
                ..Other::v2v(
                    s.id,
                    s.x,
                    s.v,
                    length_of(s, length),
                    s.lane,
                    now.since(s.stamp).as_secs(),
                )
            });
        }
    }

    /// The vehicles in `lane` (each its declared length, or `length`), as the single-lane planner
    /// wants them, into `out` (cleared first; at most `CAP`): every one a wall (Lemma 3),
    /// whatever invariant the planner keeps.
    pub fn lane_vehicles(&self, lane: u8, length: F, out: &mut Vec<Vehicle<F>, CAP>) {
        out.clear();
        for k in self.known.iter().filter(|k| k.state.lane == lane) {
            // Cannot fail: `out` has the same capacity as `known`.
            let _ = out.push(Vehicle::wall(k.state.x, length_of(&k.state, length)));
        }
    }

    /// [`WorldView::lane_vehicles`] for a planner keeping the leader-aware invariant
    /// ([`crate::Invariant::LeaderAware`]): a vehicle that cooperates and declared its
    /// braking limit carries its stamped speed, its limit and the age of its state at
    /// `now`, so the planner may credit it and judge it by its ghost
    /// ([`crate::safety::ghost_advance`]); every other one is a wall. However old the
    /// state: a cooperating leader's stamped state bounds its stopping point forever, and
    /// a follower that came close on that bound must not lose it when the leader falls
    /// silent (docs/spec.md §11, "A credit is never withdrawn").
    pub fn lane_leaders(&self, lane: u8, length: F, now: Instant, out: &mut Vec<Vehicle<F>, CAP>) {
        out.clear();
        for k in self.known.iter().filter(|k| k.state.lane == lane) {
            let s = &k.state;
            // Cannot fail: `out` has the same capacity as `known`.
            let _ = out.push(Vehicle {
                v: s.v,
                brake: s.brake.filter(|_| s.cooperative),
                age: now.since(s.stamp).as_secs(),
                ..Vehicle::wall(s.x, length_of(s, length))
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(id: u16, x: f64, stamp_ms: u64) -> VehicleState<f64> {
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
            stamp: Instant::from_millis(stamp_ms),
            cooperative: true,
            brake: None,
            length: None,
        }
    }

    #[test]
    fn a_declared_length_is_rounded_up_and_used_else_the_assumed_one() {
        let t = |l: f64| BodyLength::from_m(l).map(BodyLength::tenths);
        assert_eq!(t(4.5), Some(45));
        assert_eq!(BodyLength::from_m(4.5f32).map(BodyLength::tenths), Some(45));
        assert_eq!(t(16.51), Some(166));
        assert_eq!(t(0.01), Some(1));
        assert_eq!(t(25.5), Some(255));
        for bad in [0.0, -1.0, 25.6, f64::NAN, f64::INFINITY] {
            assert_eq!(t(bad), None, "{bad}");
        }
        assert_eq!(BodyLength::from_tenths(0), None);
        assert_eq!(
            BodyLength::from_tenths(165).map(|l| l.m::<f64>()),
            Some(16.5)
        );
        let now = Instant::from_millis(0);
        let mut w = WorldView::<f64, 4>::new(7);
        let truck = VehicleState {
            length: BodyLength::from_m(16.5),
            ..msg(1, 50.0, 0)
        };
        w.update(&truck, now).expect("taken");
        w.update(&msg(2, 80.0, 0), now).expect("taken");
        let mut others = Vec::new();
        w.others(now, 6.0, &mut others);
        let lengths: [f64; 2] = [others[0].length, others[1].length];
        assert_eq!(lengths, [16.5, 6.0]);
        let mut lane = Vec::new();
        w.lane_vehicles(0, 6.0, &mut lane);
        assert_eq!([lane[0].length, lane[1].length], [16.5, 6.0]);
        w.lane_leaders(0, 6.0, now, &mut lane);
        assert_eq!([lane[0].length, lane[1].length], [16.5, 6.0]);
    }

    #[test]
    fn keeps_latest_and_rejects_bad_messages() {
        let ms = Instant::from_millis;
        let mut w = WorldView::<f64, 2>::new(7);
        assert_eq!(w.update(&msg(1, 10.0, 0), ms(0)), Ok(()));
        assert_eq!(w.update(&msg(1, 11.0, 10), ms(10)), Ok(()));
        assert_eq!(w.update(&msg(1, 9.0, 10), ms(20)), Err(WorldError::Stale));
        assert_eq!(w.update(&msg(1, 9.0, 5), ms(20)), Err(WorldError::Stale));
        assert_eq!(
            w.update(&msg(7, 9.0, 1000), ms(1000)),
            Err(WorldError::OwnMessage)
        );
        assert_eq!(
            w.update(&msg(2, f64::NAN, 1000), ms(1000)),
            Err(WorldError::NotFinite)
        );
        let mut neg = msg(2, 0.0, 1000);
        neg.v = -1.0;
        assert_eq!(w.update(&neg, ms(1000)), Err(WorldError::NegativeSpeed));
        assert_eq!(w.update(&msg(2, 20.0, 1000), ms(1000)), Ok(()));
        assert_eq!(
            w.update(&msg(3, 30.0, 1000), ms(1000)),
            Err(WorldError::Full)
        );
        assert_eq!(w.len(), 2);
        let x1 = w.iter().find(|k| k.state.id == 1).map(|k| k.state.x);
        assert_eq!(x1, Some(11.0));
        w.forget_older_than(ms(1000), Duration::from_millis(500));
        assert_eq!(w.len(), 1);
        let mut lane = Vec::new();
        w.lane_vehicles(0, 4.5, &mut lane);
        assert_eq!(lane.len(), 1);
    }

    /// A vehicle whose clock has run 60 days, or runs across 2³² ms, takes every fresh
    /// state and sees the same ages, to the bit, as one whose clock starts at zero.
    #[test]
    fn long_uptimes_take_every_fresh_state_with_the_same_ages() {
        fn ages<F: Real>(base: Instant) -> ([F; 100], usize) {
            let mut w = WorldView::<F, 4>::new(9);
            let mut taken = 0;
            let mut out = [F::ZERO; 100];
            let mut others = Vec::<Other<F>, 4>::new();
            for k in 0..100u64 {
                let stamp = base.saturating_add(Duration::from_millis(10 * k));
                let now = stamp.saturating_add(Duration::from_millis(3 + k % 7));
                let s = VehicleState {
                    id: 1,
                    x: F::from_f64(10.0),
                    y: F::ZERO,
                    theta: F::ZERO,
                    v: F::ONE,
                    omega: F::ZERO,
                    lane: 0,
                    alpha: None,
                    beta: None,
                    stamp,
                    cooperative: true,
                    brake: None,
                    length: None,
                };
                taken += usize::from(w.update(&s, now).is_ok());
                w.others(now, F::from_f64(4.5), &mut others);
                out[k as usize] = others.first().map_or(F::ZERO, |o| o.age);
            }
            (out, taken)
        }
        let zero32 = ages::<f32>(Instant::EPOCH);
        let zero64 = ages::<f64>(Instant::EPOCH);
        assert_eq!(zero32.1, 100);
        for base in [
            Instant::from_secs(60 * 86_400),
            Instant::from_millis((1 << 32) - 500),
        ] {
            let (a32, n32) = ages::<f32>(base);
            let (a64, n64) = ages::<f64>(base);
            assert_eq!((n32, n64), (100, 100));
            assert!(a32
                .iter()
                .zip(zero32.0)
                .all(|(a, b)| a.to_bits() == b.to_bits()));
            assert!(a64
                .iter()
                .zip(zero64.0)
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }
}
