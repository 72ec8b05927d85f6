//! Intersection scenarios as fleets on CAN frames: a task per vehicle
//! and one for the intersection manager, on the in-process frame hub with the code that
//! runs on SocketCAN (the real vcan run is `host-sim/vcan/run-in-qemu.sh`, run by CI).

use crate::common;

use crate::common::{assert_all_crossed_safely, builtin, Failing};
use can_gateway::wire;
use can_gateway::{encode, FdFrame, Frames, PlainFrame, Reassembler};
use host_sim::bus::Message;
use host_sim::fleet::can::{CanPort, Hub, HubPort, WireMap};
use host_sim::fleet::{self, FleetError, FleetSummary, Medium, Node, TIMEOUT};
use host_sim::world::{Body, Fleet, WorldSpec, LENGTH_M};
use planner_core::crossing::CrossingReport;
use planner_core::intersection::ROUTES;
use std::io;
use std::time::{Duration, SystemTime};

fn scenario(name: &str, algorithm: Option<&str>) -> WorldSpec {
    let path = builtin(name);
    let mut text = std::fs::read_to_string(&path).expect("read");
    if let Some(a) = algorithm {
        let line = text
            .lines()
            .find(|l| l.starts_with("algorithm = "))
            .expect("an algorithm line")
            .to_string();
        text = text.replace(&line, &format!("algorithm = \"{a}\""));
    }
    common::parse(&text, name)
}

fn on_hub(sc: &WorldSpec) -> FleetSummary {
    fleet::Fleet::new()
        .run(sc.clone(), Medium::Hub, &mut |_| {})
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Queues at every stop line, under every algorithm, as fleets: safe, everyone crosses,
/// within two periods of the in-process run (the manager and the planners see rounded
/// reports), every frame accepted and accounted for.
#[test]
fn queued_intersection_fleets_on_can_frames() {
    for alg in ["stop", "fifo", "concurrent", "concurrent_fair", "pipelined"] {
        let sc = scenario("intersection-queues.toml", Some(alg));
        let n = sc.vehicles.len();
        let f = on_hub(&sc);
        assert_all_crossed_safely(&f.run, n as u64);
        let exact = common::run_world(sc.clone());
        assert_all_crossed_safely(&exact, n as u64);
        for (a, b) in [
            (exact.sim_seconds, f.run.sim_seconds),
            (exact.crossing_time_mean_s(), f.run.crossing_time_mean_s()),
            (exact.crossing_time_max_s(), f.run.crossing_time_max_s()),
        ] {
            assert!(
                (a - b).abs() <= 0.02 + 1e-9,
                "{alg}: in-process {a}, on CAN {b}"
            );
        }
        assert_eq!(f.tasks, n + 1);
        assert_eq!(f.sync_ticks, 2 * f.periods - 1, "{alg}");
        assert!(f.can.rejected.is_empty(), "{alg}: {:?}", f.can.rejected);
        let m = f.messages;
        // A request per vehicle and period in the system; every vehicle, leaving the world
        // with the junction, says it left for EXIT_REPEAT_S (1,000 periods) unless the
        // run ended first.
        assert!(m.requests >= n as u64 && m.grants > 0, "{alg}: {m:?}");
        let repeats = (host_sim::world::junction::EXIT_REPEAT_S / 0.01).round() as u64;
        assert!(m.exits > 0 && m.exits <= repeats * n as u64, "{alg}: {m:?}");
        // Two frames per request, one per grant and exit; no states at a lone junction.
        assert_eq!(m.states, 0, "{alg}");
        assert_eq!(
            f.can.frames_sent,
            2 * m.requests + m.grants + m.exits,
            "{alg}"
        );
        // On the hub, every node but the sender hears every frame (and every SYNC).
        assert_eq!(
            f.can.frames_received,
            f.can.frames_sent * n as u64 + f.sync_ticks * (n as u64 + 1),
            "{alg}"
        );
        assert_eq!(f.grant_latency.count, m.grants * n as u64, "{alg}");
    }
}

/// Every route of the layout goes over CAN as its own (inlet, outlet) pair and comes
/// back; what a `Request` cannot carry is refused.
#[test]
fn crossing_reports_map_onto_requests_and_back() {
    let sc = scenario("intersection.toml", None);
    let map = WireMap::new(&sc.network);
    let report = |report: CrossingReport<f64>| Message::Crossing {
        report,
        stamp: common::secs(0.0),
        junction: 0,
    };
    let mut pairs = Vec::new();
    for route in 0..ROUTES as u8 {
        let r = CrossingReport {
            id: 7,
            route,
            s: 12.345,
            v: 9.87,
            length: LENGTH_M,
            brake: None,
        };
        let m = map.to_wire(&report(r), common::secs(3.25)).expect("maps");
        let wire::Message::Request(q) = m else {
            panic!("a request: {m:?}")
        };
        pairs.push((q.inlet, q.outlet));
        assert_eq!(q.arrival, common::secs(3.25));
        // Through the codec: position and speed rounded, the route intact.
        let frames: Frames<PlainFrame> = encode(&m, 7, 0).expect("encodes");
        let mut rx = Reassembler::<4>::new();
        let mut got = None;
        for f in &frames {
            got = rx.push::<f64, _>(f, common::secs(3.5)).expect("accepted");
        }
        let Some(Message::Crossing { report: back, .. }) = got.and_then(|g| map.from_wire(&g, 7))
        else {
            panic!("a request back")
        };
        assert_eq!((back.id, back.route, back.length), (7, route, LENGTH_M));
        assert!((back.s - r.s).abs() <= 0.005 + 1e-9 && (back.v - r.v).abs() <= 0.01 + 1e-9);
    }
    pairs.sort_by_key(|(i, o)| (i.heading, i.lane, o.heading, o.lane));
    pairs.dedup();
    assert_eq!(pairs.len(), ROUTES, "each route its own inlet/outlet pair");
    let bad_route = CrossingReport {
        id: 7,
        route: ROUTES as u8,
        s: 1.0,
        v: 1.0,
        length: LENGTH_M,
        brake: None,
    };
    assert!(map.to_wire(&report(bad_route), common::secs(0.0)).is_err());
    let long = CrossingReport {
        route: 0,
        length: LENGTH_M + 1.0,
        brake: None,
        ..bad_route
    };
    // A plain request cannot say it is longer than the cars its receivers expect.
    assert!(map.to_wire(&report(long), common::secs(0.0)).is_err());
    // In a fleet with trucks it goes as a junction request that declares its length.
    let trucks = Fleet::of([Body::TRUCK]);
    let wide = WireMap::new(&sc.network).for_fleet(trucks);
    let Ok(wire::Message::JunctionRequest {
        junction: 0,
        request,
    }) = wide.to_wire(&report(long), common::secs(0.0))
    else {
        panic!("a junction request");
    };
    assert_eq!(request.length.map(|l| l.m()), Some(LENGTH_M + 1.0));
    let Some(Message::Crossing { report: back, .. }) = wide.from_wire(
        &wire::Message::JunctionRequest {
            junction: 0,
            request,
        },
        7,
    ) else {
        panic!("a report back");
    };
    assert_eq!(back.length, LENGTH_M + 1.0);
    // Undeclared (a plain request) in that fleet: taken at the truck's length.
    let plain = wire::Message::Request(wire::Request {
        length: None,
        ..request
    });
    let Some(Message::Crossing { report: back, .. }) = wide.from_wire(&plain, 7) else {
        panic!("a report back");
    };
    assert_eq!(back.length, Body::TRUCK.length);
    // A pair that is no route (straight on from the inner lane into the outer one).
    let mut q = wire::Request {
        id: 7,
        inlet: wire::TrackWire {
            heading: 0,
            lane: 0,
        },
        outlet: wire::TrackWire {
            heading: 0,
            lane: 1,
        },
        arrival: common::secs(0.0),
        s: 1.0,
        v: 1.0,
        brake: None,
        length: None,
    };
    let route_of = |q: &wire::Request<f64>| match map.from_wire(&wire::Message::Request(*q), 7) {
        Some(Message::Crossing { report, .. }) => Some(report.route),
        _ => None,
    };
    assert!(route_of(&q).is_none());
    q.outlet.lane = 0;
    assert_eq!(route_of(&q), Some(0));
}

/// A port that, with every request its vehicle sends, forges a message from the
/// vehicle's own address (as a compromised or buggy node would): `forge(sa)`.
struct Forger {
    inner: HubPort,
    sa: Option<u8>,
    forged: u8,
    forge: fn(u8) -> wire::Message<f64>,
}

/// A grant for itself.
fn own_grant(sa: u8) -> wire::Message<f64> {
    wire::Message::Grant {
        id: u16::from(sa),
        until: common::secs(1e5),
    }
}

/// An Exit for the next vehicle: the manager would forget it while it is still inside
/// A_S and could grant a conflicting route.
fn exit_of_another(sa: u8) -> wire::Message<f64> {
    wire::Message::Exit {
        id: u16::from(sa) + 1,
        at: common::secs(0.5),
    }
}

impl CanPort for Forger {
    fn transmit(&mut self, frame: &FdFrame) -> io::Result<()> {
        self.inner.transmit(frame)?;
        let Some(sa) = self.sa else {
            return Ok(());
        };
        let id = match embedded_can::Frame::id(frame) {
            embedded_can::Id::Extended(e) => e.as_raw(),
            embedded_can::Id::Standard(_) => return Ok(()),
        };
        // After the last frame of one of its requests.
        if wire::split_id(id) == Some((wire::MessageKind::Request as u8, 1, sa)) {
            let frames: Frames<PlainFrame> = encode(&(self.forge)(sa), sa, self.forged)
                .map_err(|e| io::Error::other(format!("{e:?}")))?;
            self.forged = (self.forged + 1) & 0x0F;
            for f in &frames {
                self.inner.transmit(&FdFrame::from(*f))?;
            }
        }
        Ok(())
    }
    fn receive(&mut self, timeout: Duration) -> io::Result<Option<(FdFrame, SystemTime)>> {
        self.inner.receive(timeout)
    }
}

/// Runs `sc` with every vehicle forging `forge(sa)` after each request: every forged
/// message is refused by every receiver (SenderMismatch and nothing else), and the run is
/// the clean run, to the bit.
fn forgeries_change_nothing(sc: &WorldSpec, forge: fn(u8) -> wire::Message<f64>) {
    let clean = on_hub(sc);
    let hub = Hub::new();
    let forged = fleet::Fleet::new()
        .run(
            sc.clone(),
            fleet::Ports::custom("forging hub", move |n| {
                Ok(Forger {
                    inner: hub.port(),
                    sa: match n {
                        Node::Vehicle(i) => Some(i as u8),
                        _ => None,
                    },
                    forged: 0,
                    forge,
                })
            }),
            &mut |_| {},
        )
        .expect("runs");
    let rejected = forged.can.rejected.get("SenderMismatch").copied();
    assert!(rejected.unwrap_or(0) > 0, "{:?}", forged.can.rejected);
    assert_eq!(forged.can.rejected.len(), 1, "{:?}", forged.can.rejected);
    assert_all_crossed_safely(&forged.run, sc.vehicles.len() as u64);
    let strip = |s: &host_sim::world::summary::Summary| host_sim::world::summary::Summary {
        wall_seconds: 0.0,
        ..s.clone()
    };
    assert_eq!(
        format!("{:?}", strip(&forged.run)),
        format!("{:?}", strip(&clean.run)),
        "the forged messages changed the run"
    );
    assert_eq!(forged.messages, clean.messages);
}

/// Vehicles forging their own permissions are refused by every receiver (only the
/// manager's address may grant).
#[test]
fn forged_grants_are_refused_and_change_nothing() {
    forgeries_change_nothing(&scenario("intersection.toml", Some("fifo")), own_grant);
}

/// Vehicles forging Exits for others are refused (an Exit comes only from the vehicle
/// it names): no vehicle is forgotten inside A_S, no unpermitted entry, no collision.
#[test]
fn forged_exits_are_refused_and_change_nothing() {
    forgeries_change_nothing(
        &scenario("intersection.toml", Some("pipelined")),
        exit_of_another,
    );
}

/// A manager or a vehicle whose transmitter fails ends the run at once with a typed
/// error naming it; nothing waits for a timeout.
#[test]
fn a_failing_manager_or_vehicle_ends_the_run_with_its_error() {
    let sc = scenario("intersection.toml", None);
    for (who, after) in [(Node::Manager(0), 40), (Node::Vehicle(3), 60)] {
        let hub = Hub::new();
        let t0 = std::time::Instant::now();
        let r = fleet::Fleet::new().run(
            sc.clone(),
            fleet::Ports::custom("failing hub", move |n| {
                Ok(Failing {
                    inner: hub.port(),
                    left: if n == who { after } else { u32::MAX },
                })
            }),
            &mut |_| {},
        );
        match (who, r) {
            (Node::Manager(0), Err(FleetError::Harness(e))) => {
                assert!(e.contains("manager") && e.contains("bus-off"), "{e}")
            }
            (Node::Vehicle(3), Err(FleetError::Vehicle { id: 3, error })) => {
                assert!(error.contains("bus-off"), "{error}")
            }
            (_, other) => panic!("expected node {who:?} to fail, got {other:?}"),
        }
        assert!(t0.elapsed() < TIMEOUT / 2);
    }
}

/// The CLI runs intersection files on CAN (`--bus can-hub`), prints the fleet's JSON,
/// and refuses `[faults]` there (exit 2).
#[test]
fn cli_runs_intersections_on_the_bus() {
    let v = common::json_on_the_hub(&builtin("intersection.toml"));
    assert_eq!(
        (v["crossed"].as_u64(), v["collisions"].as_u64()),
        (Some(8), Some(0))
    );
    assert_eq!(v["tasks"], 9);
    assert!(v["messages"]["grants"].as_u64().expect("count") > 0);
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("crossing-fleet-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let faulty = dir.join("faulty-intersection.toml");
    let text = std::fs::read_to_string(builtin("intersection.toml")).expect("read");
    std::fs::write(&faulty, text + "\n[faults]\nloss = 0.2\n").expect("write");
    common::refused_on_the_bus(&faulty, "[faults]");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A vehicle that writes the intersection manager's source address (CAN authenticates no
/// sender): after each of its crossing requests it sends itself a grant "from" 0xF1,
/// signed, when the fleet authenticates, with the only key it has — its own — and the
/// freshness of its own request (the right time, so the window does not refuse it).
struct Impostor {
    inner: HubPort,
    sa: Option<u8>,
    counter: u8,
    key: Option<can_gateway::secoc::Key>,
}

impl CanPort for Impostor {
    fn transmit(&mut self, frame: &FdFrame) -> io::Result<()> {
        self.inner.transmit(frame)?;
        let Some(sa) = self.sa else {
            return Ok(());
        };
        let embedded_can::Id::Extended(id) = embedded_can::Frame::id(frame) else {
            return Ok(());
        };
        // After the last frame of one of its requests (its authenticator, if keyed).
        let last = 1 + u8::from(self.key.is_some());
        if wire::split_id(id.as_raw()) != Some((wire::MessageKind::Request as u8, last, sa)) {
            return Ok(());
        }
        let grant = wire::Message::<f64>::Grant {
            id: u16::from(sa),
            until: common::secs(1e5),
        };
        let manager = wire::MANAGER_ADDRESS;
        let frames: Vec<PlainFrame> = match &self.key {
            None => encode::<f64, PlainFrame>(&grant, manager, self.counter)
                .map_err(|e| io::Error::other(format!("{e:?}")))?
                .into_iter()
                .collect(),
            Some(key) => {
                // The scenarios here last under 65.5 s: the low 16 bits are the value.
                let d = embedded_can::Frame::data(frame);
                let fv = u64::from(u16::from_le_bytes([d[1], d[2]]));
                can_gateway::codec::encode_secured::<f64, PlainFrame>(
                    &grant,
                    manager,
                    self.counter,
                    key,
                    fv,
                )
                .map_err(|e| io::Error::other(format!("{e:?}")))?
                .into_iter()
                .collect()
            }
        };
        self.counter = (self.counter + 1) & 0x0F;
        for f in &frames {
            self.inner.transmit(&FdFrame::from(*f))?;
        }
        Ok(())
    }
    fn receive(&mut self, timeout: Duration) -> io::Result<Option<(FdFrame, SystemTime)>> {
        self.inner.receive(timeout)
    }
}

fn with_impostors(
    sc: &WorldSpec,
    keys: Option<std::sync::Arc<host_sim::fleet::can::Keys>>,
) -> FleetSummary {
    let hub = Hub::new();
    let own_keys = keys.clone();
    let own = move |sa: u8| own_keys.as_ref().and_then(|k| k.get(sa).copied());
    fleet::Fleet::new()
        .keys(keys)
        .run(
            sc.clone(),
            fleet::Ports::custom("impostors' hub", move |n| {
                let sa = match n {
                    Node::Vehicle(i) => Some(i as u8),
                    _ => None,
                };
                Ok(Impostor {
                    inner: hub.port(),
                    sa,
                    counter: 0,
                    key: sa.and_then(&own),
                })
            }),
            &mut |_| {},
        )
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Without authentication the grants a vehicle forges under the manager's
/// address are accepted by every receiver (the CRC, the counter and the sender rule all
/// pass); with it, every one fails its MAC at every receiver, nothing else is refused,
/// and the run is the clean authenticated run to the bit.
#[test]
fn grants_forged_under_the_managers_address_pass_a_plain_fleet_not_an_authenticated_one() {
    let sc = scenario("intersection.toml", Some("fifo"));
    // Without authentication every receiver accepts the forged grants: the CRC, the
    // alive counter and the sender rule all pass (only a counter equal to the manager's
    // last one is refused, as a duplicate).
    let plain_clean = on_hub(&sc);
    let plain = with_impostors(&sc, None);
    let forged = plain.can.messages_received - plain_clean.can.messages_received;
    assert!(
        forged > 1000,
        "{:?} against {:?}",
        plain.can,
        plain_clean.can
    );
    assert!(
        plain.can.rejected.keys().all(|k| k == "Duplicate"),
        "{:?}",
        plain.can.rejected
    );
    let keys = std::sync::Arc::new(host_sim::fleet::can::simulation_keys(
        &can_gateway::secoc::Key(*b"test master key!"),
    ));
    let clean = fleet::Fleet::new()
        .keys(Some(keys.clone()))
        .fd(false)
        .run(sc.clone(), Medium::Hub, &mut |_| {})
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(clean.authenticated);
    assert!(clean.can.rejected.is_empty(), "{:?}", clean.can.rejected);
    let attacked = with_impostors(&sc, Some(keys));
    let bad_mac = attacked
        .can
        .rejected
        .get("Auth(BadMac)")
        .copied()
        .unwrap_or(0);
    assert!(bad_mac > 0, "{:?}", attacked.can.rejected);
    // A forgery whose counter equals the manager's last is refused before its MAC.
    assert!(
        attacked
            .can
            .rejected
            .keys()
            .all(|k| k == "Auth(BadMac)" || k == "Duplicate"),
        "{:?}",
        attacked.can.rejected
    );
    assert_all_crossed_safely(&attacked.run, sc.vehicles.len() as u64);
    let strip = |s: &host_sim::world::summary::Summary| host_sim::world::summary::Summary {
        wall_seconds: 0.0,
        ..s.clone()
    };
    assert_eq!(
        format!("{:?}", strip(&attacked.run)),
        format!("{:?}", strip(&clean.run)),
        "the forged grants changed the authenticated run"
    );
    // Authentication changes the frames, not the run.
    assert_eq!(
        format!("{:?}", strip(&clean.run)),
        format!("{:?}", strip(&plain_clean.run))
    );
    assert_eq!(
        clean.can.messages_received,
        plain_clean.can.messages_received
    );
}
