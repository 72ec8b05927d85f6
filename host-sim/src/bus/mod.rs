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
use planner_core::VehicleState;
use std::fmt;

/// The bus node of junction `j`'s manager (vehicle ids stay below it).
pub fn manager_node(j: usize) -> u16 {
    0xFF00 | (j as u16 & 0xFF)
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
        /// Sender's time stamp (s).
        stamp: f64,
        /// The junction (index).
        junction: usize,
    },
    /// V2X: vehicle `id` has left junction `junction` at `at` (its last report there no
    /// longer stands).
    Left {
        /// The vehicle.
        id: u16,
        /// When (sender's clock, s).
        at: f64,
        /// The junction (index).
        junction: usize,
    },
    /// V2V: vehicle `id` left the network at an exit at `at`: nothing it said up to then
    /// stands any more (its followers must not go on braking for where it last was).
    Gone {
        /// The vehicle.
        id: u16,
        /// When (sender's clock, s).
        at: f64,
    },
    /// I2V: vehicle `id` may enter junction `junction`'s A_S until `until` (a lease,
    /// renewed while held).
    Grant {
        /// The junction (index).
        junction: usize,
        /// The permitted vehicle.
        id: u16,
        /// Lease end (intersection clock, s).
        until: f64,
    },
}

impl Message {
    /// What a vehicle `id` says at `at` when it leaves junction `from`, or the network
    /// (`None`).
    pub fn departure(id: u16, at: f64, from: Option<usize>) -> Message {
        match from {
            Some(junction) => Message::Left { id, at, junction },
            None => Message::Gone { id, at },
        }
    }

    /// The vehicle the message is about, and its time stamp (sender's clock; a grant's
    /// is its lease end, which grows with every renewal).
    pub fn subject(&self) -> (u16, f64) {
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
    /// Attaches node `node` (a vehicle entering the world); nothing if it is attached.
    fn attach(&mut self, node: u16) -> Result<(), BusError>;
    /// Detaches node `node` (a vehicle leaving the world): what was still on its way to it
    /// is dropped, so an open world's memory stays bounded by the vehicles in it.
    fn detach(&mut self, node: u16);
}
