//! The DBC describes the frames: a candump log written by the gateway is decoded by the
//! Python `cantools` package (from PyPI) and every signal must equal what was encoded,
//! within half a resolution step; the script also recomputes every message CRC on its own.
//! README's test command (`scripts/test.sh`) installs cantools in a virtual environment;
//! run bare, the test needs `python3` with `cantools` and fails saying so. It is skipped
//! only when the test script could not set cantools up (`TESTS_SKIP=cantools`), with a
//! line in the normal output and in the script's list of skips.

use can_gateway::log::candump_line;
use can_gateway::wire::{Request, TrackWire, CLOCK_ADDRESS, MANAGER_ADDRESS};
use can_gateway::{encode, Frames, Instant, Message};
use planner_core::{BodyLength, BrakeLimit, VehicleState};

/// `ms` milliseconds after the epoch.
fn ms(ms: u64) -> Instant {
    Instant::from_millis(ms)
}

/// An instant as the DBC's time signals show it: seconds, at 1 ms, from the low 32 bits
/// of the milliseconds.
fn dbc_secs(t: Instant) -> f64 {
    f64::from(t.as_millis() as u32) * 1e-3
}
use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

/// The test script's Python and its skips (shared with host-sim's viewer test).
mod support;
use support::{python, skip_or_fail};

use can_gateway::codec::encode_fd_secured;
use can_gateway::secoc::{derive_key, Key};
use can_gateway::{encode_fd, FdFrame, PlainFrame as F8, Reassembler};
use embedded_can::{Frame, Id};

/// The message the classic `frames` carry, its sender and its alive counter.
fn message_of(frames: &Frames<F8>) -> (Message<f64>, u8, u8) {
    let mut r = Reassembler::<2>::new();
    let mut msg = None;
    for f in frames {
        msg = r.push::<f64, _>(f, ms(0)).expect("valid frames");
    }
    let Some(Id::Extended(id)) = frames.first().map(|f| f.id()) else {
        panic!("extended frames")
    };
    let counter = frames[0].data()[0] & 0x0F;
    (msg.expect("a whole message"), id.as_raw() as u8, counter)
}

#[test]
fn cantools_decodes_the_gateways_candump_log() {
    // Say what is missing instead of a Python traceback, before any work.
    let probe = Command::new(python())
        .args(["-c", "import cantools"])
        .output();
    if !probe.as_ref().is_ok_and(|o| o.status.success()) {
        let cause = match probe {
            // The traceback's last line says what is missing; one line per skip.
            Ok(o) => String::from_utf8_lossy(&o.stderr)
                .lines()
                .last()
                .unwrap_or("")
                .to_string(),
            Err(e) => e.to_string(),
        };
        let why = format!("{} has no cantools ({cause})", python());
        return skip_or_fail("cantools", "can-gateway DBC test (cantools)", &why);
    }
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let tmp = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("can-gateway-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).expect("temp dir");
    let mut log = String::new();
    let mut expected = String::new();
    let mut n = 0usize;
    let mut line = |f: &dyn Fn(u64) -> Option<heapless::String<192>>,
                    sig: &[(&str, f64)],
                    log: &mut String,
                    exp: &mut String| {
        let line = f(1_700_000_000_000_000 + n as u64 * 10_000).expect("fits");
        writeln!(log, "{line}").expect("string");
        let fields: Vec<String> = sig.iter().map(|(k, v)| format!("\"{k}\": {v}")).collect();
        writeln!(
            exp,
            "{{\"frame\": {n}, \"signals\": {{{}}}}}",
            fields.join(", ")
        )
        .expect("string");
        n += 1;
    };
    // Each message goes out three ways: its classic frames, one CAN FD frame, and one
    // secured CAN FD frame (the same signals, and the freshness value after them).
    let mut push = |frames: &Frames<F8>,
                    signals: Vec<Vec<(&str, f64)>>,
                    log: &mut String,
                    exp: &mut String| {
        assert_eq!(frames.len(), signals.len(), "the signals of every frame");
        for (f, sig) in frames.iter().zip(&signals) {
            line(&|t| candump_line(t, "vcan0", f), sig, log, exp);
        }
        let (msg, sa, counter) = message_of(frames);
        let mut all: Vec<(&str, f64)> = signals
            .concat()
            .into_iter()
            .filter(|(k, _)| *k != "FrameIndex")
            .collect();
        all.push(("AliveCounter", f64::from(counter)));
        let fd: FdFrame = encode_fd(&msg, sa, counter).expect("fits one CAN FD frame");
        all.push(("FrameIndex", 15.0));
        line(&|t| candump_line(t, "vcan0", &fd), &all, log, exp);
        let fv = 0x1_2345 + u64::from(sa);
        let key = derive_key(&Key([3; 16]), sa);
        let sec: FdFrame = encode_fd_secured(&msg, sa, counter, &key, fv).expect("fits");
        all.pop();
        all.push(("FrameIndex", 14.0));
        all.push(("FreshnessValue", (fv & 0xFFFF) as f64));
        line(&|t| candump_line(t, "vcan0", &sec), &all, log, exp);
    };
    for (i, (x, v, theta)) in [
        (1234.56, 15.02, -0.1234),
        (-50.0, 0.0, 3.0),
        (987654.32, 27.8, 0.5),
    ]
    .into_iter()
    .enumerate()
    {
        let s = VehicleState {
            id: 0x0100 + i as u16,
            x,
            y: 5.4 - i as f64,
            theta,
            v,
            omega: 0.25 * i as f64,
            lane: i as u8,
            alpha: (i == 1).then_some(2),
            beta: (i == 2).then_some(1),
            stamp: ms(12_340 + 1_000 * i as u64),
            cooperative: i != 1,
            // Not declared, a truck's, a car's.
            brake: [None, BrakeLimit::from_mps2(4.5), BrakeLimit::from_mps2(7.9)][i],
            length: [None, BodyLength::from_m(16.5), BodyLength::from_m(4.5)][i],
        };
        let frames: Frames<F8> = encode(&Message::State(s), s.id as u8, i as u8).expect("encodes");
        let deg = 180.0 / std::f64::consts::PI;
        push(
            &frames,
            vec![
                vec![
                    ("VehicleId", f64::from(s.id)),
                    ("X", x),
                    ("Lane", i as f64),
                    ("LaneChangeTo", f64::from(s.alpha.unwrap_or(15))),
                    ("FrameIndex", 0.0),
                    ("AliveCounter", i as f64),
                ],
                vec![
                    ("Y", s.y),
                    ("Heading", theta * deg),
                    ("Speed", v),
                    ("IntendedLane", f64::from(s.beta.unwrap_or(15))),
                    ("NotCooperative", if s.cooperative { 0.0 } else { 1.0 }),
                    ("FrameIndex", 1.0),
                ],
                vec![
                    ("YawRate", s.omega * deg),
                    ("Timestamp", dbc_secs(s.stamp)),
                    ("BrakeLimit", s.brake.map_or(0.0, |b| b.mps2())),
                    ("FrameIndex", 2.0),
                ],
                vec![
                    ("Length", s.length.map_or(0.0, |l| l.m())),
                    ("FrameIndex", 3.0),
                ],
            ],
            &mut log,
            &mut expected,
        );
    }
    let req = Request {
        id: 9,
        inlet: TrackWire {
            heading: 2,
            lane: 1,
        },
        outlet: TrackWire {
            heading: 3,
            lane: 1,
        },
        arrival: ms(3_500),
        s: 97.25,
        v: 13.9,
        brake: None,
        length: None,
    };
    let frames: Frames<F8> = encode(&Message::Request(req), 9, 5).expect("encodes");
    push(
        &frames,
        vec![
            vec![
                ("VehicleId", 9.0),
                ("InletHeading", 2.0),
                ("InletLane", 1.0),
                ("OutletHeading", 3.0),
                ("OutletLane", 1.0),
                ("PathPosition", 97.25),
            ],
            vec![("Arrival", 3.5), ("Speed", 13.9)],
        ],
        &mut log,
        &mut expected,
    );
    for (m, sa, name) in [
        (
            Message::Grant {
                id: 9,
                until: ms(4_000),
            },
            MANAGER_ADDRESS,
            "LeaseUntil",
        ),
        (
            Message::<f64>::Revoke {
                id: 9,
                at: ms(4_500),
            },
            MANAGER_ADDRESS,
            "At",
        ),
        (
            Message::Exit {
                id: 9,
                at: ms(9_000),
            },
            9,
            "At",
        ),
    ] {
        let t = match m {
            Message::Grant { until, .. } => dbc_secs(until),
            Message::Revoke { at, .. } | Message::Exit { at, .. } => dbc_secs(at),
            _ => 0.0,
        };
        let frames: Frames<F8> = encode(&m, sa, 1).expect("encodes");
        push(
            &frames,
            vec![vec![("VehicleId", 9.0), (name, t)]],
            &mut log,
            &mut expected,
        );
    }
    // A network's kinds: a located state, a junction's request, leaving a junction and
    // leaving the network (junction 255).
    let st = VehicleState {
        id: 0x21,
        x: 812.34,
        y: 9.0,
        theta: -0.25,
        v: 12.5,
        omega: -0.5,
        lane: 2,
        alpha: None,
        beta: Some(1),
        stamp: ms(42_125),
        cooperative: false,
        brake: planner_core::BrakeLimit::from_mps2(4.5),
        length: planner_core::BodyLength::from_m(16.5),
    };
    let deg = 180.0 / std::f64::consts::PI;
    let frames: Frames<F8> = encode(
        &Message::Located {
            segment: 1013,
            state: st,
        },
        0x21,
        7,
    )
    .expect("encodes");
    push(
        &frames,
        vec![
            vec![
                ("VehicleId", 33.0),
                ("Segment", 1013.0),
                ("Lane", 2.0),
                ("LaneChangeTo", 15.0),
                ("IntendedLane", 1.0),
                ("NotCooperative", 1.0),
                ("BrakeLimit", 4.5),
            ],
            vec![("X", st.x), ("Y", st.y), ("Length", 16.5)],
            vec![
                ("Heading", st.theta * deg),
                ("Speed", st.v),
                ("YawRate", st.omega * deg),
            ],
            vec![("Timestamp", dbc_secs(st.stamp)), ("FrameIndex", 3.0)],
        ],
        &mut log,
        &mut expected,
    );
    // Software in the loop: the world tells a vehicle's computer its own state and
    // reference speed, and the computer answers with its command (f32 on the wire).
    let frames: Frames<F8> = encode(
        &Message::Ego {
            segment: 1013,
            lanes: 3,
            state: st,
            v_ref: 27.8,
        },
        CLOCK_ADDRESS,
        5,
    )
    .expect("encodes");
    push(
        &frames,
        vec![
            vec![("VehicleId", 33.0), ("Segment", 1013.0), ("Lane", 2.0)],
            vec![("X", st.x), ("Y", st.y)],
            vec![("Speed", st.v), ("RoadLanes", 3.0)],
            vec![("Timestamp", dbc_secs(st.stamp)), ("VRef", 27.8)],
        ],
        &mut log,
        &mut expected,
    );
    let (v, omega) = (13.871_234_f32, -0.012_345_678_f32);
    let cmd = can_gateway::wire::Command {
        period: 513,
        v: f64::from(v),
        omega: f64::from(omega),
        status: can_gateway::wire::CommandStatus::Yield,
        lane: 1,
        alpha: Some(0),
        beta: None,
    };
    let frames: Frames<F8> = encode(&Message::Command(cmd), 0x21, 9).expect("encodes");
    push(
        &frames,
        vec![
            vec![("Speed", f64::from(v)), ("Status", 6.0), ("Period", 513.0)],
            vec![
                ("YawRate", f64::from(omega)),
                ("Lane", 1.0),
                ("LaneChangeTo", 0.0),
                ("IntendedLane", 15.0),
            ],
        ],
        &mut log,
        &mut expected,
    );
    // A truck's request at a network's junction declares its body (a plain request
    // cannot: its frames have no room, and cantools sees none there).
    let truck = Request {
        brake: BrakeLimit::from_mps2(4.5),
        length: BodyLength::from_m(16.5),
        ..req
    };
    let frames: Frames<F8> = encode(
        &Message::JunctionRequest {
            junction: 2,
            request: truck,
        },
        9,
        8,
    )
    .expect("encodes");
    push(
        &frames,
        vec![
            vec![
                ("VehicleId", 9.0),
                ("Junction", 2.0),
                ("InletHeading", 2.0),
                ("InletLane", 1.0),
                ("OutletHeading", 3.0),
                ("OutletLane", 1.0),
                ("Speed", 13.9),
            ],
            vec![("PathPosition", 97.25), ("Arrival", 3.5)],
            vec![("FrameIndex", 2.0), ("BrakeLimit", 4.5), ("Length", 16.5)],
        ],
        &mut log,
        &mut expected,
    );
    for junction in [2u8, 255] {
        let m = Message::<f64>::JunctionExit {
            junction,
            id: 9,
            at: ms(9_250),
        };
        let frames: Frames<F8> = encode(&m, 9, 3).expect("encodes");
        push(
            &frames,
            vec![
                vec![
                    ("VehicleId", 9.0),
                    ("Junction", f64::from(junction)),
                    ("At", 9.25),
                ],
                vec![("FrameIndex", 1.0)],
            ],
            &mut log,
            &mut expected,
        );
    }
    let sync = Message::<f64>::Sync {
        period: 1234,
        last: true,
    };
    let frames: Frames<F8> = encode(&sync, CLOCK_ADDRESS, 2).expect("encodes");
    push(
        &frames,
        vec![vec![("Period", 1234.0), ("Last", 1.0)]],
        &mut log,
        &mut expected,
    );
    let log_path = tmp.join("gateway.log");
    let exp_path = tmp.join("expected.jsonl");
    std::fs::write(&log_path, log).expect("write log");
    std::fs::write(&exp_path, expected).expect("write expected");
    let out = Command::new(python())
        .arg(dir.join("tools/check_candump.py"))
        .arg(dir.join("can-gateway.dbc"))
        .arg(&log_path)
        .arg(&exp_path)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "cantools check failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{}", String::from_utf8_lossy(&out.stdout));
    // The DBC's CAN FD messages are its classic frames laid end to end (tools/dbc_fd.py).
    let fd = Command::new(python())
        .arg(dir.join("tools/dbc_fd.py"))
        .arg(dir.join("can-gateway.dbc"))
        .arg("--check")
        .output()
        .expect("python runs");
    assert!(
        fd.status.success(),
        "{}",
        String::from_utf8_lossy(&fd.stdout)
    );
}
