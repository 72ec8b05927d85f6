//! The gateway's cost per message as a fleet pays it ("the fleet's frames/s with
//! and without" authentication): one node encodes — and signs — a stream of vehicle
//! states, the in-process hub carries the frames, another node reassembles — and
//! verifies — them. Four configurations, one after the other in the same process:
//! classic CAN, classic CAN + SecOC, CAN FD, CAN FD + SecOC (`host-sim bench-can`).

use super::can::{simulation_keys, CanError, CanNode, Hub, HubPort, Keys};
use can_gateway::secoc::Key;
use can_gateway::wire;
use planner_core::{Instant as At, VehicleState};
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

/// One configuration's figures.
#[derive(Debug, Clone, Serialize)]
pub struct Throughput {
    /// "classic", "classic+secoc", "fd" or "fd+secoc".
    pub config: &'static str,
    /// Messages sent.
    pub messages: u64,
    /// Of those, received and (with SecOC) verified.
    pub received: u64,
    /// Frames on the bus.
    pub frames: u64,
    /// Wall time (s).
    pub seconds: f64,
    /// Messages sent, carried and accepted per second.
    pub messages_per_s: f64,
    /// Frames per second.
    pub frames_per_s: f64,
}

/// Vehicles on the bus, each sending one state per period.
pub const SENDERS: u8 = 40;

/// Vehicle `sa`'s state on a two-lane road at `now` (a State names its sender; every
/// field within its wire range and changing from period to period as a real stream does).
fn state(sa: u8, now: At) -> wire::Message<f64> {
    let i = f64::from(sa);
    let t = now.as_micros() as f64 * 1e-6;
    wire::Message::State(VehicleState {
        id: u16::from(sa),
        x: 10.0 * i + 20.0 * t,
        y: 1.8 + 3.6 * f64::from(sa % 2),
        theta: 0.001 * i,
        v: 20.0 - 0.1 * i,
        omega: 0.0,
        lane: sa % 2,
        alpha: None,
        beta: None,
        stamp: now,
        cooperative: true,
        brake: None,
        length: None,
    })
}

/// A node on `hub`, as the fleet builds it.
fn node(sa: u8, hub: &Hub, fd: bool, keys: Option<&Arc<Keys>>) -> CanNode<HubPort> {
    let n = CanNode::new(sa, hub.port());
    let n = if fd { n.with_fd() } else { n };
    match keys {
        Some(k) => n.with_keys(k.clone()),
        None => n,
    }
}

/// Sends `messages` states, [`SENDERS`] per 10 ms period, to one receiving node in
/// configuration (`fd`, `secured`), and times it all: encoding (and signing), the hub,
/// reassembly (and verification).
pub fn measure(messages: u64, fd: bool, secured: bool) -> Result<Throughput, CanError> {
    let keys = secured.then(|| Arc::new(simulation_keys(&Key([0x5A; 16]))));
    let hub = Hub::new();
    let mut rx = node(0xE0, &hub, fd, keys.as_ref());
    let mut tx: Vec<_> = (1..=SENDERS)
        .map(|sa| node(sa, &hub, fd, keys.as_ref()))
        .collect();
    let mut received = 0;
    let start = Instant::now();
    for k in 0..messages {
        let now = At::from_millis(10 * (k / u64::from(SENDERS)));
        let i = (k % u64::from(SENDERS)) as usize;
        rx.set_time(now);
        if let Some(n) = tx.get_mut(i) {
            n.set_time(now);
            n.send_wire(&state(i as u8 + 1, now))?;
        }
        rx.drain(|_, _| received += 1)?;
    }
    let seconds = start.elapsed().as_secs_f64();
    let frames = tx.iter().map(|n| n.stats().frames_sent).sum();
    let config = match (fd, secured) {
        (false, false) => "classic",
        (false, true) => "classic+secoc",
        (true, false) => "fd",
        (true, true) => "fd+secoc",
    };
    Ok(Throughput {
        config,
        messages,
        received,
        frames,
        seconds,
        messages_per_s: messages as f64 / seconds,
        frames_per_s: frames as f64 / seconds,
    })
}
