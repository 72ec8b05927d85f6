//! Decoding: a verified payload read through its layout ([`crate::layout`]) into a
//! message, its values checked; and who may send what.

use super::quantize::{lane, restore_millis, speed, track_of, StateWire};
use super::{DecodeError, Field};
use crate::layout::{self, byte, get};
use crate::wire::{
    Command, CommandStatus, Message, MessageKind, Request, CLOCK_ADDRESS, MANAGER_ADDRESS,
    MANAGER_LAST, POS_RES, SPEED_LIMIT,
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
        MessageKind::Ego => {
            let (wire, id) = StateWire::read(b, &layout::EGO.state);
            let lanes = byte(b, layout::EGO.road_lanes);
            if !(1..crate::wire::NO_LANE).contains(&lanes) {
                return Err(DecodeError::OutOfRange(Field::Lane));
            }
            Message::Ego {
                segment: u16_at(layout::EGO.state.segment),
                lanes,
                state: wire.state(id, now)?,
                v_ref: F::from_f64(speed(u16_at(layout::EGO.v_ref))?),
            }
        }
        MessageKind::Command => Message::Command(read_command(b)?),
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

/// The most yaw rate a command may carry (rad/s): a full turn per second, far beyond
/// what any vehicle's limits allow, so only garbage is refused.
const COMMAND_YAW_LIMIT: f32 = 2.0 * core::f32::consts::PI;

/// A command's fields from their places, its values checked.
fn read_command<F: Real>(b: &[u8]) -> Result<Command<F>, DecodeError> {
    let f = layout::COMMAND;
    let v = f32::from_le_bytes(get(b, f.speed));
    // Plausible: finite, not reversing (a rounding's −0 aside), below the speed limit.
    if !(v.is_finite() && v >= 0.0 && f64::from(v) <= SPEED_LIMIT) {
        return Err(DecodeError::OutOfRange(Field::Speed));
    }
    let omega = f32::from_le_bytes(get(b, f.yaw));
    if !(omega.is_finite() && omega.abs() <= COMMAND_YAW_LIMIT) {
        return Err(DecodeError::OutOfRange(Field::YawRate));
    }
    let status =
        CommandStatus::from_code(byte(b, f.status)).ok_or(DecodeError::OutOfRange(Field::Flag))?;
    let lanes = byte(b, f.lanes);
    let lane = lane(lanes & 0x0F).ok_or(DecodeError::OutOfRange(Field::Lane))?;
    let beta = byte(b, f.beta);
    if beta & 0xF0 != 0 {
        return Err(DecodeError::OutOfRange(Field::Flag));
    }
    Ok(Command {
        period: u16::from_le_bytes(get(b, f.period)),
        v: F::from_f64(f64::from(v)),
        omega: F::from_f64(f64::from(omega)),
        status,
        lane,
        alpha: super::quantize::lane(lanes >> 4),
        beta: super::quantize::lane(beta),
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
/// A_S); ticks and ego states only from the time master.
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
        // The ego state comes from the vehicle's own sensing: in simulation, the world,
        // which speaks from the time master's address.
        Message::Sync { .. } | Message::Ego { .. } => sa == CLOCK_ADDRESS,
        // A command is its sender's own (it names no vehicle): any vehicle address.
        Message::Command(_) => sa < CLOCK_ADDRESS,
    }
}
