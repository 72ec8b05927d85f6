//! What each field carries, in its units: a message's numbers quantised to the wire's
//! resolutions ([`crate::wire`]) on the way out, and checked for plausibility on the way
//! in; a vehicle state's fields ([`StateWire`]) written into and read from their places
//! ([`crate::layout`]).

use super::{DecodeError, EncodeError, Field, NOT_COOPERATIVE};
use crate::layout::{byte, get, put, StateFields};
use crate::wire::{TrackWire, HEADING_RES, NO_LANE, POS_RES, SPEED_LIMIT, SPEED_RES, YAW_RATE_RES};
use planner_core::{Instant, Real, VehicleState};

pub(super) fn q<F: Real>(
    x: F,
    res: f64,
    lo: f64,
    hi: f64,
    field: Field,
) -> Result<i64, EncodeError> {
    let v = x.to_f64() / res;
    if !(v.is_finite() && v >= lo && v <= hi) {
        return Err(EncodeError::OutOfRange(field));
    }
    // Round half away from zero without std.
    Ok(if v >= 0.0 {
        (v + 0.5) as i64
    } else {
        (v - 0.5) as i64
    })
}

pub(super) fn lane_nibble(l: Option<u8>) -> Result<u8, EncodeError> {
    match l {
        None => Ok(NO_LANE),
        Some(x) if x < NO_LANE => Ok(x),
        Some(_) => Err(EncodeError::OutOfRange(Field::Lane)),
    }
}

/// A time as the wire carries it: the low 32 bits of its milliseconds ([`crate::wire`]).
pub(super) fn time(t: Instant) -> u32 {
    t.as_millis() as u32
}

/// A track as its byte: heading in the low nibble, lane in the high one.
pub(super) fn track(t: TrackWire) -> Result<u8, EncodeError> {
    if t.heading < 4 && t.lane < 16 {
        Ok(t.heading | t.lane << 4)
    } else {
        Err(EncodeError::OutOfRange(Field::TrackHeading))
    }
}

/// A position along a path, 0.01 m in 24 bits.
pub(super) fn path_position<F: Real>(s: F) -> Result<u32, EncodeError> {
    Ok(q(
        s,
        POS_RES,
        0.0,
        f64::from(0xFF_FFFFu32),
        Field::PathPosition,
    )? as u32)
}

/// A state's fields, quantized (the same for [`Message::State`] and
/// [`Message::Located`]; only their places differ).
pub(super) struct StateWire {
    pub(super) x: i32,
    pub(super) y: i16,
    pub(super) heading: i16,
    pub(super) speed: u16,
    pub(super) yaw: i16,
    pub(super) lanes: u8,
    pub(super) beta_flags: u8,
    pub(super) stamp: u32,
    /// The braking limit in tenths of m/s² (0: not declared).
    pub(super) brake: u8,
    /// The length in tenths of a metre (0: not declared).
    pub(super) length: u8,
}

impl StateWire {
    pub(super) fn of<F: Real>(s: &VehicleState<F>) -> Result<Self, EncodeError> {
        let pi = core::f64::consts::PI;
        let th = s.theta.to_f64();
        // Wrap into [−π, π) so any heading fits the i16 field (π itself goes out as −π).
        let th = th - 2.0 * pi * libm_floor((th + pi) / (2.0 * pi));
        // β in the low nibble; flags in the high one (bit 4: does not cooperate).
        let flags = if s.cooperative { 0 } else { NOT_COOPERATIVE };
        Ok(Self {
            x: q(
                s.x,
                POS_RES,
                f64::from(i32::MIN),
                f64::from(i32::MAX),
                Field::X,
            )? as i32,
            y: q(s.y, POS_RES, -32768.0, 32767.0, Field::Y)? as i16,
            heading: q(
                F::from_f64(th),
                HEADING_RES,
                -32768.0,
                32767.0,
                Field::Heading,
            )? as i16,
            speed: q(s.v, SPEED_RES, 0.0, 65535.0, Field::Speed)? as u16,
            yaw: q(s.omega, YAW_RATE_RES, -32768.0, 32767.0, Field::YawRate)? as i16,
            lanes: lane_nibble(Some(s.lane))? | lane_nibble(s.alpha)? << 4,
            beta_flags: lane_nibble(s.beta)? | flags,
            stamp: time(s.stamp),
            brake: s.brake.map_or(0, planner_core::BrakeLimit::tenths),
            length: s.length.map_or(0, planner_core::BodyLength::tenths),
        })
    }

    /// Writes these fields and vehicle `id` into their places in `b` (the segment is the
    /// caller's); the layout's length.
    pub(super) fn write(&self, b: &mut [u8], f: &StateFields, id: u16) -> usize {
        put(b, f.id.clone(), &id.to_le_bytes());
        put(b, f.x.clone(), &self.x.to_le_bytes());
        put(b, f.lanes.clone(), &[self.lanes]);
        put(b, f.y.clone(), &self.y.to_le_bytes());
        put(b, f.heading.clone(), &self.heading.to_le_bytes());
        put(b, f.speed.clone(), &self.speed.to_le_bytes());
        put(b, f.beta_flags.clone(), &[self.beta_flags]);
        put(b, f.yaw.clone(), &self.yaw.to_le_bytes());
        put(b, f.stamp.clone(), &self.stamp.to_le_bytes());
        put(b, f.brake.clone(), &[self.brake]);
        put(b, f.length.clone(), &[self.length]);
        f.len
    }

    /// The fields at their places in `b`, and the vehicle's id.
    pub(super) fn read(b: &[u8], f: &StateFields) -> (Self, u16) {
        let wire = Self {
            x: i32::from_le_bytes(get(b, f.x.clone())),
            y: i16::from_le_bytes(get(b, f.y.clone())),
            heading: i16::from_le_bytes(get(b, f.heading.clone())),
            speed: u16::from_le_bytes(get(b, f.speed.clone())),
            yaw: i16::from_le_bytes(get(b, f.yaw.clone())),
            lanes: byte(b, f.lanes.clone()),
            beta_flags: byte(b, f.beta_flags.clone()),
            stamp: u32::from_le_bytes(get(b, f.stamp.clone())),
            brake: byte(b, f.brake.clone()),
            length: byte(b, f.length.clone()),
        };
        (wire, u16::from_le_bytes(get(b, f.id.clone())))
    }

    /// The state of vehicle `id` from these fields, if plausible; its stamp restored as
    /// the instant nearest `now`.
    pub(super) fn state<F: Real>(
        &self,
        id: u16,
        now: Instant,
    ) -> Result<VehicleState<F>, DecodeError> {
        let f = |x: f64| F::from_f64(x);
        let v = f64::from(self.speed) * SPEED_RES;
        if v > SPEED_LIMIT {
            return Err(DecodeError::OutOfRange(Field::Speed));
        }
        let own = self.lanes & 0x0F;
        if own == NO_LANE {
            return Err(DecodeError::OutOfRange(Field::Lane));
        }
        // Flags: only "does not cooperate" is defined; the rest must be clear.
        if self.beta_flags & 0xF0 & !NOT_COOPERATIVE != 0 {
            return Err(DecodeError::OutOfRange(Field::Flag));
        }
        let th = f64::from(self.heading) * HEADING_RES;
        if th.abs() > core::f64::consts::PI + HEADING_RES {
            return Err(DecodeError::OutOfRange(Field::Heading));
        }
        Ok(VehicleState {
            id,
            x: f(f64::from(self.x) * POS_RES),
            y: f(f64::from(self.y) * POS_RES),
            theta: f(th),
            v: f(v),
            omega: f(f64::from(self.yaw) * YAW_RATE_RES),
            lane: own,
            alpha: lane(self.lanes >> 4),
            beta: lane(self.beta_flags & 0x0F),
            stamp: restore_millis(self.stamp, now),
            cooperative: self.beta_flags & NOT_COOPERATIVE == 0,
            brake: planner_core::BrakeLimit::from_tenths(self.brake),
            length: planner_core::BodyLength::from_tenths(self.length),
        })
    }
}

pub(super) fn libm_floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

pub(super) fn lane(n: u8) -> Option<u8> {
    (n != NO_LANE).then_some(n)
}

/// A track from its byte, if its heading is one of the four.
pub(super) fn track_of(x: u8) -> Result<TrackWire, DecodeError> {
    let t = TrackWire {
        heading: x & 0x0F,
        lane: x >> 4,
    };
    if t.heading > 3 {
        return Err(DecodeError::OutOfRange(Field::TrackHeading));
    }
    Ok(t)
}

/// A speed from its field, if plausible.
pub(super) fn speed(raw: u16) -> Result<f64, DecodeError> {
    let v = f64::from(raw) * SPEED_RES;
    if v > SPEED_LIMIT {
        return Err(DecodeError::OutOfRange(Field::Speed));
    }
    Ok(v)
}

/// The instant whose milliseconds have the low 32 bits `low` and that is nearest `now`
/// (the wire carries times that way, [`crate::wire`]): exact for any time within 24.8
/// days of the receiver's clock, whatever either clock reads.
pub fn restore_millis(low: u32, now: Instant) -> Instant {
    const RANGE: u64 = 1 << 32;
    let now_ms = now.as_millis();
    let base = (now_ms & !(RANGE - 1)) | u64::from(low);
    let mut best = base;
    for c in [base.checked_sub(RANGE), base.checked_add(RANGE)]
        .into_iter()
        .flatten()
    {
        if c.abs_diff(now_ms) < best.abs_diff(now_ms) {
            best = c;
        }
    }
    Instant::from_millis(best)
}
