//! The layouts of `can_gateway::layout` against the signals of `can-gateway.dbc`: every
//! field of every kind is where the DBC says, in its classic frame and in both CAN FD
//! messages (plain and secured), and every DBC signal but the frame header, the CRC and
//! the SecOC trailer belongs to a field. The encoder and the decoder use only these
//! layouts, so a change to one that the DBC does not follow fails here.

use can_gateway::layout::{self, Field};
use can_gateway::wire::{MessageKind, CHUNK};
use std::collections::{BTreeMap, BTreeSet};

/// A DBC signal: start bit (little-endian) and length in bits.
type Signal = (usize, usize);

/// Message name → signal name → signal.
fn dbc() -> BTreeMap<String, BTreeMap<String, Signal>> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/can-gateway.dbc");
    let text = std::fs::read_to_string(path).expect("the DBC is readable");
    let mut out: BTreeMap<String, BTreeMap<String, Signal>> = BTreeMap::new();
    let mut current = None;
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("BO_") => {
                let name = words.nth(1).expect("a message name").trim_end_matches(':');
                out.insert(name.to_string(), BTreeMap::new());
                current = Some(name.to_string());
            }
            Some("SG_") => {
                let name = words.next().expect("a signal name").to_string();
                let at = words.nth(1).expect("start|length@…");
                let (start, rest) = at.split_once('|').expect("start|length");
                let length = rest.split('@').next().expect("length");
                let sig = (
                    start.parse().expect("start"),
                    length.parse().expect("length"),
                );
                let msg = current.as_ref().expect("a signal inside a message");
                out.get_mut(msg).expect("its message").insert(name, sig);
            }
            _ => {}
        }
    }
    out
}

/// Every field of every kind: (kind, DBC message prefix, the field, the signals in it).
fn fields() -> Vec<(MessageKind, &'static str, Field, &'static [&'static str])> {
    let mut out = Vec::new();
    let state = |k, p: &'static str, f: layout::StateFields| {
        let mut v = vec![
            (k, p, f.id, &["VehicleId"][..]),
            (k, p, f.x, &["X"][..]),
            (k, p, f.lanes, &["Lane", "LaneChangeTo"][..]),
            (k, p, f.y, &["Y"][..]),
            (k, p, f.heading, &["Heading"][..]),
            (k, p, f.speed, &["Speed"][..]),
            (k, p, f.beta_flags, &["IntendedLane", "NotCooperative"][..]),
            (k, p, f.yaw, &["YawRate"][..]),
            (k, p, f.stamp, &["Timestamp"][..]),
            (k, p, f.brake, &["BrakeLimit"][..]),
            (k, p, f.length, &["Length"][..]),
        ];
        if !f.segment.is_empty() {
            v.push((k, p, f.segment, &["Segment"][..]));
        }
        v
    };
    out.extend(state(MessageKind::State, "VehicleState", layout::STATE));
    out.extend(state(MessageKind::Located, "Located", layout::LOCATED));
    out.extend(state(MessageKind::Ego, "Ego", layout::EGO.state));
    out.push((MessageKind::Ego, "Ego", layout::EGO.v_ref, &["VRef"][..]));
    out.push((
        MessageKind::Ego,
        "Ego",
        layout::EGO.road_lanes,
        &["RoadLanes"][..],
    ));
    let c = layout::COMMAND;
    out.extend([
        (MessageKind::Command, "Command", c.speed, &["Speed"][..]),
        (MessageKind::Command, "Command", c.status, &["Status"][..]),
        (MessageKind::Command, "Command", c.period, &["Period"][..]),
        (MessageKind::Command, "Command", c.yaw, &["YawRate"][..]),
        (
            MessageKind::Command,
            "Command",
            c.lanes,
            &["Lane", "LaneChangeTo"][..],
        ),
        (
            MessageKind::Command,
            "Command",
            c.beta,
            &["IntendedLane"][..],
        ),
    ]);
    for (k, p, f) in [
        (MessageKind::Request, "Request", layout::REQUEST),
        (
            MessageKind::JunctionRequest,
            "JunctionRequest",
            layout::JUNCTION_REQUEST,
        ),
    ] {
        out.extend([
            (k, p, f.id, &["VehicleId"][..]),
            (k, p, f.inlet, &["InletHeading", "InletLane"][..]),
            (k, p, f.outlet, &["OutletHeading", "OutletLane"][..]),
            (k, p, f.speed, &["Speed"][..]),
            (k, p, f.s, &["PathPosition"][..]),
            (k, p, f.arrival, &["Arrival"][..]),
        ]);
        let optional: [(Field, &'static [&'static str]); 3] = [
            (f.junction, &["Junction"]),
            (f.brake, &["BrakeLimit"]),
            (f.length, &["Length"]),
        ];
        for (field, signals) in optional {
            if !field.is_empty() {
                out.push((k, p, field, signals));
            }
        }
    }
    for (k, p, time) in [
        (MessageKind::Grant, "Grant", &["LeaseUntil"][..]),
        (MessageKind::Revoke, "Revoke", &["At"][..]),
        (MessageKind::Exit, "Exit", &["At"][..]),
    ] {
        let f = layout::ID_TIME;
        out.extend([(k, p, f.id, &["VehicleId"][..]), (k, p, f.time, time)]);
    }
    let (k, f) = (MessageKind::JunctionExit, layout::JUNCTION_EXIT);
    out.extend([
        (k, "JunctionExit", f.id, &["VehicleId"][..]),
        (k, "JunctionExit", f.junction, &["Junction"][..]),
        (k, "JunctionExit", f.time, &["At"][..]),
    ]);
    let f = layout::SYNC;
    out.extend([
        (MessageKind::Sync, "Sync", f.period, &["Period"][..]),
        (MessageKind::Sync, "Sync", f.last, &["Last"][..]),
    ]);
    out
}

/// The DBC messages that carry `field` of a `prefix` message, and the bit its first
/// payload byte starts at in each: the classic frame, and the two CAN FD messages.
fn carriers(kind: MessageKind, prefix: &str, field: &Field) -> [(String, usize); 3] {
    let frame = field.start / CHUNK;
    let classic = if kind.frames() == 1 {
        prefix.to_string()
    } else {
        format!("{prefix}_F{frame}")
    };
    [
        (classic, 8 * (1 + field.start % CHUNK)),
        (format!("{prefix}_FD"), 8 * (1 + field.start)),
        (format!("{prefix}_FD_Secured"), 8 * (1 + field.start)),
    ]
}

#[test]
fn every_field_is_where_the_dbc_says_in_every_frame_format() {
    let dbc = dbc();
    let mut claimed: BTreeSet<(String, String)> = BTreeSet::new();
    for (kind, prefix, field, signals) in fields() {
        for (msg, first_bit) in carriers(kind, prefix, &field) {
            let sigs = dbc
                .get(&msg)
                .unwrap_or_else(|| panic!("no DBC message {msg}"));
            let bits = first_bit..first_bit + 8 * field.len();
            for (i, name) in signals.iter().enumerate() {
                let &(start, len) = sigs
                    .get(*name)
                    .unwrap_or_else(|| panic!("{msg} has no signal {name}"));
                assert!(
                    bits.contains(&start) && start + len <= bits.end,
                    "{msg}.{name} at {start}|{len} is outside {kind:?}'s field {field:?} ({bits:?})"
                );
                // A field of one signal is that signal, whole; packed nibbles start at
                // the field's first bit, in order.
                if signals.len() == 1 {
                    assert_eq!((start, len), (bits.start, bits.len()), "{msg}.{name}");
                } else if i == 0 {
                    assert_eq!(start, bits.start, "{msg}.{name}");
                }
                claimed.insert((msg.clone(), name.to_string()));
            }
        }
    }
    // The other way: every payload signal of the DBC belongs to a field.
    let framing = ["AliveCounter", "FrameIndex", "Crc", "FreshnessValue", "Mac"];
    for (msg, sigs) in &dbc {
        for name in sigs.keys() {
            if !framing.contains(&name.as_str()) {
                assert!(
                    claimed.contains(&(msg.clone(), name.clone())),
                    "the DBC's {msg}.{name} belongs to no field of can_gateway::layout"
                );
            }
        }
    }
    assert!(claimed.len() > 100, "{}", claimed.len());
}

#[test]
fn the_crc_is_the_last_payload_byte_in_the_dbc() {
    let dbc = dbc();
    let kinds = [
        (MessageKind::State, "VehicleState"),
        (MessageKind::Located, "Located"),
        (MessageKind::Request, "Request"),
        (MessageKind::JunctionRequest, "JunctionRequest"),
        (MessageKind::JunctionExit, "JunctionExit"),
        (MessageKind::Grant, "Grant"),
        (MessageKind::Sync, "Sync"),
        (MessageKind::Ego, "Ego"),
        (MessageKind::Command, "Command"),
    ];
    for (kind, prefix) in kinds {
        let last = kind.frames() * CHUNK - 1;
        let byte = Field {
            start: last,
            end: last + 1,
        };
        for (msg, bit) in carriers(kind, prefix, &byte) {
            assert_eq!(dbc[&msg].get("Crc"), Some(&(bit, 8)), "{msg}");
        }
    }
}
