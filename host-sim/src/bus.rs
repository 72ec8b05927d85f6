//! The medium vehicles talk over. Every vehicle learns about the others only from what
//! the bus delivers to it. The in-process bus is the default: a broadcast medium with
//! zero delay and no loss, deterministic (delivery in send order).
//!
//! The trait is per node (`send` from a node, `receive` for a node), so a SocketCAN bus,
//! where each node owns a socket, implements it the same way.

use planner_core::crossing::CrossingReport;
use planner_core::VehicleState;
use std::collections::VecDeque;
use std::fmt;

/// A message on the bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message {
    /// V2V vehicle state, broadcast every period.
    State(VehicleState<f64>),
    /// V2I: a vehicle's position on its intersection route (registers it on arrival,
    /// and tells the other vehicles where it is), with its time stamp.
    Crossing(CrossingReport<f64>, f64),
    /// V2X: vehicle `id` has left the area (its last position no longer stands).
    Left {
        /// The vehicle.
        id: u16,
    },
    /// I2V: vehicle `id` may enter A_S until `until` (a lease, renewed while held).
    Grant {
        /// The permitted vehicle.
        id: u16,
        /// Lease end (intersection clock, s).
        until: f64,
    },
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
}

impl fmt::Display for BusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UnknownNode(n) => write!(f, "node {n} is not on this bus"),
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
}

/// The in-process bus: zero delay, no loss, delivery in send order.
#[derive(Debug, Clone, Default)]
pub struct InProcessBus {
    nodes: Vec<u16>,
    queues: Vec<VecDeque<Received>>,
}

impl InProcessBus {
    /// A bus with the given nodes attached.
    pub fn new(nodes: &[u16]) -> Self {
        Self {
            nodes: nodes.to_vec(),
            queues: nodes.iter().map(|_| VecDeque::new()).collect(),
        }
    }

    fn index(&self, node: u16) -> Result<usize, BusError> {
        self.nodes
            .iter()
            .position(|&n| n == node)
            .ok_or(BusError::UnknownNode(node))
    }
}

impl Bus for InProcessBus {
    fn send(&mut self, from: u16, msg: &Message, now: f64) -> Result<(), BusError> {
        let me = self.index(from)?;
        for (i, q) in self.queues.iter_mut().enumerate() {
            if i != me {
                q.push_back(Received { msg: *msg, at: now });
            }
        }
        Ok(())
    }

    fn receive(&mut self, node: u16, now: f64, out: &mut Vec<Received>) -> Result<(), BusError> {
        let i = self.index(node)?;
        let q = &mut self.queues[i];
        while q.front().is_some_and(|r| r.at <= now) {
            if let Some(r) = q.pop_front() {
                out.push(r);
            }
        }
        Ok(())
    }
}
