//! What a fleet run reports: its summary, the latencies and messages it measured, and why
//! it failed.

use super::can::{CanError, CanStats};
use super::intruder::Attack;
use crate::world::summary::Summary;
use serde::Serialize;
use std::fmt;

use super::TIMEOUT;

/// Latency percentiles (µs) from publication to reception, by receive time stamps.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Latency {
    /// Messages measured.
    pub count: u64,
    /// Median (µs).
    pub p50_us: f64,
    /// 99th percentile (µs).
    pub p99_us: f64,
    /// Largest (µs).
    pub max_us: f64,
}

impl Latency {
    /// Percentiles of `v` (µs).
    pub fn of(mut v: Vec<f64>) -> Self {
        if v.is_empty() {
            return Self::default();
        }
        v.sort_by(f64::total_cmp);
        let at = |q: f64| {
            let i = ((v.len() - 1) as f64 * q).round() as usize;
            v.get(i).copied().unwrap_or(0.0)
        };
        Self {
            count: v.len() as u64,
            p50_us: at(0.5),
            p99_us: at(0.99),
            max_us: v.last().copied().unwrap_or(0.0),
        }
    }
}

/// Messages of a fleet run, by kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Messages {
    /// Vehicles' states.
    pub states: u64,
    /// Vehicles' crossing requests.
    pub requests: u64,
    /// Managers' grants.
    pub grants: u64,
    /// Vehicles' exits.
    pub exits: u64,
}

/// What a fleet run produced (the `--json` summary of `run --bus`).
#[derive(Debug, Clone, Serialize)]
pub struct FleetSummary {
    /// The run, as the in-process world reports it.
    #[serde(flatten)]
    pub run: Summary,
    /// The medium (`socketcan:vcan0`, `can-hub`).
    pub medium: String,
    /// Tasks: one per vehicle and per junction manager.
    pub tasks: usize,
    /// Junction managers (each its own node, at 0xF1 + its index).
    pub managers: usize,
    /// Periods run (0 to the last, inclusive).
    pub periods: u64,
    /// SYNC ticks sent.
    pub sync_ticks: u64,
    /// Messages the vehicles and managers sent.
    pub messages: Messages,
    /// Every node's CAN traffic, summed.
    pub can: CanStats,
    /// Every message carried a SecOC-style authenticator, and every node accepted only
    /// those that verified.
    pub authenticated: bool,
    /// Every message went as one CAN FD frame (its authenticator inside).
    pub can_fd: bool,
    /// States: publication (before the first frame is written) to the receiving socket's
    /// time stamp of the last frame.
    pub state_latency: Latency,
    /// Crossing requests, likewise (at managers and vehicles).
    pub request_latency: Latency,
    /// Grants, likewise.
    pub grant_latency: Latency,
    /// SYNC: written by the master to received by the node that acts on it.
    pub sync_latency: Latency,
    /// The intruder's attack and what of it was accepted (attack runs only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub intrusion: Option<Intrusion>,
    /// Grants the managers sent while `[faults.manager_down]` had theirs down (runs with
    /// an outage only; 0 is the only right answer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grants_while_down: Option<u64>,
}

/// An intruder's attack on a fleet run, and what of it the receivers accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Intrusion {
    /// The attack.
    pub attack: Attack,
    /// Messages it wrote (frames, for a flood).
    pub attempts: u64,
    /// Messages receivers accepted that no genuine node sent — forgeries, and copies
    /// beyond the genuine ones (replays) — summed over receivers ([`super::ledger::Ledger`]).
    pub accepted: u64,
}

impl FleetSummary {
    /// One line for a terminal.
    pub fn line(&self) -> String {
        format!(
            "{}: {} tasks, {} periods ({} SYNC ticks); {} states, {} requests, {} grants, {} exits; \
             frames sent {}, received {}, rejected {}; state latency p50 {:.0} µs, p99 {:.0} µs; \
             request latency p50 {:.0} µs, p99 {:.0} µs",
            self.medium,
            self.tasks,
            self.periods,
            self.sync_ticks,
            self.messages.states,
            self.messages.requests,
            self.messages.grants,
            self.messages.exits,
            self.can.frames_sent,
            self.can.frames_received,
            self.can.rejected_total(),
            self.state_latency.p50_us,
            self.state_latency.p99_us,
            self.request_latency.p50_us,
            self.request_latency.p99_us,
        )
    }
}

/// Why a fleet run failed.
#[derive(Debug)]
pub enum FleetError {
    /// Opening a node's port, or the master's traffic.
    Can(CanError),
    /// A vehicle task failed.
    Vehicle {
        /// The vehicle.
        id: u16,
        /// What failed.
        error: String,
    },
    /// The tasks broke the period protocol (a report out of turn, a panicked task).
    Harness(String),
    /// A task did not report within [`TIMEOUT`].
    Timeout {
        /// The period waited for.
        period: u64,
    },
    /// The world cannot run as a fleet (see `host-sim run --bus`).
    Unsupported(String),
}

impl fmt::Display for FleetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Can(e) => write!(f, "{e}"),
            Self::Vehicle { id, error } => write!(f, "vehicle {id}: {error}"),
            Self::Harness(e) => write!(f, "{e}"),
            Self::Timeout { period } => write!(
                f,
                "no report from every task for period {period} within {} s",
                TIMEOUT.as_secs()
            ),
            Self::Unsupported(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for FleetError {}

impl From<CanError> for FleetError {
    fn from(e: CanError) -> Self {
        Self::Can(e)
    }
}
