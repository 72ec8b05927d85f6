//! The fleet on CAN frames without a kernel: every vehicle in its
//! own task on the in-process frame hub, with the same code that runs on SocketCAN
//! (the real vcan test is `host-sim/vcan/run-in-qemu.sh`, run by CI).

use crate::common;

use crate::common::{builtin, load as scenario, Failing};
use can_gateway::FdFrame;
use embedded_can::{Frame, Id, StandardId};
use host_sim::bus::{Bus, Clock};
use host_sim::fleet::can::RESOLUTION;
use host_sim::fleet::can::{CanBus, CanPort, Hub, HubPort};
use host_sim::fleet::{self, FleetError, FleetSummary, Medium, Node};
use host_sim::world::summary::Summary;
use host_sim::world::{SolverChoice, World};
use planner_core::Instant;
use std::collections::VecDeque;
use std::io;
use std::process::Command;
use std::time::{Duration, SystemTime};

fn safe_and_complete(s: &Summary) {
    common::assert_safe(s);
    assert!(s.completed, "{s:?}");
}

fn on_hub(name: &str) -> FleetSummary {
    fleet::Fleet::new()
        .run(scenario(name), Medium::Hub, &mut |_| {})
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Cars and trucks over CAN frames (scenarios/trucks.toml): each state carries its
/// sender's length and braking limit through the codec; safe and every lane change done
/// under both invariants, every frame accepted.
#[test]
fn cars_and_trucks_on_can_frames() {
    for invariant in [
        planner_core::Invariant::Paper,
        planner_core::Invariant::LeaderAware,
    ] {
        let mut sc = scenario("trucks.toml");
        sc.invariant = invariant;
        let f = fleet::Fleet::new()
            .run(sc, Medium::Hub, &mut |_| {})
            .unwrap_or_else(|e| panic!("{e}"));
        safe_and_complete(&f.run);
        assert!(f.can.rejected.is_empty(), "{:?}", f.can.rejected);
    }
}

/// The multi-lane scenario as a fleet: a task per vehicle, every state through the codec;
/// safe, every lane change done, every frame accepted, one SYNC per period.
#[test]
fn multilane_fleet_on_can_frames() {
    let f = on_hub("multilane.toml");
    safe_and_complete(&f.run);
    let v = f.run.vehicles as u64;
    assert_eq!(f.tasks, f.run.vehicles);
    assert_eq!(f.periods, 1501);
    assert!(f.can.rejected.is_empty(), "{:?}", f.can.rejected);
    // Four frames per state, one state per vehicle and period.
    assert_eq!(f.can.frames_sent, 4 * v * f.periods);
    // Everyone hears every other vehicle's frames and every SYNC.
    assert_eq!(f.can.frames_received, v * ((v - 1) * 4 + 1) * f.periods);
    assert_eq!(f.state_latency.count, v * (v - 1) * (f.periods - 1));
    assert_eq!(f.run.lane_changes.changes, 8);
    // As on the in-process bus, to within a period (the planners see rounded states).
    let exact = common::run_world(scenario("multilane.toml"));
    let (a, b) = (
        exact.lane_changes.all_done_at_s.expect("done"),
        f.run.lane_changes.all_done_at_s.expect("done"),
    );
    assert!((a - b).abs() <= 0.05, "in-process {a} s, on CAN {b} s");
}

/// The single-threaded simulator over the same CAN transport ([`CanBus`] behind the
/// `Bus` trait): the same run, to the bit, as the fleet of tasks.
#[test]
fn can_bus_behind_the_bus_trait_equals_the_fleet() {
    let sc = scenario("dead-end.toml");
    let ids: Vec<u16> = sc.vehicles.iter().map(|v| v.id).collect();
    let hub = Hub::new();
    let bus = CanBus::new(&ids, &sc.network, Clock::new(Instant::EPOCH, 0.01), |_| {
        Ok(hub.port())
    })
    .expect("ports");
    let mut sim = World::<20, _>::with_bus(sc, SolverChoice::Ours, None, bus);
    sim.set_bus_resolution(RESOLUTION).expect("valid");
    let mut rows = Vec::new();
    while !sim.finished() {
        sim.step(&mut |r| rows.push(*r)).expect("step");
    }
    let s = sim.summary(0.0);
    safe_and_complete(&s);
    let mut fleet_rows = Vec::new();
    let f = fleet::Fleet::new()
        .run(scenario("dead-end.toml"), Medium::Hub, &mut |r| {
            fleet_rows.push(*r)
        })
        .expect("runs");
    assert_eq!(rows, fleet_rows);
    assert_eq!(s.min_gap_m, f.run.min_gap_m);
}

/// A port that, after every 50th frame it receives, also hands up a copy of that frame
/// and a standard-identifier frame: duplicates and foreign traffic on the bus.
struct Noisy {
    inner: HubPort,
    n: u64,
    extra: VecDeque<(FdFrame, SystemTime)>,
}

impl CanPort for Noisy {
    fn transmit(&mut self, frame: &FdFrame) -> io::Result<()> {
        self.inner.transmit(frame)
    }
    fn receive(&mut self, timeout: Duration) -> io::Result<Option<(FdFrame, SystemTime)>> {
        if let Some(f) = self.extra.pop_front() {
            return Ok(Some(f));
        }
        let got = self.inner.receive(timeout)?;
        if let Some((f, at)) = got {
            self.n += 1;
            if self.n.is_multiple_of(50) {
                let foreign = FdFrame::new(
                    Id::Standard(StandardId::new(0x123).expect("11 bits")),
                    &[1, 2, 3],
                )
                .expect("frame");
                self.extra.push_back((f, at));
                self.extra.push_back((foreign, at));
            }
        }
        Ok(got)
    }
}

/// Duplicated and foreign frames are rejected with their reason and change nothing: the
/// run is the same as on a clean bus.
#[test]
fn duplicates_and_foreign_frames_change_nothing() {
    let clean = on_hub("multilane.toml");
    let hub = Hub::new();
    let noisy = fleet::Fleet::new()
        .run(
            scenario("multilane.toml"),
            fleet::Ports::custom("noisy hub", move |_| {
                Ok(Noisy {
                    inner: hub.port(),
                    n: 0,
                    extra: VecDeque::new(),
                })
            }),
            &mut |_| {},
        )
        .expect("runs");
    let r = &noisy.can.rejected;
    assert!(r.get("NotOurs").copied().unwrap_or(0) > 0, "{r:?}");
    let dup = ["Duplicate", "OutOfSequence", "Stale"]
        .iter()
        .map(|k| r.get(*k).copied().unwrap_or(0))
        .sum::<u64>();
    assert!(dup > 0, "{r:?}");
    safe_and_complete(&noisy.run);
    assert_eq!(noisy.run.min_gap_m, clean.run.min_gap_m);
    assert_eq!(
        noisy.run.lane_changes.all_done_at_s,
        clean.run.lane_changes.all_done_at_s
    );
}

/// A vehicle whose transmitter fails ends the run at once with a typed error naming it
/// (every other task stops at the master's last SYNC; nothing waits for a timeout).
#[test]
fn a_failing_node_ends_the_run_with_its_error() {
    let hub = Hub::new();
    let t0 = std::time::Instant::now();
    let r = fleet::Fleet::new().run(
        scenario("multilane.toml"),
        fleet::Ports::custom("failing hub", move |n| {
            Ok(Failing {
                inner: hub.port(),
                left: if n == Node::Vehicle(4) { 30 } else { u32::MAX },
            })
        }),
        &mut |_| {},
    );
    match r {
        Err(FleetError::Vehicle { id: 4, error }) => assert!(error.contains("bus-off"), "{error}"),
        other => panic!("expected vehicle 4 to fail, got {other:?}"),
    }
    assert!(t0.elapsed() < fleet::TIMEOUT / 2);
}

/// Bus errors of the `Bus` trait: an unknown node, a message with no CAN mapping.
#[test]
fn can_bus_refuses_what_it_cannot_carry() {
    let hub = Hub::new();
    let road = host_sim::world::network::Network::road(1, None, 27.8);
    let mut bus = CanBus::new(&[1, 2], &road, Clock::new(Instant::EPOCH, 0.01), |_| {
        Ok(hub.port())
    })
    .expect("ports");
    let report = planner_core::crossing::CrossingReport {
        id: 1,
        route: 0,
        s: 1.0,
        v: 1.0,
        length: 4.5,
        brake: None,
    };
    // A road has no junction whose routes could carry a crossing report.
    let msg = host_sim::bus::Message::Crossing {
        report,
        stamp: common::secs(0.0),
        junction: 0,
    };
    assert!(bus.send(1, &msg, 0.0).is_err());
    let left = host_sim::bus::Message::Left {
        id: 1,
        at: common::secs(0.5),
        junction: 0,
    };
    assert!(bus.send(3, &left, 0.0).is_err());
    bus.send(1, &left, 0.0).expect("sent");
    let mut out = Vec::new();
    bus.receive(2, 0.5, &mut out).expect("received");
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].msg, left);
    // Ids that are not CAN source addresses are refused.
    assert!(
        CanBus::new(&[0xF0], &road, Clock::new(Instant::EPOCH, 0.01), |_| Ok(
            hub.port()
        ))
        .is_err()
    );
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
}

/// The CLI: `--bus can-hub` prints the fleet's JSON; bad `--bus` values, a scenario with
/// `[faults]` (the CAN bus carries frames as they are), and an interface that cannot be
/// opened are refused with a message and their exit codes (2 bad input, 4 bus failure).
#[test]
fn cli_bus_option() {
    let v = common::json_on_the_hub(&builtin("road-end.toml"));
    assert_eq!(v["collisions"], 0);
    assert!(v["can"]["frames_sent"].as_u64().expect("count") > 0);
    for (args, code, says) in [
        (vec!["--bus", "no such iface"], 2, "network interface name"),
        (vec!["--bus", ""], 2, "network interface name"),
        (vec!["--bus", "vcan-none9"], 4, "vcan-none9"),
        (
            vec!["--can-fd"],
            2,
            "--can-fd puts messages on CAN FD frames",
        ),
        (vec!["--bus", "vcan-none9", "--can-fd"], 4, "vcan-none9"),
    ] {
        let out = bin()
            .arg("run")
            .arg(builtin("road-end.toml"))
            .args(&args)
            .output()
            .expect("runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
    common::refused_on_the_bus(&builtin("multilane-faults.toml"), "[faults]");
}

/// CAN FD: every message in one frame — on a road, at a junction and in a network, plain
/// and authenticated — drives exactly the run classic CAN drives (the same bytes reach
/// the same planners), in half the frames or fewer.
#[test]
fn can_fd_carries_the_same_runs_in_one_frame_per_message() {
    let keys = std::sync::Arc::new(host_sim::fleet::can::simulation_keys(
        &can_gateway::secoc::Key(*b"test master key!"),
    ));
    for (name, keyed) in [
        ("multilane.toml", false),
        ("intersection-queues.toml", true),
        ("../host-sim/vcan/two-junctions.toml", false),
    ] {
        let run = |fd: bool| {
            let mut rows = Vec::new();
            let k = keyed.then(|| keys.clone());
            let f = fleet::Fleet::new()
                .keys(k)
                .fd(fd)
                .run(scenario(name), Medium::Hub, &mut |r| rows.push(*r))
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            (f, rows)
        };
        let (classic, classic_rows) = run(false);
        let (fd, fd_rows) = run(true);
        safe_and_complete(&fd.run);
        assert!(fd.can_fd && !classic.can_fd);
        assert_eq!(fd.authenticated, keyed);
        assert!(fd.can.rejected.is_empty(), "{name}: {:?}", fd.can.rejected);
        assert_eq!(fd_rows, classic_rows, "{name}: the trace differs");
        assert_eq!(fd.messages, classic.messages, "{name}");
        // One frame per message of the vehicles and managers (a classic message takes 1
        // to 5; the clock's ticks are not counted here): half the frames or fewer.
        let m = fd.messages;
        assert_eq!(
            fd.can.frames_sent,
            m.states + m.requests + m.grants + m.exits,
            "{name}"
        );
        assert!(2 * fd.can.frames_sent <= classic.can.frames_sent, "{name}");
        println!(
            "{name}: {} classic frames, {} CAN FD frames",
            classic.can.frames_sent, fd.can.frames_sent
        );
        assert_eq!(fd.can.messages_received, classic.can.messages_received);
    }
}

/// Cars and trucks at a single intersection over CAN frames
/// (scenarios/trucks-intersection.toml): with trucks about, every request declares its
/// sender's length and braking limit (kind 8), so the manager places each vehicle where it
/// is; safe, every vehicle across under both invariants, every frame accepted.
#[test]
fn cars_and_trucks_cross_on_can_frames() {
    for invariant in [
        planner_core::Invariant::Paper,
        planner_core::Invariant::LeaderAware,
    ] {
        let mut sc = scenario("trucks-intersection.toml");
        sc.invariant = invariant;
        let n = sc.vehicles.len() as u64;
        let f = fleet::Fleet::new()
            .run(sc, Medium::Hub, &mut |_| {})
            .unwrap_or_else(|e| panic!("{e}"));
        safe_and_complete(&f.run);
        assert_eq!(f.run.crossed(), n, "{invariant:?}: {:?}", f.run);
        assert!(f.can.rejected.is_empty(), "{:?}", f.can.rejected);
    }
}
