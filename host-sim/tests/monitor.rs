//! The independent monitors must see what they are there to see: hand-placed
//! ground truth just inside and just outside each rule, for the road, the intersection
//! and the network monitor. A blind monitor would certify every run; these fail if a
//! check is switched off, loosened or pointed at the wrong lane.

mod common;

use host_sim::monitor::junction::{JunctionWatch, OnRoute};
use host_sim::monitor::{Findings, Limits, Truth};
use host_sim::world::at::At;
use host_sim::world::network::{End, Network};
use host_sim::world::vehicle::VehicleTruth;
use host_sim::world::watch::{segment_truth, WorldMonitor};
use host_sim::world::{LANE_WIDTH_M, LENGTH_M};
use std::f64::consts::FRAC_PI_4;

const MM: f64 = 1e-3;

fn lim() -> Limits {
    Limits::table_i()
}

/// A planner-driven car at (x, y), straight, at `v` (steady).
fn car(x: f64, y: f64, v: f64) -> Truth {
    Truth {
        x,
        y,
        theta: 0.0,
        length: LENGTH_M,
        width: 1.7,
        lane: (y / LANE_WIDTH_M) as u8,
        keeps_invariant: true,
        leader_aware: false,
        brake: 7.9,
        v,
        v_before: v,
        mapped: false,
    }
}

fn centre(lane: u8) -> f64 {
    (f64::from(lane) + 0.5) * LANE_WIDTH_M
}

/// Findings of one instant on a straight road of 3 lanes.
fn road(all: &[Truth], end_x: Option<f64>) -> Findings {
    let mut f = Findings::new();
    f.check(&lim(), all, end_x, 3);
    f
}

/// Bumper gap at which a follower at `v` is exactly on Lemma 3's boundary.
fn boundary(v: f64) -> f64 {
    lim().d0 + lim().safe_distance(v)
}

#[test]
fn the_monitors_safe_distance_is_planner_cores_by_another_formula() {
    // The monitor's closed form (v + |amin| h)² / (2|amin|) against planner-core's dS of
    // (8)(9) (braking distance plus the period's travel), and against values by hand.
    let p = planner_core::Params::<f64>::table_i();
    for i in 0..=278 {
        let v = 0.1 * f64::from(i);
        let (ours, theirs) = (lim().safe_distance(v), planner_core::safety::d_s(&p, v));
        assert!((ours - theirs).abs() < 1e-9, "v {v}: {ours} vs {theirs}");
    }
    assert!((lim().safe_distance(0.0) - 0.079 * 0.079 / 15.8).abs() < 1e-15);
    assert!((lim().safe_distance(20.0) - 20.079f64.powi(2) / 15.8).abs() < 1e-12);
}

#[test]
fn the_invariant_is_judged_in_every_lane_to_the_millimetre() {
    for lane in 0..3 {
        let y = centre(lane);
        for (gap, violated) in [(boundary(20.0) - MM, true), (boundary(20.0) + MM, false)] {
            let leader = car(100.0, y, 20.0);
            let follower = car(100.0 - LENGTH_M - gap, y, 20.0);
            let f = road(&[leader, follower], None);
            assert_eq!(
                f.invariant_violations,
                u64::from(violated),
                "lane {lane}, gap {gap}"
            );
            assert_eq!(f.collisions, 0);
            assert!((f.min_gap_m - gap).abs() < 1e-9);
        }
        // The rule is the follower's speed: the same gap is fine at a lower speed.
        let f = road(
            &[
                car(100.0, y, 20.0),
                car(100.0 - LENGTH_M - boundary(20.0) + MM, y, 15.0),
            ],
            None,
        );
        assert_eq!(f.invariant_violations, 0, "lane {lane}");
    }
}

#[test]
fn a_vehicle_straddling_two_lanes_is_in_both() {
    // Centred on the line between lanes 0 and 1.
    let straddler = car(100.0, LANE_WIDTH_M, 20.0);
    let tight = LENGTH_M + boundary(20.0) - MM;
    for lane in [0, 1] {
        // A follower too close behind it in either lane.
        let f = road(&[straddler, car(100.0 - tight, centre(lane), 20.0)], None);
        assert_eq!(f.invariant_violations, 1, "follower in lane {lane}");
        // It too close behind a leader in either lane.
        let f = road(&[car(100.0 + tight, centre(lane), 20.0), straddler], None);
        assert_eq!(f.invariant_violations, 1, "leader in lane {lane}");
    }
    // Not in lane 2.
    let f = road(&[straddler, car(100.0 - tight, centre(2), 20.0)], None);
    assert_eq!(f.invariant_violations, 0);
    // A rectangle turned toward lane 1 from lane 0's centre reaches into it.
    // Straight there, its edge is 0.35 m short of lane 1; turned by 0.2 rad, its corner
    // is 0.08 m into it.
    let mut turned = car(100.0, centre(0) + 0.6, 20.0);
    let f = road(&[turned, car(100.0 - tight, centre(1), 20.0)], None);
    assert_eq!(f.invariant_violations, 0);
    turned.theta = 0.2;
    let f = road(&[turned, car(100.0 - tight, centre(1), 20.0)], None);
    assert_eq!(f.invariant_violations, 1);
}

#[test]
fn a_rectangle_exactly_touching_a_lane_line_is_not_in_the_lane_beyond() {
    let tight = LENGTH_M + boundary(20.0) - MM;
    // Its top edge exactly on the line between lanes 0 and 1 (checked as computed), a
    // leader in lane 1 just ahead: not a follower in lane 1.
    let below = car(100.0 - tight, 2.75, 20.0);
    assert_eq!(host_sim::monitor::lateral_span(&below).1, LANE_WIDTH_M);
    let f = road(&[car(100.0, centre(1), 20.0), below], None);
    assert_eq!((f.invariant_violations, f.off_road), (0, 0));
    // Its bottom edge exactly on that line, a follower in lane 0 just behind: not a leader
    // in lane 0.
    let above = car(100.0, 4.45, 20.0);
    assert_eq!(host_sim::monitor::lateral_span(&above).0, LANE_WIDTH_M);
    let f = road(&[above, car(100.0 - tight, centre(0), 20.0)], None);
    assert_eq!(f.invariant_violations, 0);
    // The top lane's vehicles are on the road (3 lanes: up to 10.8 m), beyond its edge
    // they are not; exactly on either edge of the road, or with the front exactly at its
    // end, a vehicle is still on it.
    let top = car(100.0, centre(2), 20.0);
    assert_eq!(road(&[top], None).off_road, 0);
    let beyond = car(100.0, 3.0 * LANE_WIDTH_M - 0.85 + MM, 20.0);
    assert_eq!(road(&[beyond], None).off_road, 1);
    for (edge, side) in [(0.0, 0), (3.0 * LANE_WIDTH_M, 1)] {
        let c = touching(edge, side);
        assert_eq!(road(&[c], None).off_road, 0, "edge {edge}");
    }
    let at_end = car(500.0 - 0.5 * LENGTH_M, centre(1), 0.0);
    assert_eq!(road(&[at_end], Some(500.0)).road_end_overruns, 0);
    let past_end = car(500.0 - 0.5 * LENGTH_M + MM, centre(1), 0.0);
    assert_eq!(road(&[past_end], Some(500.0)).road_end_overruns, 1);
}

/// A car whose lateral span's bottom (`side` 0) or top (1) is exactly `edge` as the
/// monitor computes it (found by stepping y one unit in the last place at a time).
fn touching(edge: f64, side: usize) -> Truth {
    let mut y = if side == 0 { edge + 0.85 } else { edge - 0.85 };
    for _ in 0..16 {
        let c = car(100.0, y, 20.0);
        let (lo, hi) = host_sim::monitor::lateral_span(&c);
        let got = if side == 0 { lo } else { hi };
        if got == edge {
            return c;
        }
        // One unit in the last place up or down (y is positive and normal here).
        let bits = y.to_bits();
        y = f64::from_bits(if got < edge { bits + 1 } else { bits - 1 });
    }
    panic!("no y puts the span's edge exactly on {edge}");
}

#[test]
fn the_road_end_is_judged_like_a_stopped_leader() {
    let end = 500.0;
    for (room, violated) in [(boundary(10.0) - MM, true), (boundary(10.0) + MM, false)] {
        let c = car(end - 0.5 * LENGTH_M - room, centre(1), 10.0);
        let f = road(&[c], Some(end));
        assert_eq!(f.invariant_violations, u64::from(violated), "room {room}");
        assert_eq!(f.road_end_overruns, 0);
    }
    // Its front past the end: an overrun.
    let f = road(&[car(end - 0.5 * LENGTH_M + MM, centre(0), 0.0)], Some(end));
    assert_eq!(f.road_end_overruns, 1);
    let f = road(&[car(end - 0.5 * LENGTH_M - MM, centre(0), 0.0)], Some(end));
    assert_eq!(f.road_end_overruns, 0);
}

#[test]
fn leaving_the_road_and_breaking_the_limits_are_seen() {
    let l = lim();
    // A rectangle's edge below y = 0 or above the top lane.
    assert_eq!(road(&[car(0.0, 0.85 - MM, 5.0)], None).off_road, 1);
    assert_eq!(road(&[car(0.0, 0.85 + MM, 5.0)], None).off_road, 0);
    assert_eq!(
        road(&[car(0.0, 3.0 * LANE_WIDTH_M - 0.85 + MM, 5.0)], None).off_road,
        1
    );
    // Speed, acceleration, braking, heading.
    let mut c = car(0.0, centre(0), l.v_max + 1e-3);
    assert_eq!(road(&[c], None).limit_violations, 1);
    c = car(0.0, centre(0), 10.0);
    c.v_before = 10.0 - l.a_max * l.h - 1e-4;
    assert_eq!(road(&[c], None).limit_violations, 1);
    c.v_before = 10.0 + l.brake * l.h + 1e-4;
    assert_eq!(road(&[c], None).limit_violations, 1);
    c.v_before = 10.0 - l.a_max * l.h + 1e-6;
    assert_eq!(road(&[c], None).limit_violations, 0);
    c = car(0.0, centre(1), 10.0);
    c.theta = l.theta_max + 1e-6;
    assert_eq!(road(&[c], None).limit_violations, 1);
    // The heading bound holds to 1e-12 rad, both ways, and not beyond.
    for theta in [l.theta_max, -l.theta_max, l.theta_max + 1e-12, 0.1] {
        c.theta = theta;
        assert_eq!(road(&[c], None).limit_violations, 0, "θ {theta}");
    }
    c.theta = -(l.theta_max + 2e-12);
    assert_eq!(road(&[c], None).limit_violations, 1);
    // A negative speed beyond the tolerance is a violation, at the tolerance it is not.
    c = car(0.0, centre(1), -1e-3);
    c.v_before = c.v;
    assert_eq!(road(&[c], None).limit_violations, 1);
    c.v = -host_sim::monitor::LIMIT_TOL;
    c.v_before = c.v;
    assert_eq!(road(&[c], None).limit_violations, 0);
    // Standing, at vmax, at vmax plus the tolerance: within the limits; braking or
    // accelerating by exactly the table's rates over a period too.
    let tol = host_sim::monitor::LIMIT_TOL;
    for (v, before) in [
        (0.0, 0.0),
        (l.v_max, l.v_max),
        (l.v_max + tol, l.v_max + tol),
        (10.0, 10.0 + l.brake * l.h),
        (10.0, 10.0 - l.a_max * l.h),
    ] {
        let mut c = car(0.0, centre(1), v);
        c.v_before = before;
        assert_eq!(road(&[c], None).limit_violations, 0, "v {v} after {before}");
    }
}

#[test]
fn collisions_of_rotated_rectangles_are_seen() {
    let a = car(0.0, centre(1), 10.0);
    // Nose to tail: touching by a millimetre, or a millimetre apart.
    assert_eq!(
        road(&[a, car(LENGTH_M - MM, centre(1), 10.0)], None).collisions,
        1
    );
    assert_eq!(
        road(&[a, car(LENGTH_M + MM, centre(1), 10.0)], None).collisions,
        0
    );
    // Exactly touching counts (the separating-axis test is strict), whichever of the two
    // is listed first (each order compares the other pair of projections).
    assert_eq!(
        road(&[a, car(LENGTH_M, centre(1), 10.0)], None).collisions,
        1
    );
    assert_eq!(
        road(&[car(LENGTH_M, centre(1), 10.0), a], None).collisions,
        1
    );
    // Near the origin, where coordinates are small (the speed shortcut must compare
    // differences, not ratios): overlapping by 0.5 m along, by 1.3 m across.
    for (p, q) in [((5.0, 1.8), (1.0, 1.8)), ((1.0, 0.5), (0.0, 0.1))] {
        let (one, two) = (car(p.0, p.1, 1.0), car(q.0, q.1, 1.0));
        assert_eq!(road(&[one, two], None).collisions, 1, "{p:?} {q:?}");
        assert_eq!(road(&[two, one], None).collisions, 1, "{q:?} {p:?}");
    }
    // Rotated 45° beside it: the corner reaches in, or its bounding boxes overlap while
    // the rectangles do not.
    let mut b = car(3.6, centre(1) + 2.2, 10.0);
    b.theta = FRAC_PI_4;
    assert_eq!(road(&[a, b], None).collisions, 1);
    b.x = 4.0;
    b.y = centre(1) + 2.6;
    assert_eq!(road(&[a, b], None).collisions, 0);
    // Every pair counts, whatever their lanes and drivers.
    let mut s = car(1.0, centre(1), 10.0);
    s.keeps_invariant = false;
    assert_eq!(road(&[a, s, car(2.0, centre(1), 0.0)], None).collisions, 3);
}

#[test]
fn a_scripted_follower_is_not_held_to_the_invariant_but_its_follower_is() {
    let tight = LENGTH_M + boundary(20.0) - MM;
    let mut script = car(100.0 - tight, centre(0), 20.0);
    script.keeps_invariant = false;
    let f = road(&[car(100.0, centre(0), 20.0), script], None);
    assert_eq!(f.invariant_violations, 0);
    let f = road(
        &[
            car(100.0, centre(0), 20.0),
            script,
            car(100.0 - 2.0 * tight, centre(0), 20.0),
        ],
        None,
    );
    assert_eq!(f.invariant_violations, 1);
}

// ---- the intersection's monitor ----

fn layout() -> planner_core::intersection::Layout<f64> {
    host_sim::experiments::throughput::spec8_layout()
}

fn on(id: u16, route: u8, s: f64, v: f64) -> OnRoute {
    OnRoute {
        id,
        route,
        s,
        v,
        length: LENGTH_M,
        leader_aware: false,
        brake: lim().brake,
    }
}

fn junction(watch: &JunctionWatch, cars: &[OnRoute]) -> Findings {
    let mut f = Findings::new();
    watch.check(&mut f, &layout(), &lim(), cars);
    f
}

#[test]
fn the_invariant_is_judged_on_shared_paths_of_a_junction() {
    let l = layout();
    let w = JunctionWatch::default();
    let tight = LENGTH_M + boundary(10.0) - MM;
    let loose = LENGTH_M + boundary(10.0) + MM;
    // Same route.
    let r = 0u8;
    assert_eq!(
        junction(&w, &[on(1, r, 60.0, 0.0), on(2, r, 60.0 - tight, 10.0)]).invariant_violations,
        1
    );
    assert_eq!(
        junction(&w, &[on(1, r, 60.0, 0.0), on(2, r, 60.0 - loose, 10.0)]).invariant_violations,
        0
    );
    // Two routes of one inlet lane while the one ahead is still on the inlet.
    let r0 = l.route(0).expect("route 0");
    let other = (0..l.routes.len())
        .find(|&k| k != 0 && l.route(k).is_some_and(|q| q.inlet == r0.inlet))
        .expect("another route from route 0's inlet") as u8;
    let ahead = r0.path.entry() - 10.0;
    let cars = [on(1, other, ahead, 0.0), on(2, 0, ahead - tight, 10.0)];
    assert_eq!(junction(&w, &cars).invariant_violations, 1);
    // Routes sharing an outlet, both past their exits.
    let mut pair = None;
    for a in 0..l.routes.len() {
        for b in 0..l.routes.len() {
            let (ra, rb) = (l.route(a).expect("a"), l.route(b).expect("b"));
            if a != b && ra.outlet == rb.outlet && ra.inlet != rb.inlet {
                pair = Some((a as u8, b as u8, ra.path.exit(), rb.path.exit()));
            }
        }
    }
    let (a, b, xa, xb) = pair.expect("two routes into one outlet");
    let cars = [on(1, a, xa + 30.0, 0.0), on(2, b, xb + 30.0 - tight, 10.0)];
    assert_eq!(junction(&w, &cars).invariant_violations, 1);
    let cars = [on(1, a, xa + 30.0, 0.0), on(2, b, xb + 30.0 - loose, 10.0)];
    assert_eq!(junction(&w, &cars).invariant_violations, 0);
    // ... but not while either is still before its exit, however close their s.
    let cars = [on(1, a, xa - 1.0, 0.0), on(2, b, xb - 1.0 - tight, 10.0)];
    assert_eq!(junction(&w, &cars).invariant_violations, 0, "both inside");
    let cars = [on(1, a, xa + 30.0, 0.0), on(2, b, xb - 1.0, 10.0)];
    assert_eq!(
        junction(&w, &cars).invariant_violations,
        0,
        "the follower inside"
    );
    let cars = [on(1, a, xa - 1.0, 0.0), on(2, b, xb + 30.0, 10.0)];
    assert_eq!(
        junction(&w, &cars).invariant_violations,
        0,
        "the leader inside"
    );
}

#[test]
fn paths_that_share_nothing_are_not_judged_together() {
    let l = layout();
    let w = JunctionWatch::default();
    let tight = LENGTH_M + boundary(10.0) - MM;
    // Two inlets, two outlets: positions along different paths mean nothing together.
    let (a, b) = (0..l.routes.len())
        .flat_map(|a| (0..l.routes.len()).map(move |b| (a, b)))
        .find(|&(a, b)| {
            let (ra, rb) = (l.route(a).expect("a"), l.route(b).expect("b"));
            ra.inlet != rb.inlet && ra.outlet != rb.outlet
        })
        .expect("two routes sharing no inlet or outlet");
    let (ra, rb) = (l.route(a).expect("a"), l.route(b).expect("b"));
    for (sa, sb) in [
        (ra.path.entry() - 10.0, rb.path.entry() - 10.0 - tight),
        (ra.path.exit() + 10.0, rb.path.exit() + 10.0 - tight),
    ] {
        let cars = [on(1, a as u8, sa, 0.0), on(2, b as u8, sb, 10.0)];
        assert_eq!(junction(&w, &cars).invariant_violations, 0, "{sa} {sb}");
    }
    // One inlet lane: judged while the one ahead is on it (its centre before A_S), not
    // from the moment its centre reaches A_S's entry (its route is then its own).
    let r0 = l.route(0).expect("route 0");
    let other = (0..l.routes.len())
        .find(|&k| k != 0 && l.route(k).is_some_and(|q| q.inlet == r0.inlet))
        .expect("another route from route 0's inlet") as u8;
    let at_entry = l.route(usize::from(other)).expect("route").path.entry();
    let cars = [
        on(1, other, at_entry, 0.0),
        on(2, 0, at_entry - tight, 10.0),
    ];
    assert_eq!(junction(&w, &cars).invariant_violations, 0);
    // Two vehicles at the very same place: a collision (the rectangles' business), not a
    // follower short of its leader: the invariant is judged toward the one strictly ahead.
    let cars = [on(1, 0, 50.0, 10.0), on(2, 0, 50.0, 10.0)];
    assert_eq!(junction(&w, &cars).invariant_violations, 0);
}

#[test]
fn entering_a_s_without_a_permission_is_seen() {
    let l = layout();
    let r = l.route(3).expect("route 3");
    let mut w = JunctionWatch::default();
    let front_at = |x: f64| x - 0.5 * LENGTH_M;
    // Front a millimetre into A_S, never permitted.
    let inside = on(7, 3, front_at(r.path.entry()) + MM, 5.0);
    let before = on(7, 3, front_at(r.path.entry()) - MM, 5.0);
    assert_eq!(junction(&w, &[inside]).unpermitted_entries, 1);
    assert_eq!(junction(&w, &[before]).unpermitted_entries, 0);
    // Permitted once: not an unpermitted entry.
    w.granted(&[7]);
    assert_eq!(junction(&w, &[inside]).unpermitted_entries, 0);
    assert_eq!(
        junction(&w, &[on(8, 3, r.path.entry() + 2.0, 5.0)]).unpermitted_entries,
        1
    );
}

#[test]
fn a_s_is_entered_past_its_entry_and_left_once_the_rear_is_past_its_exit() {
    let l = layout();
    let r = l.route(3).expect("route 3");
    let w = JunctionWatch::default();
    let count = |s: f64| junction(&w, &[on(9, 3, s, 5.0)]).unpermitted_entries;
    let half = 0.5 * LENGTH_M;
    // The front exactly on the entry line: not yet in.
    assert_eq!(count(r.path.entry() - half), 0);
    // Centre past the exit, rear still inside: in; the rear exactly on the exit line or
    // past it: out.
    assert_eq!(count(r.path.exit() + 1.0), 1);
    assert_eq!(count(r.path.exit() + half), 0);
    assert_eq!(count(r.path.exit() + half + MM), 0);
    assert_eq!(count(r.path.exit() + half - MM), 1);
}

// ---- the network's monitor ----

fn network() -> Network {
    let spec = common::parse(
        r#"
name = "net-monitor"
duration_s = 10.0
algorithm = "pipelined"
[grid]
rows = 1
cols = 2
block_m = 300.0
lanes = 2
[arrivals]
rate_vph = 100.0
"#,
        "net-monitor.toml",
    );
    spec.network
}

fn truth(id: u16, at: At, v: f64) -> VehicleTruth {
    VehicleTruth {
        id,
        at,
        v,
        v_before: v,
        planner: true,
        unmet: true,
        target_lane: 0,
        leader_aware: false,
        body: host_sim::world::Body::CAR,
    }
}

fn on_lane(seg: usize, x: f64, lane: u8) -> At {
    At::Lane {
        seg,
        x,
        y: centre(lane),
        theta: 0.0,
        lane,
        alpha: None,
        beta: None,
    }
}

fn world(net: &Network, vehicles: &[VehicleTruth]) -> Findings {
    let mut m = WorldMonitor::new(net);
    m.check(&lim(), net, vehicles);
    m.findings
}

#[test]
fn the_network_monitor_judges_segments_junction_edges_and_the_world() {
    let net = network();
    let (k, stop) = net
        .segments
        .iter()
        .enumerate()
        .find_map(|(k, s)| match s.end {
            End::Junction(_, x) => Some((k, x)),
            _ => None,
        })
        .expect("a segment into a junction");
    let tight = LENGTH_M + boundary(12.0) - MM;
    let loose = LENGTH_M + boundary(12.0) + MM;
    // On a segment, in each lane.
    for lane in 0..2 {
        let a = truth(1, on_lane(k, 100.0, lane), 0.0);
        let f = world(&net, &[a, truth(2, on_lane(k, 100.0 - tight, lane), 12.0)]);
        assert_eq!(f.invariant_violations, 1, "lane {lane}");
        let f = world(&net, &[a, truth(2, on_lane(k, 100.0 - loose, lane), 12.0)]);
        assert_eq!(f.invariant_violations, 0, "lane {lane}");
    }
    // A vehicle on a segment past its junction's stop line: only crossing vehicles may be
    // in A_S.
    let f = world(
        &net,
        &[truth(3, on_lane(k, stop - 0.5 * LENGTH_M + MM, 0), 1.0)],
    );
    assert_eq!(f.unpermitted_entries, 1);
    let f = world(
        &net,
        &[truth(3, on_lane(k, stop - 0.5 * LENGTH_M - MM, 0), 1.0)],
    );
    assert_eq!(f.unpermitted_entries, 0);
    // Across the edge of a junction: a crossing vehicle on its outlet track, which lies
    // on the segment leaving the junction, and a vehicle on that segment ahead of it.
    let jn = &net.junctions[0];
    let (route, seg, x, lane) = (0..jn.layout.routes.len())
        .find_map(|r| {
            let s = jn.layout.route(r)?.path.exit() + 20.0;
            let (seg, x, lane) = net.on_segment(0, r as u8, s)?;
            Some((r as u8, seg, x, lane))
        })
        .expect("an outlet on a segment");
    let s = jn
        .layout
        .route(usize::from(route))
        .expect("route")
        .path
        .exit()
        + 20.0;
    let crossing = truth(
        4,
        At::Crossing {
            junction: 0,
            route,
            s,
        },
        12.0,
    );
    let mapped = segment_truth(&crossing, &net, seg).expect("mapped onto the segment");
    assert!(mapped.mapped && (mapped.x - x).abs() < 1e-9);
    let f = world(
        &net,
        &[crossing, truth(5, on_lane(seg, x + tight, lane), 0.0)],
    );
    assert_eq!(f.invariant_violations, 1, "across the junction's edge");
    let f = world(
        &net,
        &[crossing, truth(5, on_lane(seg, x + loose, lane), 0.0)],
    );
    assert_eq!(f.invariant_violations, 0);
    // Collisions in world coordinates, between any two places.
    let f = world(
        &net,
        &[
            crossing,
            truth(5, on_lane(seg, x + LENGTH_M - MM, lane), 0.0),
        ],
    );
    assert_eq!(f.collisions, 1);
}

/// Corners of an oriented rectangle, counter-clockwise, computed here and not by the
/// monitor.
fn corners_of(t: &Truth) -> [(f64, f64); 4] {
    let (s, c) = t.theta.sin_cos();
    let (hl, hw) = (0.5 * t.length, 0.5 * t.width);
    [(hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw)]
        .map(|(u, w)| (t.x + u * c - w * s, t.y + u * s + w * c))
}

/// An independent oracle for two convex quadrilaterals: they meet iff an edge of one
/// crosses an edge of the other, or a corner of one lies inside the other.
fn quads_meet(a: &[(f64, f64); 4], b: &[(f64, f64); 4]) -> bool {
    let cross = |o: (f64, f64), p: (f64, f64), q: (f64, f64)| {
        (p.0 - o.0) * (q.1 - o.1) - (p.1 - o.1) * (q.0 - o.0)
    };
    let inside =
        |q: &[(f64, f64); 4], p: (f64, f64)| (0..4).all(|i| cross(q[i], q[(i + 1) % 4], p) >= 0.0);
    let edges_cross = |p1, p2, q1, q2| {
        let (d1, d2) = (cross(q1, q2, p1), cross(q1, q2, p2));
        let (d3, d4) = (cross(p1, p2, q1), cross(p1, p2, q2));
        d1 * d2 < 0.0 && d3 * d4 < 0.0
    };
    (0..4).any(|i| (0..4).any(|j| edges_cross(a[i], a[(i + 1) % 4], b[j], b[(j + 1) % 4])))
        || a.iter().any(|&p| inside(b, p))
        || b.iter().any(|&p| inside(a, p))
}

#[test]
fn the_collision_test_agrees_with_an_independent_oracle() {
    // 20,000 random pairs near each other, at any headings and positions away from the
    // origin (so that a coordinate difference is not a ratio in disguise).
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut met, mut apart) = (0, 0);
    for _ in 0..20_000 {
        let mut a = car(100.0 + 50.0 * next(), 20.0 + 10.0 * next(), 0.0);
        a.theta = std::f64::consts::TAU * next();
        let mut b = car(a.x + 12.0 * next() - 6.0, a.y + 12.0 * next() - 6.0, 0.0);
        b.theta = std::f64::consts::TAU * next();
        let want = quads_meet(&corners_of(&a), &corners_of(&b));
        let got = host_sim::monitor::rectangles_overlap(&a, &b);
        assert_eq!(got, want, "{a:?} {b:?}");
        if want {
            met += 1;
        } else {
            apart += 1;
        }
    }
    assert!(met > 2_000 && apart > 2_000, "{met} met, {apart} apart");
}

#[test]
fn a_rotated_rectangle_spans_what_its_corners_span() {
    for theta in [0.0, 0.3, -0.7, 1.2, FRAC_PI_4] {
        let mut c = car(50.0, centre(1), 0.0);
        c.theta = theta;
        let ys = corners_of(&c).map(|p| p.1);
        let lo = ys.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let (bottom, top) = host_sim::monitor::lateral_span(&c);
        assert!(
            (bottom - lo).abs() < 1e-12 && (top - hi).abs() < 1e-12,
            "{theta}"
        );
    }
}

/// The swept collision count is the count over every pair: random crowds (headings,
/// lengths and widths of their own, some touching exactly, a few far away), each counted
/// both ways.
#[test]
fn the_swept_collision_count_is_every_pairs() {
    use rand::{Rng, SeedableRng};
    let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut total = 0;
    for case in 0..200 {
        let n = r.random_range(2..120);
        let span = r.random_range(5.0..200.0);
        let mut all: Vec<Truth> = (0..n)
            .map(|_| Truth {
                theta: r.random_range(-1.6..1.6),
                length: r.random_range(2.0..12.0),
                width: r.random_range(1.0..2.6),
                ..car(r.random_range(0.0..span), r.random_range(0.0..10.0), 0.0)
            })
            .collect();
        // Bumper to bumper exactly, and one far off.
        let a = all[0];
        all.push(Truth {
            x: a.x + a.length,
            ..a
        });
        all.push(Truth { x: 1e5, ..a });
        let mut every = 0;
        for (i, a) in all.iter().enumerate() {
            for b in &all[i + 1..] {
                every += u64::from(host_sim::monitor::rectangles_overlap(a, b));
            }
        }
        assert_eq!(
            host_sim::monitor::road::collisions(&all),
            every,
            "case {case}"
        );
        total += every;
    }
    assert!(total > 1000, "the crowds collide: {total} pairs");
}

/// At a junction, a leader-aware follower is judged with its leader's exact least travel
/// along the path (braking at the harder of the two limits), and only when it is behind
/// by more than d0; the paper's follower with the wall.
#[test]
fn a_leader_aware_follower_at_a_junction_is_judged_with_the_leaders_least_travel() {
    use host_sim::monitor::road::least_travel;
    let w = JunctionWatch::default();
    let lim = lim();
    let r = 0u8;
    let aware = |id: u16, s: f64, v: f64, brake: f64| OnRoute {
        leader_aware: true,
        brake,
        ..on(id, r, s, v)
    };
    // The leader at 10 m/s braking at 4.5, the follower at 10 m/s braking at 7.9: the
    // leader still travels least_travel(10, 7.9) along the path.
    let credit = least_travel(10.0, lim.brake, lim.h);
    assert!(credit > 5.0);
    let need = LENGTH_M + boundary(10.0) - credit;
    let leader = |id| OnRoute {
        brake: 4.5,
        ..on(id, r, 60.0, 10.0)
    };
    for (gap, violations) in [(need - MM, 1), (need + MM, 0)] {
        let cars = [leader(1), aware(2, 60.0 - gap, 10.0, lim.brake)];
        assert_eq!(
            junction(&w, &cars).invariant_violations,
            violations,
            "{gap}"
        );
    }
    // The same follower under the paper's invariant: the wall.
    let cars = [leader(1), on(2, r, 60.0 - need - MM, 10.0)];
    assert_eq!(junction(&w, &cars).invariant_violations, 1);
    // A follower that brakes softer than the leader is judged at the leader's limit for
    // the credit, and at its own for its stopping distance.
    let soft = least_travel(10.0, 4.5, lim.h);
    let strong = OnRoute {
        brake: 9.0,
        ..on(1, r, 60.0, 10.0)
    };
    let gap = LENGTH_M + lim.d0 + lim.safe_distance_at(10.0, 4.5) - least_travel(10.0, 9.0, lim.h);
    let cars = [strong, aware(2, 60.0 - gap - MM, 10.0, 4.5)];
    assert_eq!(junction(&w, &cars).invariant_violations, 0, "{soft}");
    let cars = [strong, aware(2, 60.0 - gap + MM, 10.0, 4.5)];
    assert_eq!(junction(&w, &cars).invariant_violations, 1);
    // No credit within d0 of the leader, however fast it goes.
    let cars = [
        OnRoute {
            v: 13.9,
            ..leader(1)
        },
        aware(2, 60.0 - LENGTH_M - lim.d0 + MM, 0.0, lim.brake),
    ];
    assert_eq!(junction(&w, &cars).invariant_violations, 1);
}
