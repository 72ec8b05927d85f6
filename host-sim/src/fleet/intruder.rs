//! An intruder on the fleet's bus: a node that is not the fleet's — or a
//! vehicle's node that has been taken over — writing what a genuine node would not.
//!
//! It holds a port on the same medium and, if the fleet authenticates, one key: its own
//! address's, as a compromised vehicle node would (it has no manager's key and no other
//! vehicle's). It acts once per period, after the managers have granted and before the
//! vehicles plan, so that what it writes reaches every receiver in the period it means
//! to confuse:
//!
//! - [`Attack::ForgedGrant`]: grants under each manager's address, for every vehicle;
//! - [`Attack::ReplayedGrant`], [`Attack::ReplayedState`]: the genuine grants (states and
//!   crossing requests) it heard one period and a second earlier, written again byte
//!   for byte — inside and outside the receivers' freshness window;
//! - [`Attack::SpoofedId`]: each vehicle's state under that vehicle's address and id,
//!   [`SPOOF_AHEAD_M`] further on than it is (it sees the road as a roadside observer
//!   would: the vehicles' true places), stamped newer than the genuine one;
//! - [`Attack::Flood`]: frames of the highest priority (identifier 0), four for every
//!   frame the fleet sent in the period — [`FLOOD_SHARE`] of the frames on the bus. (The
//!   hub and vcan have no bit rate to saturate; on a real bus these frames would win
//!   every arbitration, and the fleet's own load decides whether the rest still fits.)
//!
//! What of it the receivers accepted, the [`super::ledger::Ledger`] counts.

use super::can::{vehicle_address, CanError, CanPort, WireMap};
use crate::world::at::At;
use crate::world::vehicle::{announce, VehicleTruth};
use can_gateway::codec::{encode_fd_secured, encode_secured, SecuredFrames};
use can_gateway::secoc::{FreshnessTx, Key};
use can_gateway::wire::{self, MessageKind};
use can_gateway::{encode, encode_fd, FdFrame, Frames, PlainFrame};
use embedded_can::{ExtendedId, Frame, Id};
use serde::Serialize;
use std::collections::VecDeque;
use std::fmt;
use std::time::Duration;

/// The intruder's source address: a vehicle address no scenario vehicle may hold in an
/// attack run (the fleet refuses one that does).
pub const INTRUDER_ADDRESS: u8 = 0xEF;
/// How much further on a spoofed vehicle is claimed to be (m): room that is not there.
pub const SPOOF_AHEAD_M: f64 = 20.0;
/// Replays: frames heard this many periods earlier are written again (one period, 10 ms:
/// inside the receivers' 500 ms freshness window; a hundred, 1 s: outside it).
pub const REPLAY_AFTER: [u64; 2] = [1, 100];
/// The flood's share of the frames on the bus.
pub const FLOOD_SHARE: f64 = 0.8;
/// Most frames the intruder reads in one period before it acts.
const READ_LIMIT: usize = 1 << 20;

/// An attack of the intruder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Attack {
    /// Grants under a manager's address from a vehicle node.
    ForgedGrant,
    /// Genuine grants written again later.
    ReplayedGrant,
    /// Genuine states and crossing requests written again later.
    ReplayedState,
    /// Another vehicle's identity claimed, with a place it is not at.
    SpoofedId,
    /// The bus filled with frames of the highest priority.
    Flood,
}

impl Attack {
    /// Every attack.
    pub const ALL: [Attack; 5] = [
        Self::ForgedGrant,
        Self::ReplayedGrant,
        Self::ReplayedState,
        Self::SpoofedId,
        Self::Flood,
    ];

    /// Its name (as in the experiment's JSON).
    pub fn name(self) -> &'static str {
        match self {
            Self::ForgedGrant => "forged-grant",
            Self::ReplayedGrant => "replayed-grant",
            Self::ReplayedState => "replayed-state",
            Self::SpoofedId => "spoofed-id",
            Self::Flood => "flood",
        }
    }

    /// Frames it records for replay: grants, or vehicles' states and requests.
    fn records(self, kind: u8) -> bool {
        let grants = [MessageKind::Grant as u8];
        let states = [
            MessageKind::State as u8,
            MessageKind::Request as u8,
            MessageKind::Located as u8,
            MessageKind::JunctionRequest as u8,
        ];
        match self {
            Self::ReplayedGrant => grants.contains(&kind),
            Self::ReplayedState => states.contains(&kind),
            _ => false,
        }
    }
}

impl fmt::Display for Attack {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Frames of the flood in a period in which the fleet sent `genuine`: [`FLOOD_SHARE`] of
/// the period's frames.
pub fn flood_frames(genuine: u64) -> u64 {
    (genuine as f64 * FLOOD_SHARE / (1.0 - FLOOD_SHARE)).round() as u64
}

/// The intruder's node.
pub struct Intruder<P> {
    attack: Attack,
    port: P,
    /// Its own key, when the fleet authenticates.
    key: Option<Key>,
    fd: bool,
    fresh: FreshnessTx,
    counters: [u8; 16],
    /// Frames heard, with the period they were heard in (only those it may replay).
    heard: VecDeque<(u64, FdFrame)>,
    /// The first period it acts in.
    from: u64,
    /// Messages (frames, for the flood) it wrote.
    attempts: u64,
    /// State of its noise for the flood's data.
    noise: u64,
}

impl<P: CanPort> Intruder<P> {
    /// An intruder carrying out `attack` on `port` from period `from`, holding `key` (its
    /// own address's) when the fleet authenticates, and writing CAN FD frames when `fd`.
    pub fn new(attack: Attack, port: P, key: Option<Key>, fd: bool, from: u64) -> Self {
        Self {
            attack,
            port,
            key,
            fd,
            fresh: FreshnessTx::new(),
            counters: [0; 16],
            heard: VecDeque::new(),
            from,
            attempts: 0,
            noise: 0x9E37_79B9_7F4A_7C15,
        }
    }

    /// Its attack.
    pub fn attack(&self) -> Attack {
        self.attack
    }

    /// Messages (frames, for the flood) it has written.
    pub fn attempts(&self) -> u64 {
        self.attempts
    }

    /// Period `k` (its clock reading `now`, period `h` s): it reads what the bus carried,
    /// then attacks (`present`: the vehicles as it sees them; `junctions`: how many
    /// managers).
    pub fn act(
        &mut self,
        (k, now, h): (u64, planner_core::Instant, f64),
        present: &[VehicleTruth],
        map: &WireMap<'_>,
        junctions: usize,
    ) -> Result<(), CanError> {
        let heard = self.listen(k)?;
        if k < self.from {
            return Ok(());
        }
        let now_ms = now.as_millis();
        let later = |s: f64| {
            now.saturating_add(planner_core::Duration::from_secs_real(s).unwrap_or_default())
        };
        match self.attack {
            Attack::ForgedGrant => {
                for j in 0..junctions.max(1) {
                    let sa = map.manager_address(j)?;
                    for v in present {
                        let grant = wire::Message::Grant {
                            id: v.id,
                            until: later(5.0),
                        };
                        self.write(&grant, sa, now_ms)?;
                    }
                }
            }
            Attack::ReplayedGrant | Attack::ReplayedState => self.replay(k)?,
            Attack::SpoofedId => {
                for v in present {
                    let claimed = announce(
                        (v.id, v.body),
                        ahead(v.at),
                        (v.v, 0.0),
                        true,
                        later(h / 2.0),
                    );
                    let msg = map.to_wire(&claimed, now)?;
                    self.write(&msg, vehicle_address(v.id)?, now_ms)?;
                }
            }
            Attack::Flood => self.flood(heard)?,
        }
        Ok(())
    }

    /// Reads every frame queued at its port, keeping those it may replay; how many.
    fn listen(&mut self, k: u64) -> Result<u64, CanError> {
        let mut heard = 0;
        for _ in 0..READ_LIMIT {
            let Some((frame, _)) = self.port.receive(Duration::ZERO)? else {
                break;
            };
            heard += 1;
            let kind = match frame.id() {
                Id::Extended(x) => wire::split_id(x.as_raw()).map(|(kind, _, _)| kind),
                Id::Standard(_) => None,
            };
            if kind.is_some_and(|c| self.attack.records(c)) {
                self.heard.push_back((k, frame));
            }
        }
        let oldest = REPLAY_AFTER.iter().max().copied().unwrap_or(0);
        while self.heard.front().is_some_and(|&(p, _)| p + oldest < k) {
            self.heard.pop_front();
        }
        Ok(heard)
    }

    /// Writes again, byte for byte, the frames heard [`REPLAY_AFTER`] periods ago.
    fn replay(&mut self, k: u64) -> Result<(), CanError> {
        let old: Vec<FdFrame> = self
            .heard
            .iter()
            .filter(|&&(p, _)| REPLAY_AFTER.iter().any(|&r| p + r == k))
            .map(|&(_, f)| f)
            .collect();
        for f in &old {
            self.port.transmit(f)?;
            // A message's first frame counts it (a CAN FD frame is a whole message).
            let whole = [0, wire::FD_INDEX, wire::FD_SECURED_INDEX];
            if let Id::Extended(x) = f.id() {
                if wire::split_id(x.as_raw()).is_some_and(|(_, i, _)| whole.contains(&i)) {
                    self.attempts += 1;
                }
            }
        }
        Ok(())
    }

    /// Writes one period's flood, `genuine` being the frames the fleet sent in it:
    /// identifier 0 wins every arbitration.
    fn flood(&mut self, genuine: u64) -> Result<(), CanError> {
        let id = ExtendedId::new(0).ok_or(CanError::Unmapped("identifier 0"))?;
        for _ in 0..flood_frames(genuine) {
            // xorshift: data that changes from frame to frame.
            self.noise ^= self.noise << 13;
            self.noise ^= self.noise >> 7;
            self.noise ^= self.noise << 17;
            let frame = FdFrame::new(id, &self.noise.to_le_bytes())
                .ok_or(CanError::Unmapped("an 8-byte frame"))?;
            self.port.transmit(&frame)?;
            self.attempts += 1;
        }
        Ok(())
    }

    /// Encodes `msg` under source address `sa` — authenticated with its own key, which
    /// is not `sa`'s — and writes it.
    fn write(&mut self, msg: &wire::Message<f64>, sa: u8, now_ms: u64) -> Result<(), CanError> {
        let k = msg.kind() as usize;
        let counter = self.counters.get(k).copied().unwrap_or(0);
        let frames: Vec<FdFrame> = match (self.key, self.fd) {
            (None, true) => vec![encode_fd(msg, sa, counter).map_err(CanError::Encode)?],
            (None, false) => {
                let f: Frames<PlainFrame> = encode(msg, sa, counter).map_err(CanError::Encode)?;
                f.iter().map(|&p| p.into()).collect()
            }
            (Some(key), true) => {
                let fv = self.fresh.next(msg.kind() as u8, now_ms);
                let f = encode_fd_secured(msg, sa, counter, &key, fv).map_err(CanError::Encode)?;
                vec![f]
            }
            (Some(key), false) => {
                let fv = self.fresh.next(msg.kind() as u8, now_ms);
                let f: SecuredFrames<PlainFrame> =
                    encode_secured(msg, sa, counter, &key, fv).map_err(CanError::Encode)?;
                f.iter().map(|&p| p.into()).collect()
            }
        };
        for f in &frames {
            self.port.transmit(f)?;
        }
        if let Some(c) = self.counters.get_mut(k) {
            *c = (counter + 1) & 0x0F;
        }
        self.attempts += 1;
        Ok(())
    }
}

/// `at` moved [`SPOOF_AHEAD_M`] further along its lane or route.
fn ahead(mut at: At) -> At {
    match &mut at {
        At::Lane { x, .. } => *x += SPOOF_AHEAD_M,
        At::Crossing { s, .. } => *s += SPOOF_AHEAD_M,
    }
    at
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flood_takes_its_share_of_the_frames() {
        // Four of every five frames on the bus.
        assert_eq!(flood_frames(0), 0);
        assert_eq!(flood_frames(25), 100);
        assert_eq!(flood_frames(26) as f64 / (26.0 + 104.0), 0.8);
    }
}
