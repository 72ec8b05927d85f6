//! The medium vehicles talk over: the [`Bus`] trait, its messages and node addresses; the
//! in-process bus with injected [`faults`]. CAN media and the fleet of tasks on them are
//! in [`crate::fleet`], which builds on this and on the world.
//!
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

pub mod faults;
pub mod inprocess;

pub use faults::{FaultStats, Faults, Liar, ManagerDown, Silent, LOSS_PERIODS};
pub use inprocess::InProcessBus;
use planner_core::crossing::CrossingReport;
use planner_core::{Instant, VehicleState};
use std::fmt;

/// Every node's clock in a simulated world ([`planner_core::time`]): the same for all
/// nodes (their clock error ε is zero), starting at `start` (`host-sim run
/// --clock-start`: an uptime of days, or one just before the wire's 32-bit milliseconds
/// wrap) and advancing by the period h each step. The world's own time — what traces,
/// plots and fault schedules are written in — is seconds since the run began; a node's
/// clock is that plus `start`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Clock {
    /// What every clock reads when the run begins.
    pub start: Instant,
    /// The period h (µs).
    pub period_us: u64,
}

impl Clock {
    /// Clocks starting at `start`, with period `h` (s).
    pub fn new(start: Instant, h: f64) -> Self {
        Self {
            start,
            period_us: (h * 1e6).round() as u64,
        }
    }

    /// The clocks' reading after `steps` periods.
    pub fn at_step(&self, steps: u64) -> Instant {
        self.start
            .saturating_add(planner_core::Duration::from_micros(
                steps.saturating_mul(self.period_us),
            ))
    }

    /// The world's time (s since the run began) of a clock reading.
    pub fn world_secs(&self, t: Instant) -> f64 {
        t.since(self.start).as_secs::<f64>()
    }

    /// The clock reading at world time `t` (s since the run began), to the microsecond.
    pub fn at_secs(&self, t: f64) -> Instant {
        self.start
            .saturating_add(planner_core::Duration::from_secs_real(t.max(0.0)).unwrap_or_default())
    }
}

/// The first node address of the junction managers: 0xFF00 to 0xFFFF are theirs.
pub const FIRST_MANAGER_NODE: u16 = 0xFF00;

/// The bus node of junction `j`'s manager (vehicle ids stay below it).
pub fn manager_node(j: usize) -> u16 {
    FIRST_MANAGER_NODE | (j as u16 & 0xFF)
}

/// `true` if `id` can be a vehicle's: 1 to 65,279 (0 is no one's; from 0xFF00 on the
/// junction managers' nodes).
pub fn is_vehicle_id(id: u16) -> bool {
    id != 0 && id < FIRST_MANAGER_NODE
}

/// A message on the bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message {
    /// V2V vehicle state on a segment (in its frame), broadcast every period.
    State {
        /// The state.
        state: VehicleState<f64>,
        /// The segment (index) whose frame it is in.
        segment: usize,
    },
    /// V2I: a vehicle's position on its route at a junction (registers it on arrival,
    /// and tells the other vehicles where it is), with its time stamp.
    Crossing {
        /// The report.
        report: CrossingReport<f64>,
        /// Sender's time stamp.
        stamp: Instant,
        /// The junction (index).
        junction: usize,
    },
    /// V2X: vehicle `id` has left junction `junction` at `at` (its last report there no
    /// longer stands).
    Left {
        /// The vehicle.
        id: u16,
        /// When (sender's clock).
        at: Instant,
        /// The junction (index).
        junction: usize,
    },
    /// V2V: vehicle `id` left the network at an exit at `at`: nothing it said up to then
    /// stands any more (its followers must not go on braking for where it last was).
    Gone {
        /// The vehicle.
        id: u16,
        /// When (sender's clock).
        at: Instant,
    },
    /// I2V: vehicle `id` may enter junction `junction`'s A_S until `until` (a lease,
    /// renewed while held).
    Grant {
        /// The junction (index).
        junction: usize,
        /// The permitted vehicle.
        id: u16,
        /// Lease end (intersection clock).
        until: Instant,
    },
}

impl Message {
    /// What a vehicle `id` says at `at` when it leaves junction `from`, or the network
    /// (`None`).
    pub fn departure(id: u16, at: Instant, from: Option<usize>) -> Message {
        match from {
            Some(junction) => Message::Left { id, at, junction },
            None => Message::Gone { id, at },
        }
    }

    /// The vehicle the message is about, and its time stamp (sender's clock; a grant's
    /// is its lease end, which grows with every renewal).
    pub fn subject(&self) -> (u16, Instant) {
        match *self {
            Message::State { state, .. } => (state.id, state.stamp),
            Message::Crossing { report, stamp, .. } => (report.id, stamp),
            Message::Left { id, at, .. } | Message::Gone { id, at } => (id, at),
            Message::Grant { id, until, .. } => (id, until),
        }
    }

    /// Who sent it, as far as a receiver can tell: the subject, but for a grant, which a
    /// junction's manager sends.
    pub fn sender(&self) -> u16 {
        match *self {
            Message::Grant { junction, .. } => manager_node(junction),
            _ => self.subject().0,
        }
    }
}

/// A delivered message and when the medium delivers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Received {
    /// The message.
    pub msg: Message,
    /// Delivery time, in the world's time (s since the run began): the medium's
    /// bookkeeping, not a node's clock.
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
    /// Attaches node `node` (a vehicle entering the world); nothing if it is attached.
    fn attach(&mut self, node: u16) -> Result<(), BusError>;
    /// Detaches node `node` (a vehicle leaving the world): what was still on its way to it
    /// is dropped, so an open world's memory stays bounded by the vehicles in it.
    fn detach(&mut self, node: u16);
    /// Node `node` is at (`x`, `y`) in the world now (a radio medium reaches only so far;
    /// a bus that reaches every node ignores it).
    fn locate(&mut self, _node: u16, _x: f64, _y: f64) {}
}
