//! Where each field sits in a message's payload, per kind: the one place a layout is
//! written (smoltcp's `wire` style, a `field` per kind). The encoder writes and the
//! decoder reads through these ranges alone, and `tests/layout_dbc.rs` checks each of
//! them against the signals of `can-gateway.dbc`.
//!
//! Offsets count payload bytes: byte `i` travels in classic frame `i / 7` at data byte
//! `1 + i % 7` (byte 0 of a frame is its header, [`crate::wire`]), or in a CAN FD frame at
//! data byte `1 + i`. No field straddles two 7-byte chunks, so each is a signal of one
//! classic frame. A message's last payload byte, `kind.frames() × 7 − 1`, is its CRC;
//! the bytes between a layout's `len` and the CRC are reserved and zero.

use core::ops::Range;

/// A field's bytes in the payload.
pub type Field = Range<usize>;

/// The fields of a vehicle state: [`STATE`] on a straight road, [`LOCATED`] on a
/// network's segment (the same fields in other places, and a segment).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StateFields {
    /// Vehicle id (u16).
    pub id: Field,
    /// x, 0.01 m (i32).
    pub x: Field,
    /// Lane (low nibble) and the lane it changes to (high nibble), 15 = none.
    pub lanes: Field,
    /// y, 0.01 m (i16).
    pub y: Field,
    /// Heading, 0.0125° (i16).
    pub heading: Field,
    /// Speed, 0.02 m/s (u16).
    pub speed: Field,
    /// The intended lane β (low nibble) and flags (high nibble: bit 4, does not
    /// cooperate).
    pub beta_flags: Field,
    /// Yaw rate, 0.01°/s (i16).
    pub yaw: Field,
    /// Stamp, the low 32 bits of the sender's clock in ms (u32).
    pub stamp: Field,
    /// Braking limit, 0.1 m/s² (u8, 0 = not declared).
    pub brake: Field,
    /// Length, 0.1 m (u8, 0 = not declared).
    pub length: Field,
    /// The segment (u16; empty for [`STATE`]).
    pub segment: Field,
    /// Bytes the fields cover.
    pub len: usize,
}

/// A vehicle state (kind 1): id, x, lanes | y, heading, speed, β and flags | yaw rate,
/// stamp, braking limit | length, reserved, CRC. The length took frame 3's first
/// reserved byte: 0, as an older sender wrote it, reads "not declared".
pub const STATE: StateFields = StateFields {
    id: 0..2,
    x: 2..6,
    lanes: 6..7,
    y: 7..9,
    heading: 9..11,
    speed: 11..13,
    beta_flags: 13..14,
    yaw: 14..16,
    stamp: 16..20,
    brake: 20..21,
    segment: 0..0,
    length: 21..22,
    len: 22,
};

/// A vehicle state on a segment (kind 7): id, segment, lanes, β and flags, braking limit
/// | x, y, length | heading, speed, yaw rate, reserved | stamp, CRC. The braking limit
/// took frame 0's reserved byte, the length frame 1's: 0, as an older sender wrote
/// them, reads "not declared".
pub const LOCATED: StateFields = StateFields {
    id: 0..2,
    segment: 2..4,
    lanes: 4..5,
    beta_flags: 5..6,
    brake: 6..7,
    x: 7..11,
    y: 11..13,
    length: 13..14,
    heading: 14..16,
    speed: 16..18,
    yaw: 18..20,
    stamp: 21..25,
    len: 25,
};

/// The fields of a vehicle's own state sent to its computer ([`EGO`]): a located
/// state's fields in their places, and the reference speed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EgoFields {
    /// The state's fields, as in [`LOCATED`].
    pub state: StateFields,
    /// Lanes of the road the vehicle is on (u8, 1–14).
    pub road_lanes: Field,
    /// Reference speed, 0.02 m/s (u16).
    pub v_ref: Field,
    /// Bytes the fields cover.
    pub len: usize,
}

/// A vehicle's own state (kind 10): a located state's layout, the road's lane count in
/// its reserved byte 20, and the reference speed in frame 3's spare bytes.
pub const EGO: EgoFields = EgoFields {
    state: LOCATED,
    road_lanes: 20..21,
    v_ref: 25..27,
    len: 27,
};

/// The fields of a vehicle computer's command (kind 11).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CommandFields {
    /// Commanded speed, m/s (IEEE 754 single precision).
    pub speed: Field,
    /// What the planner did ([`crate::wire::CommandStatus`], u8).
    pub status: Field,
    /// The period answered: the low 16 bits of the tick's number (u16).
    pub period: Field,
    /// Commanded yaw rate, rad/s (IEEE 754 single precision).
    pub yaw: Field,
    /// Lane (low nibble) and the lane it changes to (high nibble, 15 = none).
    pub lanes: Field,
    /// The lane it intends (low nibble, 15 = none; the high nibble is reserved, 0).
    pub beta: Field,
    /// Bytes the fields cover.
    pub len: usize,
}

/// A command (kind 11): speed, status, period | yaw rate, lanes, β, CRC.
pub const COMMAND: CommandFields = CommandFields {
    speed: 0..4,
    status: 4..5,
    period: 5..7,
    yaw: 7..11,
    lanes: 11..12,
    beta: 12..13,
    len: 13,
};

/// The fields of a crossing request: [`REQUEST`] at the Fig. 8 intersection,
/// [`JUNCTION_REQUEST`] at a network's junction (and its junction).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RequestFields {
    /// Vehicle id (u16).
    pub id: Field,
    /// The junction (u8; empty for [`REQUEST`]).
    pub junction: Field,
    /// Inlet track: heading (low nibble), lane (high nibble).
    pub inlet: Field,
    /// Outlet track, as the inlet.
    pub outlet: Field,
    /// Speed, 0.02 m/s (u16).
    pub speed: Field,
    /// Position along the route's path, 0.01 m (u24).
    pub s: Field,
    /// When it entered A_C, ms (u32).
    pub arrival: Field,
    /// Braking limit, 0.1 m/s² (u8, 0 = not declared; empty for [`REQUEST`]).
    pub brake: Field,
    /// Length, 0.1 m (u8, 0 = not declared; empty for [`REQUEST`]).
    pub length: Field,
    /// Bytes the fields cover.
    pub len: usize,
}

/// A crossing request (kind 2): id, inlet, outlet, s | arrival, speed, CRC. Its two
/// frames have no byte to spare: it declares neither length nor braking limit, and its
/// receivers take the sender at the longest vehicle they expect, as a wall.
pub const REQUEST: RequestFields = RequestFields {
    id: 0..2,
    junction: 0..0,
    inlet: 2..3,
    outlet: 3..4,
    s: 4..7,
    arrival: 7..11,
    speed: 11..13,
    brake: 0..0,
    length: 0..0,
    len: 13,
};

/// A crossing request at a junction (kind 8): id, junction, inlet, outlet, speed | s,
/// arrival | braking limit, length, reserved, CRC. The braking limit and the length took
/// frame 2's first reserved bytes: 0, as an older sender wrote them, reads "not
/// declared".
pub const JUNCTION_REQUEST: RequestFields = RequestFields {
    id: 0..2,
    junction: 2..3,
    inlet: 3..4,
    outlet: 4..5,
    speed: 5..7,
    s: 7..10,
    arrival: 10..14,
    brake: 14..15,
    length: 15..16,
    len: 16,
};

/// The fields of a message that names a vehicle and an instant: a grant (until), a
/// revoke, an exit (at), and an exit from a network's junction (with its junction).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdTimeFields {
    /// Vehicle id (u16).
    pub id: Field,
    /// The junction (u8; empty but for [`JUNCTION_EXIT`]).
    pub junction: Field,
    /// The instant, ms (u32).
    pub time: Field,
    /// Bytes the fields cover.
    pub len: usize,
}

/// A grant, a revoke or an exit (kinds 3, 4, 5): id, instant, CRC.
pub const ID_TIME: IdTimeFields = IdTimeFields {
    id: 0..2,
    junction: 2..2,
    time: 2..6,
    len: 6,
};

/// An exit from a junction (kind 9): id, junction, instant | CRC.
pub const JUNCTION_EXIT: IdTimeFields = IdTimeFields {
    id: 0..2,
    junction: 2..3,
    time: 3..7,
    len: 7,
};

/// The fields of the time master's tick (kind 6): period number (u32), end flag (u8, 0
/// or 1), CRC.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SyncFields {
    /// The period number.
    pub period: Field,
    /// 1 on the last tick of a run.
    pub last: Field,
    /// Bytes the fields cover.
    pub len: usize,
}

/// The tick.
pub const SYNC: SyncFields = SyncFields {
    period: 0..4,
    last: 4..5,
    len: 5,
};

/// Writes `bytes` into `field` of `b` (as many as both hold: a u24 field takes the low
/// three bytes of a u32's).
pub(crate) fn put(b: &mut [u8], field: Field, bytes: &[u8]) {
    if let Some(dst) = b.get_mut(field) {
        for (d, s) in dst.iter_mut().zip(bytes) {
            *d = *s;
        }
    }
}

/// `field` of `b` as `K` bytes, zero-extended (a u24 field reads as a u32's low bytes).
pub(crate) fn get<const K: usize>(b: &[u8], field: Field) -> [u8; K] {
    let mut out = [0u8; K];
    if let Some(src) = b.get(field) {
        for (d, s) in out.iter_mut().zip(src) {
            *d = *s;
        }
    }
    out
}

/// The byte at `field`'s start (0 if the field is empty or the payload shorter).
pub(crate) fn byte(b: &[u8], field: Field) -> u8 {
    b.get(field).and_then(|f| f.first()).copied().unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{MessageKind, CHUNK};

    type Row = (MessageKind, &'static str, Field);

    /// Every field of every kind, with the kind whose payload holds it.
    fn all() -> heapless::Vec<Row, 80> {
        use MessageKind as K;
        let (s, l) = (STATE, LOCATED);
        let mut out = heapless::Vec::new();
        let rows: [Row; 23] = [
            (K::State, "id", s.id),
            (K::State, "x", s.x),
            (K::State, "lanes", s.lanes),
            (K::State, "y", s.y),
            (K::State, "heading", s.heading),
            (K::State, "speed", s.speed),
            (K::State, "beta_flags", s.beta_flags),
            (K::State, "yaw", s.yaw),
            (K::State, "stamp", s.stamp),
            (K::State, "brake", s.brake),
            (K::State, "length", s.length),
            (K::Located, "id", l.id),
            (K::Located, "segment", l.segment),
            (K::Located, "lanes", l.lanes),
            (K::Located, "beta_flags", l.beta_flags),
            (K::Located, "brake", l.brake),
            (K::Located, "length", l.length),
            (K::Located, "x", l.x),
            (K::Located, "y", l.y),
            (K::Located, "heading", l.heading),
            (K::Located, "speed", l.speed),
            (K::Located, "yaw", l.yaw),
            (K::Located, "stamp", l.stamp),
        ];
        out.extend(rows);
        for (k, r) in [
            (K::Request, REQUEST),
            (K::JunctionRequest, JUNCTION_REQUEST),
        ] {
            out.extend([
                (k, "id", r.id.clone()),
                (k, "inlet", r.inlet.clone()),
                (k, "outlet", r.outlet.clone()),
                (k, "speed", r.speed.clone()),
                (k, "s", r.s.clone()),
                (k, "arrival", r.arrival.clone()),
            ]);
            if k == K::JunctionRequest {
                out.extend([
                    (k, "junction", r.junction),
                    (k, "brake", r.brake),
                    (k, "length", r.length),
                ]);
            }
        }
        for (k, r) in [(K::Grant, ID_TIME), (K::JunctionExit, JUNCTION_EXIT)] {
            out.extend([(k, "id", r.id.clone()), (k, "time", r.time.clone())]);
            if k == K::JunctionExit {
                out.extend([(k, "junction", r.junction)]);
            }
        }
        out.extend([
            (K::Sync, "period", SYNC.period),
            (K::Sync, "last", SYNC.last),
        ]);
        let e = EGO.state;
        out.extend([
            (K::Ego, "id", e.id),
            (K::Ego, "segment", e.segment),
            (K::Ego, "lanes", e.lanes),
            (K::Ego, "beta_flags", e.beta_flags),
            (K::Ego, "brake", e.brake),
            (K::Ego, "length", e.length),
            (K::Ego, "x", e.x),
            (K::Ego, "y", e.y),
            (K::Ego, "heading", e.heading),
            (K::Ego, "speed", e.speed),
            (K::Ego, "yaw", e.yaw),
            (K::Ego, "stamp", e.stamp),
            (K::Ego, "v_ref", EGO.v_ref),
            (K::Ego, "road_lanes", EGO.road_lanes),
        ]);
        let c = COMMAND;
        out.extend([
            (K::Command, "speed", c.speed),
            (K::Command, "status", c.status),
            (K::Command, "period", c.period),
            (K::Command, "yaw", c.yaw),
            (K::Command, "lanes", c.lanes),
            (K::Command, "beta", c.beta),
        ]);
        out
    }

    #[test]
    fn no_field_straddles_a_frame_and_the_crc_stays_clear() {
        assert_eq!(all().len(), 65);
        for (kind, name, f) in all() {
            assert!(!f.is_empty(), "{kind:?}.{name}");
            assert_eq!(
                f.start / CHUNK,
                (f.end - 1) / CHUNK,
                "{kind:?}.{name} {f:?}"
            );
            assert!(
                f.end < kind.frames() * CHUNK,
                "{kind:?}.{name} reaches the CRC"
            );
        }
    }

    #[test]
    fn the_fields_of_a_kind_tile_its_payload_without_overlap() {
        let lens = [
            (MessageKind::State, STATE.len),
            (MessageKind::Located, LOCATED.len),
            (MessageKind::Request, REQUEST.len),
            (MessageKind::JunctionRequest, JUNCTION_REQUEST.len),
            (MessageKind::Grant, ID_TIME.len),
            (MessageKind::JunctionExit, JUNCTION_EXIT.len),
            (MessageKind::Sync, SYNC.len),
            (MessageKind::Ego, EGO.len),
            (MessageKind::Command, COMMAND.len),
        ];
        for (kind, len) in lens {
            let mut used = [false; 28];
            for (_, name, f) in all().into_iter().filter(|(k, ..)| *k == kind) {
                for i in f {
                    assert!(!used[i], "{kind:?}.{name} overlaps at byte {i}");
                    used[i] = true;
                }
            }
            let last = used.iter().rposition(|u| *u).map_or(0, |i| i + 1);
            assert_eq!(last, len, "{kind:?}");
            // Only the located state has a gap (reserved byte 20).
            let gaps = used[..len].iter().filter(|u| !**u).count();
            assert_eq!(gaps, usize::from(kind == MessageKind::Located), "{kind:?}");
        }
    }
}
