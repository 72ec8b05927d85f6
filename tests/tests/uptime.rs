//! A time base that lasts: a vehicle whose clock reads 60 days, or whose clock runs
//! across the wrap of the wire's 32-bit milliseconds (49.7 days), takes every fresh
//! message and decides bit for bit as one whose clock started at zero — in `f32`, as on
//! the microcontroller, and in `f64`.
//!
//! Three drives, each run from several clock readings and compared command for command:
//! - the firmware's own approach scenario (its source, compiled here as in the host
//!   mirror): a stopped car's states through can-gateway, a `WorldView`, the single-lane
//!   planner (`f32`);
//! - the same approach in `f64`;
//! - an intersection: two vehicles on crossing routes report to a manager through
//!   can-gateway's request messages, the manager grants leases (grant messages), and each
//!   vehicle's crossing planner drives on what it heard (`f32` and `f64`).

#[path = "../../firmware-example/src/scenarios.rs"]
#[allow(dead_code)]
mod scenarios;

use can_gateway::wire::{Request, TrackWire, MANAGER_ADDRESS};
use can_gateway::{encode, Frames, Message, PlainFrame, Reassembler};
use planner_core::crossing::{Algorithm, CrossingPlanner, CrossingReport, Manager};
use planner_core::intersection::{Layout, LayoutSpec, Movement};
use planner_core::{
    CostWeights, Duration, Instant, Observation, Params, Planner, PlannerSlot, Real, VehicleState,
    WorldView,
};

/// The clock readings every drive is run from: zero, 60 days, half a second before the
/// wire's milliseconds wrap (so the drive runs across it), and ten years.
fn starts() -> [Instant; 4] {
    [
        Instant::EPOCH,
        Instant::from_secs(60 * 86_400),
        Instant::from_millis((1 << 32) - 500),
        Instant::from_secs(10 * 365 * 86_400),
    ]
}

/// The period k·h after `start`.
fn period(start: Instant, k: u32) -> Instant {
    start.saturating_add(Duration::from_millis(10 * u64::from(k)))
}

#[test]
fn the_firmware_approach_plans_the_same_from_any_uptime() {
    let run = |start: Instant| {
        let mut slot = Box::new(PlannerSlot::<f32, 20>::new());
        let planner = slot
            .init(Params::table_i(), CostWeights::default())
            .expect("valid");
        let mut out = Vec::new();
        let mut node = Box::new(scenarios::Node::new());
        let a = scenarios::approach::<20>(planner, &mut node, start, &mut || 0, &mut |r| {
            out.push((r.v.to_bits(), r.omega.to_bits()))
        })
        .expect("runs");
        assert_eq!(a.rejected, 0, "every frame taken at {start:?}");
        assert_eq!(a.fallbacks, 0);
        out
    };
    let zero = run(Instant::EPOCH);
    assert_eq!(zero.len(), scenarios::APPROACH_STEPS as usize);
    for start in starts() {
        assert_eq!(run(start), zero, "from {start:?}");
    }
}

/// The approach of the firmware, generic in precision: a stopped car's states every
/// period through the codec into a view; the planner's speeds as bits.
fn approach<F: Real>(start: Instant) -> (Vec<u64>, u32) {
    let p = Params::<F>::table_i();
    let mut planner = Planner::<F, 20>::new(p, CostWeights::default()).expect("valid");
    let mut rx = Reassembler::<4>::new();
    let mut view = WorldView::<F, 4>::new(2);
    let mut lane = heapless::Vec::new();
    let (mut x, mut v) = (F::ZERO, F::from_f64(15.0));
    let (mut out, mut taken) = (Vec::new(), 0);
    for k in 0..600u32 {
        let now = period(start, k);
        let leader = VehicleState {
            id: 1,
            x: F::from_f64(60.0),
            y: F::from_f64(1.8),
            theta: F::ZERO,
            v: F::ZERO,
            omega: F::ZERO,
            lane: 0,
            alpha: None,
            beta: None,
            stamp: now,
            cooperative: false,
            brake: None,
            length: None,
        };
        let frames: Frames<PlainFrame> =
            encode(&Message::State(leader), 1, (k % 16) as u8).expect("encodes");
        for f in &frames {
            if let Ok(Some(Message::State(s))) = rx.push::<F, _>(f, now) {
                taken += u32::from(view.update(&s, now).is_ok());
            }
        }
        view.lane_vehicles(0, F::from_f64(4.5), &mut lane);
        let obs = Observation {
            x,
            v_prev: v,
            vehicles: &lane,
            stop_line: None,
            target_x: F::ZERO,
            v_ref: p.v_max(),
        };
        v = planner.step(&obs).expect("valid input").v;
        x += v * p.h();
        out.push(v.to_f64().to_bits());
    }
    (out, taken)
}

#[test]
fn the_approach_plans_the_same_from_any_uptime_in_f32_and_f64() {
    let (z32, n32) = approach::<f32>(Instant::EPOCH);
    let (z64, n64) = approach::<f64>(Instant::EPOCH);
    assert_eq!((n32, n64), (600, 600));
    for start in starts() {
        assert_eq!(
            approach::<f32>(start),
            (z32.clone(), 600),
            "f32 from {start:?}"
        );
        assert_eq!(
            approach::<f64>(start),
            (z64.clone(), 600),
            "f64 from {start:?}"
        );
    }
}

/// Two vehicles on crossing routes of the Fig. 8 intersection: each reports itself to
/// the manager every period (a request message through the codec), the manager grants
/// by FIFO (grant messages with their lease ends), and each vehicle's crossing planner
/// drives on the grants and the other's reports it heard. The speeds of both, as bits.
fn crossing<F: Real>(start: Instant) -> Vec<u64> {
    let p = Params::<F>::table_i();
    let layout = Layout::new(&p, LayoutSpec::spec8(&p)).expect("valid layout");
    let routes = [
        layout.route_index(0, 0, Movement::Straight).expect("route"),
        layout.route_index(1, 0, Movement::Straight).expect("route"),
    ];
    assert!(layout.conflict(routes[0], routes[1]));
    let mut manager = Manager::<F, 8>::new(layout.clone(), Algorithm::Fifo);
    let mut cars: Vec<_> = routes
        .iter()
        .enumerate()
        .map(|(i, &r)| {
            let planner = Planner::<F, 20>::new(p, CostWeights::default()).expect("valid");
            CrossingPlanner::<F, 20, 4>::new(planner, i as u16 + 1, r as u8, F::from_f64(4.5))
        })
        .collect();
    // Both start 40 m before their stop lines at vImax/2.
    let mut s: Vec<F> = routes
        .iter()
        .map(|&r| layout.route(r).expect("route").path.entry() - F::from_f64(42.25))
        .collect();
    let mut v = [F::from_f64(6.95); 2];
    let mut rx = Reassembler::<8>::new();
    let mut out = Vec::new();
    for k in 0..1200u32 {
        let now = period(start, k);
        // V2I: each vehicle's request; I2V: the manager's grants.
        let mut frames: Vec<PlainFrame> = Vec::new();
        for (i, &r) in routes.iter().enumerate() {
            let route = layout.route(r).expect("route");
            let track = |t: planner_core::intersection::Track| TrackWire {
                heading: t.heading,
                lane: t.lane,
            };
            let req = Request {
                id: i as u16 + 1,
                inlet: track(route.inlet),
                outlet: track(route.outlet),
                arrival: now,
                s: s[i],
                v: v[i],
                brake: None,
                length: None,
            };
            let f: Frames<PlainFrame> =
                encode(&Message::Request(req), i as u8 + 1, (k % 16) as u8).expect("encodes");
            frames.extend(f);
        }
        let mut heard: Vec<Message<F>> = Vec::new();
        for f in &frames {
            if let Ok(Some(m)) = rx.push::<F, _>(f, now) {
                heard.push(m);
            }
        }
        for m in &heard {
            if let Message::Request(q) = m {
                let route = routes[usize::from(q.id - 1)] as u8;
                let report = CrossingReport {
                    id: q.id,
                    route,
                    s: q.s,
                    v: q.v,
                    length: F::from_f64(4.5),
                    brake: None,
                };
                manager.observe(&report, now).expect("valid report");
                for (i, c) in cars.iter_mut().enumerate() {
                    if usize::from(q.id) != i + 1 {
                        c.hear_report(&report, q.arrival).expect("room");
                    }
                }
            }
        }
        manager.update(now);
        for e in manager.entries().iter().filter(|e| e.permitted) {
            let g = Message::<F>::Grant {
                id: e.id,
                until: manager.lease_until(now),
            };
            let f: Frames<PlainFrame> =
                encode(&g, MANAGER_ADDRESS, (k % 16) as u8).expect("encodes");
            for fr in &f {
                if let Ok(Some(Message::Grant { id, until })) = rx.push::<F, _>(fr, now) {
                    for c in cars.iter_mut() {
                        c.hear_grant(id, until);
                    }
                }
            }
        }
        for i in 0..2 {
            let cmd = cars[i].step(&layout, s[i], v[i], now).expect("valid");
            v[i] = cmd.v;
            s[i] += cmd.v * p.h();
            out.push(cmd.v.to_f64().to_bits());
        }
    }
    // Both crossed.
    for (i, &r) in routes.iter().enumerate() {
        assert!(
            s[i] > layout.route(r).expect("route").path.exit(),
            "vehicle {} did not cross from {start:?}",
            i + 1
        );
    }
    out
}

#[test]
fn the_intersection_decides_the_same_from_any_uptime_in_f32_and_f64() {
    let z32 = crossing::<f32>(Instant::EPOCH);
    let z64 = crossing::<f64>(Instant::EPOCH);
    for start in starts() {
        assert!(crossing::<f32>(start) == z32, "f32 from {start:?}");
        assert!(crossing::<f64>(start) == z64, "f64 from {start:?}");
    }
}
