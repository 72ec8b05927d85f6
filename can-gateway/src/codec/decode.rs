//! Decoding: a verified payload read through its layout ([`crate::layout`]) into a
//! message, its values checked; and who may send what.

use super::quantize::{restore_millis, speed, track_of, StateWire};
use super::{DecodeError, Field};
use crate::layout::{self, byte, get};
use crate::wire::{
    Message, MessageKind, Request, CLOCK_ADDRESS, MANAGER_ADDRESS, MANAGER_LAST, POS_RES,
};
use planner_core::{BodyLength, BrakeLimit, Instant, Real};

/// Decodes a verified payload received at `now`, each field read from its place
/// ([`crate::layout`]), and checks plausibility.
pub(super) fn decode_body<F: Real>(
    kind: MessageKind,
    b: &[u8],
    now: Instant,
) -> Result<Message<F>, DecodeError> {
    let u16_at = |f: layout::Field| u16::from_le_bytes(get(b, f));
    let t = |f: layout::Field| restore_millis(u32::from_le_bytes(get(b, f)), now);
    Ok(match kind {
        MessageKind::State => {
            let (wire, id) = StateWire::read(b, &layout::STATE);
            Message::State(wire.state(id, now)?)
        }
        MessageKind::Located => {
            let (wire, id) = StateWire::read(b, &layout::LOCATED);
            Message::Located {
                segment: u16_at(layout::LOCATED.segment),
                state: wire.state(id, now)?,
            }
        }
        MessageKind::JunctionRequest => Message::JunctionRequest {
            junction: byte(b, layout::JUNCTION_REQUEST.junction),
            request: read_request(b, &layout::JUNCTION_REQUEST, now)?,
        },
        MessageKind::Request => Message::Request(read_request(b, &layout::REQUEST, now)?),
        MessageKind::JunctionExit => Message::JunctionExit {
            junction: byte(b, layout::JUNCTION_EXIT.junction),
            id: u16_at(layout::JUNCTION_EXIT.id),
            at: t(layout::JUNCTION_EXIT.time),
        },
        MessageKind::Grant | MessageKind::Revoke | MessageKind::Exit => {
            let id = u16_at(layout::ID_TIME.id);
            let t = t(layout::ID_TIME.time);
            match kind {
                MessageKind::Grant => Message::Grant { id, until: t },
                MessageKind::Revoke => Message::Revoke { id, at: t },
                _ => Message::Exit { id, at: t },
            }
        }
        MessageKind::Sync => {
            let last = match byte(b, layout::SYNC.last) {
                0 => false,
                1 => true,
                _ => return Err(DecodeError::OutOfRange(Field::Flag)),
            };
            Message::Sync {
                period: u32::from_le_bytes(get(b, layout::SYNC.period)),
                last,
            }
        }
    })
}

/// A request's fields (all but the junction) from their places, its values checked.
fn read_request<F: Real>(
    b: &[u8],
    f: &layout::RequestFields,
    now: Instant,
) -> Result<Request<F>, DecodeError> {
    let (inlet, outlet) = (
        track_of(byte(b, f.inlet.clone()))?,
        track_of(byte(b, f.outlet.clone()))?,
    );
    // u24, zero-extended.
    let s = u32::from_le_bytes(get(b, f.s.clone()));
    Ok(Request {
        id: u16::from_le_bytes(get(b, f.id.clone())),
        inlet,
        outlet,
        arrival: restore_millis(u32::from_le_bytes(get(b, f.arrival.clone())), now),
        s: F::from_f64(f64::from(s) * POS_RES),
        v: F::from_f64(speed(u16::from_le_bytes(get(b, f.speed.clone())))?),
        // Empty fields in a kind 2 request: read as 0, not declared.
        brake: BrakeLimit::from_tenths(byte(b, f.brake.clone())),
        length: BodyLength::from_tenths(byte(b, f.length.clone())),
    })
}

/// Whether `sa` may send `msg`: a vehicle speaks only for itself; permissions come only
/// from an intersection manager (a vehicle cannot grant itself, or another, entry to
/// A_S); ticks only from the time master.
pub(super) fn sender_ok<F>(msg: &Message<F>, sa: u8) -> bool {
    match msg {
        Message::State(s) | Message::Located { state: s, .. } => s.id & 0xFF == u16::from(sa),
        Message::Request(r) | Message::JunctionRequest { request: r, .. } => {
            r.id & 0xFF == u16::from(sa)
        }
        Message::Exit { id, .. } | Message::JunctionExit { id, .. } => id & 0xFF == u16::from(sa),
        Message::Grant { .. } | Message::Revoke { .. } => {
            (MANAGER_ADDRESS..=MANAGER_LAST).contains(&sa)
        }
        Message::Sync { .. } => sa == CLOCK_ADDRESS,
    }
}
