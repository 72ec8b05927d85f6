//! The medium vehicles talk over. Every vehicle learns about the others only from what
//! the bus delivers to it. The in-process bus is the default: a broadcast medium with
//! zero delay and no loss, deterministic (delivery in send order); it injects [`Faults`]
//! (loss, delay, jitter, duplication, reordering, a silent vehicle) when a scenario asks.
//!
//! The trait is per node (`send` from a node, `receive` for a node), so a SocketCAN bus,
//! where each node owns a socket, implements it the same way.
//!
//! Receivers keep, per sender and subject, the newest time stamp delivered and drop
//! anything not newer: duplicates and messages overtaken by a newer one (what can-gateway's
//! E2E check does with its alive counter on CAN).

use planner_core::crossing::CrossingReport;
use planner_core::VehicleState;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::fmt;

/// A message on the bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message {
    /// V2V vehicle state, broadcast every period.
    State(VehicleState<f64>),
    /// V2I: a vehicle's position on its intersection route (registers it on arrival,
    /// and tells the other vehicles where it is), with its time stamp.
    Crossing(CrossingReport<f64>, f64),
    /// V2X: vehicle `id` has left the area at `at` (its last position no longer stands).
    Left {
        /// The vehicle.
        id: u16,
        /// When (sender's clock, s).
        at: f64,
    },
    /// I2V: vehicle `id` may enter A_S until `until` (a lease, renewed while held).
    Grant {
        /// The permitted vehicle.
        id: u16,
        /// Lease end (intersection clock, s).
        until: f64,
    },
}

impl Message {
    /// The vehicle the message is about, and its time stamp (sender's clock; a grant's
    /// is its lease end, which grows with every renewal).
    pub fn subject(&self) -> (u16, f64) {
        match *self {
            Message::State(s) => (s.id, s.stamp),
            Message::Crossing(r, stamp) => (r.id, stamp),
            Message::Left { id, at } => (id, at),
            Message::Grant { id, until } => (id, until),
        }
    }
}

/// A delivered message and its receive time (receiver's clock, s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Received {
    /// The message.
    pub msg: Message,
    /// Receive time (s).
    pub at: f64,
}

/// Bus failures.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BusError {
    /// The node is not attached to this bus.
    UnknownNode(u16),
    /// The transport failed (a CAN socket, an encoding).
    Transport(String),
}

impl fmt::Display for BusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UnknownNode(n) => write!(f, "node {n} is not on this bus"),
            Self::Transport(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for BusError {}

/// A broadcast medium.
pub trait Bus {
    /// Broadcasts `msg` from node `from` at time `now` to every other node.
    fn send(&mut self, from: u16, msg: &Message, now: f64) -> Result<(), BusError>;
    /// Appends to `out` everything delivered to `node` by time `now`, in delivery order.
    fn receive(&mut self, node: u16, now: f64, out: &mut Vec<Received>) -> Result<(), BusError>;
    /// What injected faults did (nothing, for a bus that injects none).
    fn fault_stats(&self) -> FaultStats {
        FaultStats::default()
    }
}

/// Faults the in-process bus injects, per message and receiver (scenario `[faults]`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Faults {
    /// Probability that a receiver loses a message.
    pub loss: f64,
    /// Delivery delay (s).
    pub delay_s: f64,
    /// Extra delay drawn uniformly from [0, jitter_s] (s).
    pub jitter_s: f64,
    /// Probability that a receiver gets a message twice (the copy up to `jitter_s` + one
    /// period later).
    pub duplicate: f64,
    /// Probability that a message is held back by `reorder_s`, so later ones overtake it.
    pub reorder: f64,
    /// How long a reordered message is held back (s).
    pub reorder_s: f64,
    /// A vehicle whose transmitter goes silent from a time on (it still receives).
    pub silent: Option<Silent>,
}

/// A vehicle going silent.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Silent {
    /// The vehicle.
    pub id: u16,
    /// From when (s).
    pub from_s: f64,
}

impl Default for Faults {
    fn default() -> Self {
        Self::NONE
    }
}

impl Faults {
    /// A perfect bus.
    pub const NONE: Faults = Faults {
        loss: 0.0,
        delay_s: 0.0,
        jitter_s: 0.0,
        duplicate: 0.0,
        reorder: 0.0,
        reorder_s: 0.02,
        silent: None,
    };

    /// Checks the values: probabilities in [0, 1) (a bus that loses everything carries
    /// nothing), times finite, ≥ 0 and below 1 s.
    pub fn validate(&self) -> Result<(), String> {
        for (name, p) in [
            ("loss", self.loss),
            ("duplicate", self.duplicate),
            ("reorder", self.reorder),
        ] {
            if !(0.0..1.0).contains(&p) {
                return Err(format!("faults.{name} = {p}: must be in [0, 1)"));
            }
        }
        for (name, t) in [
            ("delay_s", self.delay_s),
            ("jitter_s", self.jitter_s),
            ("reorder_s", self.reorder_s),
        ] {
            if !(0.0..1.0).contains(&t) {
                return Err(format!("faults.{name} = {t}: must be in [0, 1) s"));
            }
        }
        if let Some(s) = self.silent {
            if !(s.from_s.is_finite() && s.from_s >= 0.0) {
                return Err(format!("faults.silent.from_s = {}: must be ≥ 0", s.from_s));
            }
        }
        Ok(())
    }

    /// `true` when nothing is injected.
    pub fn is_none(&self) -> bool {
        self.loss == 0.0
            && self.delay_s == 0.0
            && self.jitter_s == 0.0
            && self.duplicate == 0.0
            && self.reorder == 0.0
            && self.silent.is_none()
    }

    /// A bound on the time until a receiver has a message sent now, given period `h`:
    /// delay, jitter and reordering, plus `LOSS_PERIODS` periods of consecutive losses
    /// (the sender repeats its state every period). The lane-change protocol waits this
    /// long after declaring β and inflates (17) by it.
    pub fn notify_bound(&self, h: f64) -> f64 {
        let lost = if self.loss > 0.0 {
            LOSS_PERIODS as f64 * h
        } else {
            0.0
        };
        let held = if self.reorder > 0.0 {
            self.reorder_s
        } else {
            0.0
        };
        h + self.delay_s + self.jitter_s + held + lost
    }
}

/// Consecutive losses of a repeated message the notification bound covers: at 20 % loss,
/// 12 in a row has probability 0.2^12 ≈ 4·10⁻⁹ per message and receiver.
pub const LOSS_PERIODS: u32 = 12;

/// The in-process bus: zero delay, no loss, delivery in send order — unless built
/// [`InProcessBus::with_faults`].
#[derive(Debug, Clone)]
pub struct InProcessBus {
    nodes: Vec<u16>,
    /// Per node, pending deliveries sorted by time (ties in send order).
    queues: Vec<Vec<Received>>,
    /// Per node, newest stamp delivered per (sender, subject).
    newest: Vec<HashMap<(u16, u16), f64>>,
    faults: Faults,
    rng: ChaCha8Rng,
    /// Period h, for duplicate spacing.
    h: f64,
    /// Messages injected faults dropped (lost or silenced), duplicated, held back.
    stats: FaultStats,
}

/// What the injected faults did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FaultStats {
    /// Deliveries lost.
    pub lost: u64,
    /// Messages a silent vehicle did not send.
    pub silenced: u64,
    /// Extra copies delivered.
    pub duplicated: u64,
    /// Deliveries held back for reordering.
    pub reordered: u64,
    /// Deliveries dropped by receivers as duplicate or overtaken.
    pub dropped_old: u64,
}

impl Default for InProcessBus {
    fn default() -> Self {
        Self::new(&[])
    }
}

impl InProcessBus {
    /// A perfect bus with the given nodes attached.
    pub fn new(nodes: &[u16]) -> Self {
        Self::with_faults(nodes, Faults::NONE, 0, 0.01)
    }

    /// A bus injecting `faults` (validated by the caller), drawn from `seed`; `h` is the
    /// period (duplicates arrive up to one period late).
    pub fn with_faults(nodes: &[u16], faults: Faults, seed: u64, h: f64) -> Self {
        Self {
            nodes: nodes.to_vec(),
            queues: nodes.iter().map(|_| Vec::new()).collect(),
            newest: nodes.iter().map(|_| HashMap::new()).collect(),
            faults,
            rng: crate::instances::rng(seed ^ 0xfa17),
            h,
            stats: FaultStats::default(),
        }
    }

    fn index(&self, node: u16) -> Result<usize, BusError> {
        self.nodes
            .iter()
            .position(|&n| n == node)
            .ok_or(BusError::UnknownNode(node))
    }

    fn enqueue(q: &mut Vec<Received>, r: Received) {
        let at = q.partition_point(|p| p.at <= r.at);
        q.insert(at, r);
    }
}

impl Bus for InProcessBus {
    fn fault_stats(&self) -> FaultStats {
        self.stats
    }

    fn send(&mut self, from: u16, msg: &Message, now: f64) -> Result<(), BusError> {
        let me = self.index(from)?;
        let f = self.faults;
        if f.silent.is_some_and(|s| s.id == from && now >= s.from_s) {
            self.stats.silenced += 1;
            return Ok(());
        }
        if f.is_none() {
            for (i, q) in self.queues.iter_mut().enumerate() {
                if i != me {
                    q.push(Received { msg: *msg, at: now });
                }
            }
            return Ok(());
        }
        for i in 0..self.queues.len() {
            if i == me {
                continue;
            }
            if self.rng.random_bool(f.loss) {
                self.stats.lost += 1;
                continue;
            }
            let mut at = now + f.delay_s + self.rng.random_range(0.0..=f.jitter_s);
            if self.rng.random_bool(f.reorder) {
                at += f.reorder_s;
                self.stats.reordered += 1;
            }
            let dup = self.rng.random_bool(f.duplicate);
            let extra = self.rng.random_range(0.0..=f.jitter_s) + self.h;
            if let Some(q) = self.queues.get_mut(i) {
                Self::enqueue(q, Received { msg: *msg, at });
                if dup {
                    self.stats.duplicated += 1;
                    Self::enqueue(
                        q,
                        Received {
                            msg: *msg,
                            at: at + extra,
                        },
                    );
                }
            }
        }
        Ok(())
    }

    fn receive(&mut self, node: u16, now: f64, out: &mut Vec<Received>) -> Result<(), BusError> {
        let i = self.index(node)?;
        let (Some(q), Some(newest)) = (self.queues.get_mut(i), self.newest.get_mut(i)) else {
            return Err(BusError::UnknownNode(node));
        };
        let ready = q.partition_point(|r| r.at <= now);
        if self.faults.is_none() {
            // In order and unique by construction: nothing to drop.
            out.extend(q.drain(..ready));
            return Ok(());
        }
        for r in q.drain(..ready) {
            // Receivers do not know the sender of a broadcast beyond what it says about
            // itself; the subject is the sender for everything but grants (manager → id).
            let (subject, stamp) = r.msg.subject();
            let sender = match r.msg {
                Message::Grant { .. } => u16::MAX,
                _ => subject,
            };
            match newest.get(&(sender, subject)) {
                Some(&last) if !(stamp > last) => self.stats.dropped_old += 1,
                _ => {
                    newest.insert((sender, subject), stamp);
                    out.push(r);
                }
            }
        }
        Ok(())
    }
}
