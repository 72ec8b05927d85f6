//! The intersection manager's rules one at a time, on hand-placed reports (the mutation audit's
//! second mutation pass: each test here pins a rule that only the slow host-sim sweeps
//! exercised before, so that a bug in it fails `cargo test -p planner-core`).
//!
//! Positions: a report's `s` is its centre along its route's path; with the class length
//! 4.5 m its front is `to_line` metres before the stop line when
//! `s = entry − 2.25 − to_line` (negative `to_line`: past the line, inside A_S).

use planner_core::crossing::{
    Algorithm, CrossingReport, Manager, ManagerError, PLATOON_MAX_WAIT, REQUEST_DISTANCE_M,
};
use planner_core::intersection::{Layout, LayoutSpec, Movement, CONFLICT_SAMPLE_M, ROUTES};
use planner_core::{Instant, Params};

/// `t` seconds into a test, 1,000 s after the managers' start (past their quiet time).
fn secs(t: f64) -> Instant {
    Instant::from_micros(((1000.0 + t) * 1e6).round() as u64)
}

/// A manager that started at the epoch: its start-up quiet time is over by [`secs`]`(0)`.
fn manager(l: &Layout<f64>, alg: Algorithm) -> Manager<f64, 8> {
    let mut m = Manager::new(l.clone(), alg);
    m.update(Instant::EPOCH);
    m
}

const LENGTH: f64 = 4.5;
const HALF: f64 = LENGTH / 2.0;

fn layout() -> Layout<f64> {
    let p = Params::<f64>::table_i();
    Layout::new(&p, LayoutSpec::spec8(&p)).unwrap()
}

/// Vehicle `id` on `route`, its front `to_line` metres before the stop line, at speed `v`.
fn at(l: &Layout<f64>, id: u16, route: usize, to_line: f64, v: f64) -> CrossingReport<f64> {
    let entry = l.route(route).unwrap().path.entry();
    CrossingReport {
        id,
        route: route as u8,
        s: entry - HALF - to_line,
        v,
        length: LENGTH,
        brake: None,
    }
}

fn route(l: &Layout<f64>, heading: u8, movement: Movement) -> usize {
    l.route_index(heading, 0, movement).unwrap()
}

fn inlet(l: &Layout<f64>, r: usize) -> usize {
    l.inlet_index(l.route(r).unwrap().inlet)
}

fn entry(m: &Manager<f64, 8>, id: u16) -> planner_core::crossing::Entry<f64> {
    *m.entries().iter().find(|e| e.id == id).expect("registered")
}

/// A manager under `alg` whose vehicle `id` on `route` was granted at its line at t = 0
/// and reports itself 3 m inside A_S at t = 1 (a holder); nothing is decided yet at t = 1.
fn with_holder(l: &Layout<f64>, alg: Algorithm, id: u16, route: usize) -> Manager<f64, 8> {
    let mut m = manager(l, alg);
    m.observe(&at(l, id, route, 0.5, 0.0), secs(0.0)).unwrap();
    m.update(secs(100.0));
    m.observe(&at(l, id, route, -3.0, 5.0), secs(1.0)).unwrap();
    m
}

#[test]
fn algorithm_names_are_the_ones_outputs_and_the_cli_use() {
    let names: Vec<&str> = Algorithm::ALL.iter().map(|a| a.name()).collect();
    assert_eq!(
        names,
        ["STOP", "STOP-1", "FIFO", "CON", "CON-fair", "PIPE", "PLATOON"]
    );
}

#[test]
fn a_report_sets_the_distance_to_the_line_the_progress_and_the_stop() {
    let l = layout();
    let r = route(&l, 0, Movement::Straight);
    let mut m = manager(&l, Algorithm::AllWayStop);
    // Stopped 10 m before the line: registered, not "stopped at the line".
    m.observe(&at(&l, 1, r, 10.0, 0.0), secs(1.0)).unwrap();
    let e = entry(&m, 1);
    assert!((e.to_line - 10.0).abs() < 1e-9, "{}", e.to_line);
    assert!((e.progress - (-10.0 - HALF)).abs() < 1e-9, "{}", e.progress);
    assert_eq!(e.stopped_at, None);
    // Rolling 1 m before the line: not stopped either.
    m.observe(&at(&l, 1, r, 1.0, 3.0), secs(2.0)).unwrap();
    let e = entry(&m, 1);
    assert_eq!(e.stopped_at, None);
    assert!((e.progress - (-1.0 - HALF)).abs() < 1e-9, "{}", e.progress);
    // Standing within the stop-line zone: stopped, from now on.
    m.observe(&at(&l, 1, r, 0.5, 0.0), secs(3.0)).unwrap();
    m.observe(&at(&l, 1, r, 0.4, 0.0), secs(4.0)).unwrap();
    let e = entry(&m, 1);
    assert_eq!(e.stopped_at, Some(secs(3.0)));
    assert!((e.to_line - 0.4).abs() < 1e-9);
    assert_eq!(e.tau, secs(1.0), "τ is the first report inside A_C");
}

#[test]
fn a_vehicle_of_no_length_is_refused_and_changes_nothing() {
    let l = layout();
    let r = route(&l, 0, Movement::Straight);
    let mut m = manager(&l, Algorithm::Fifo);
    let mut bad = at(&l, 1, r, 5.0, 0.0);
    bad.length = 0.0;
    assert_eq!(m.observe(&bad, secs(0.0)), Err(ManagerError::BadValue));
    assert!(m.entries().is_empty());
}

#[test]
fn forget_drops_that_vehicle_only() {
    let l = layout();
    let mut m = manager(&l, Algorithm::Fifo);
    m.observe(
        &at(&l, 1, route(&l, 0, Movement::Straight), 5.0, 0.0),
        secs(0.0),
    )
    .unwrap();
    m.observe(
        &at(&l, 2, route(&l, 1, Movement::Straight), 5.0, 0.0),
        secs(0.0),
    )
    .unwrap();
    m.forget(1);
    let ids: Vec<u16> = m.entries().iter().map(|e| e.id).collect();
    assert_eq!(ids, [2]);
}

/// Only the pipelined manager waits until a vehicle is within the request distance.
#[test]
fn only_the_pipelined_manager_holds_back_a_vehicle_far_from_its_line() {
    let l = layout();
    let r = route(&l, 0, Movement::Straight);
    let far = REQUEST_DISTANCE_M + 5.0;
    let pose = l.route(r).unwrap().path.pose_at(at(&l, 1, r, far, 8.0).s);
    assert!(
        l.in_comm_region(pose.x, pose.y),
        "the test needs it inside A_C"
    );
    for (alg, expected) in [
        (Algorithm::ConcurrentFair, true),
        (Algorithm::Concurrent, true),
        (Algorithm::Pipelined, false),
    ] {
        let mut m = manager(&l, alg);
        m.observe(&at(&l, 1, r, far, 8.0), secs(0.0)).unwrap();
        m.update(secs(100.0));
        assert_eq!(m.permitted(1), expected, "{alg:?}");
        m.observe(&at(&l, 1, r, REQUEST_DISTANCE_M - 5.0, 8.0), secs(0.5))
            .unwrap();
        m.update(secs(100.0));
        assert!(m.permitted(1), "{alg:?}: within the request distance");
    }
}

/// Routes (a, x, y), a ≥ 1, with a ⊗ x, a ⊗ y and x, y compatible: every such triple.
fn starving_triples(l: &Layout<f64>) -> Vec<(usize, usize, usize)> {
    let mut out = Vec::new();
    for a in 1..ROUTES {
        for x in 0..ROUTES {
            for y in 0..ROUTES {
                let distinct = x != a && y != a && x != y;
                if distinct && l.conflict(a, x) && l.conflict(a, y) && !l.conflict(x, y) {
                    out.push((a, x, y));
                }
            }
        }
    }
    out
}

/// The starvation-free rule: a later vehicle may not be granted a route that conflicts
/// with an earlier vehicle still waiting, for every route of the waiting vehicle.
#[test]
fn no_later_vehicle_overtakes_a_waiting_conflicting_one_under_the_fair_variant() {
    let l = layout();
    let triples = starving_triples(&l);
    assert!(!triples.is_empty());
    for (a, x, y) in triples {
        for (alg, y_permitted) in [
            (Algorithm::ConcurrentFair, false),
            (Algorithm::Pipelined, false),
            (Algorithm::Concurrent, true),
        ] {
            let mut m = with_holder(&l, alg, 10, x);
            assert!(m.permitted(10));
            m.observe(&at(&l, 11, a, 0.5, 0.0), secs(1.0)).unwrap();
            m.observe(&at(&l, 12, y, 0.5, 0.0), secs(2.0)).unwrap();
            m.update(secs(100.0));
            assert!(m.permitted(10) && !m.permitted(11), "{alg:?} {a} {x} {y}");
            assert_eq!(m.permitted(12), y_permitted, "{alg:?} routes {a} {x} {y}");
        }
    }
}

/// Two routes on different inlet lanes, the first on the lane earlier in Ψ's order.
fn two_inlets(l: &Layout<f64>) -> (usize, usize) {
    let (p, q) = (
        route(l, 0, Movement::Straight),
        route(l, 1, Movement::Straight),
    );
    assert_ne!(inlet(l, p), inlet(l, q));
    if inlet(l, p) < inlet(l, q) {
        (p, q)
    } else {
        (q, p)
    }
}

/// Vehicles arriving together on different lanes go in Ψ's lane order, whatever their
/// distance to the line (the tie rule of the manager's priority).
#[test]
fn ties_across_lanes_go_by_lane_order_not_by_position() {
    let l = layout();
    let (first, second) = two_inlets(&l);
    let mut m = manager(&l, Algorithm::Fifo);
    m.observe(&at(&l, 1, first, 20.0, 5.0), secs(0.0)).unwrap();
    m.observe(&at(&l, 2, second, 0.5, 0.0), secs(0.0)).unwrap();
    m.update(secs(100.0));
    assert!(m.permitted(1) && !m.permitted(2));
}

/// A vehicle on another lane, nearer its own line, never takes a permission away: the
/// withdrawal rule is about a leader on the same lane only.
#[test]
fn a_vehicle_on_another_lane_does_not_withdraw_a_permission() {
    let l = layout();
    for (held, other) in [two_inlets(&l), {
        let (p, q) = two_inlets(&l);
        (q, p)
    }] {
        let mut m = manager(&l, Algorithm::Fifo);
        m.observe(&at(&l, 1, held, 20.0, 5.0), secs(0.0)).unwrap();
        m.update(secs(100.0));
        assert!(m.permitted(1));
        m.observe(&at(&l, 1, held, 15.0, 5.0), secs(1.0)).unwrap();
        m.observe(&at(&l, 2, other, 0.5, 0.0), secs(1.0)).unwrap();
        m.update(secs(100.0));
        assert!(
            m.permitted(1) && !m.permitted(2),
            "held {held}, other {other}"
        );
    }
}

/// A permission inside A_S is never withdrawn for an earlier vehicle that was not yet
/// asking (pipelined: it was beyond the request distance when the other was granted).
#[test]
fn a_vehicle_inside_keeps_its_permission_against_an_earlier_arrival() {
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let x = (0..ROUTES)
        .find(|&x| l.conflict(a, x) && inlet(&l, x) != inlet(&l, a))
        .unwrap();
    let mut m = manager(&l, Algorithm::Pipelined);
    m.observe(&at(&l, 1, a, REQUEST_DISTANCE_M + 5.0, 8.0), secs(0.0))
        .unwrap();
    m.observe(&at(&l, 2, x, 1.0, 2.0), secs(1.0)).unwrap();
    m.update(secs(100.0));
    assert!(m.permitted(2) && !m.permitted(1));
    m.observe(&at(&l, 2, x, -3.0, 5.0), secs(2.0)).unwrap();
    m.observe(&at(&l, 1, a, 10.0, 8.0), secs(2.0)).unwrap();
    m.update(secs(100.0));
    assert!(m.permitted(2), "inside A_S: its permission stays");
    assert!(!m.permitted(1), "conflicting with a holder");
}

/// Pipelined relaxation 1: a follower on the holder's route, behind it, is granted.
#[test]
fn pipelined_grants_a_follower_on_the_holders_route() {
    let l = layout();
    let r = route(&l, 0, Movement::Straight);
    for (alg, follower) in [
        (Algorithm::Pipelined, true),
        (Algorithm::ConcurrentFair, false),
    ] {
        let mut m = with_holder(&l, alg, 1, r);
        m.observe(&at(&l, 2, r, 0.5, 0.0), secs(1.0)).unwrap();
        m.update(secs(100.0));
        assert!(m.permitted(1));
        assert_eq!(m.permitted(2), follower, "{alg:?}");
    }
}

/// Pipelined relaxation 2: once the holder's centre is past its conflict zone with a
/// route (plus the sampling step), that route is granted; not a step before.
#[test]
fn pipelined_grants_a_conflicting_route_only_past_the_conflict_zone() {
    let l = layout();
    let mut checked = 0;
    for h in 0..ROUTES {
        for c in 0..ROUTES {
            let end = l.zone_end[h][c];
            let path = l.route(h).unwrap().path;
            let room = path.exit() - path.entry() - HALF;
            if h == c || !l.conflict(h, c) || end + CONFLICT_SAMPLE_M + 0.2 > room {
                continue;
            }
            if inlet(&l, h) == inlet(&l, c) {
                continue;
            }
            for (past, granted) in [(0.1, true), (-0.1, false)] {
                let mut m = manager(&l, Algorithm::Pipelined);
                m.observe(&at(&l, 1, h, 0.5, 0.0), secs(0.0)).unwrap();
                m.update(secs(100.0));
                assert!(m.permitted(1));
                // progress = s − entry = −HALF − to_line.
                let progress = end + CONFLICT_SAMPLE_M + past;
                m.observe(&at(&l, 1, h, -HALF - progress, 8.0), secs(1.0))
                    .unwrap();
                m.observe(&at(&l, 2, c, 0.5, 0.0), secs(1.0)).unwrap();
                m.update(secs(100.0));
                assert_eq!(m.permitted(2), granted, "holder {h}, c {c}, {past:+}");
            }
            checked += 1;
        }
    }
    assert!(checked > 0);
}

/// Routes (x, a, f, y) where a relaxation-4 case exists: a conflicts with the holder's x;
/// f leaves a's inlet lane by another movement; y, on a third lane, conflicts with f only.
fn lane_head_quadruples(l: &Layout<f64>) -> Vec<[usize; 4]> {
    let mut out = Vec::new();
    for x in 0..ROUTES {
        for a in (0..ROUTES).filter(|&a| l.conflict(a, x) && inlet(l, x) != inlet(l, a)) {
            for f in (0..ROUTES).filter(|&f| f != a && inlet(l, f) == inlet(l, a)) {
                let other_lane =
                    |y: usize| inlet(l, y) != inlet(l, a) && inlet(l, y) != inlet(l, x);
                let only_f = |y: usize| !l.conflict(y, x) && !l.conflict(y, a) && l.conflict(y, f);
                out.extend(
                    (0..ROUTES)
                        .filter(|&y| other_lane(y) && only_f(y))
                        .map(|y| [x, a, f, y]),
                );
            }
        }
    }
    out
}

/// Pipelined relaxation 4: a vehicle queued behind a waiting lane head is neither granted
/// nor counted as waiting, so a later vehicle on another lane whose route conflicts only
/// with the follower's goes; the fair variant holds it back (there the follower is
/// granted and then withdrawn, or counts as waiting).
#[test]
fn pipelined_lets_only_a_lanes_head_hold_back_other_routes() {
    let l = layout();
    let cases = lane_head_quadruples(&l);
    assert!(!cases.is_empty(), "the layout has no such routes");
    for [x, a, f, y] in cases {
        for (alg, y_permitted) in [
            (Algorithm::Pipelined, true),
            (Algorithm::ConcurrentFair, false),
        ] {
            let mut m = with_holder(&l, alg, 10, x);
            m.observe(&at(&l, 11, a, 0.5, 0.0), secs(1.0)).unwrap();
            m.observe(&at(&l, 12, f, 8.0, 0.0), secs(1.0)).unwrap();
            m.observe(&at(&l, 13, y, 0.5, 0.0), secs(2.0)).unwrap();
            m.update(secs(100.0));
            let what = format!("{alg:?} routes x {x} a {a} f {f} y {y}");
            assert!(m.permitted(10) && !m.permitted(11), "{what}");
            assert_eq!(m.permitted(13), y_permitted, "{what}");
            if alg == Algorithm::Pipelined {
                assert!(!m.permitted(12), "{what}: queued behind a waiting head");
            }
        }
    }
}

/// A follower behind a lane head granted in the same scan is not queued behind it: on
/// the head's route it is granted in that scan too (relaxation 1).
#[test]
fn pipelined_grants_a_head_and_its_follower_in_one_scan() {
    let l = layout();
    let r = route(&l, 0, Movement::Straight);
    let mut m = manager(&l, Algorithm::Pipelined);
    m.observe(&at(&l, 1, r, 0.5, 0.0), secs(0.0)).unwrap();
    m.observe(&at(&l, 2, r, 8.0, 0.0), secs(0.0)).unwrap();
    m.update(secs(100.0));
    assert!(m.permitted(1) && m.permitted(2));
}

/// A manager restarted mid-crossing rebuilds its state from the next reports:
/// a vehicle first heard inside A_S holds its zones as a permission would, under every
/// algorithm, so a conflicting route waits for it — even one whose vehicle was heard
/// first and waits at its line — and is granted once it has left.
#[test]
fn a_vehicle_first_heard_inside_a_s_holds_its_route_after_a_restart() {
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let x = (0..ROUTES)
        .find(|&x| l.conflict(a, x) && inlet(&l, x) != inlet(&l, a))
        .unwrap();
    for alg in Algorithm::ALL {
        let mut m = manager(&l, alg);
        m.observe(&at(&l, 2, x, 0.5, 0.0), secs(10.0)).unwrap();
        m.observe(&at(&l, 1, a, -3.0, 5.0), secs(10.0)).unwrap();
        m.update(secs(100.0));
        assert!(entry(&m, 1).holds(), "{alg:?}: inside A_S when first heard");
        assert!(
            !m.permitted(2),
            "{alg:?}: its route conflicts with one inside"
        );
        // Vehicle 1 leaves (its rear past A_S: off the manager's list); 2 is granted.
        let exit = l.route(a).unwrap().path.exit();
        let gone = CrossingReport {
            s: exit + HALF + 1.0,
            ..at(&l, 1, a, 0.0, 5.0)
        };
        m.observe(&gone, secs(11.0)).unwrap();
        m.update(secs(100.0));
        assert!(m.entries().iter().all(|e| e.id != 1), "{alg:?}");
        if matches!(alg, Algorithm::AllWayStop | Algorithm::AllWayStopSingle) {
            m.observe(&at(&l, 2, x, 0.5, 0.0), secs(11.5)).unwrap();
            m.update(secs(100.0));
        }
        assert!(m.permitted(2), "{alg:?}: granted once the zone is clear");
    }
    // Heard before its line, able to stop there (the normal case): registered without a
    // permission. At the line at 5 m/s it could not stop: committed, it holds its zones.
    let mut m = manager(&l, Algorithm::Fifo);
    m.observe(&at(&l, 1, a, 20.0, 5.0), secs(0.0)).unwrap();
    assert!(!entry(&m, 1).holds());
    m.observe(&at(&l, 1, a, 0.0, 5.0), secs(4.0)).unwrap();
    assert!(entry(&m, 1).holds() && entry(&m, 1).committed);
}

/// A vehicle that jumps 15 m between two reports 10 ms apart is a suspect: the report is
/// refused, its record stays where it was last trusted, nothing it says later is taken —
/// not even that it left — and, holding a permission when it lied, it holds its zones
/// for good: no conflicting route is granted. One that lies before it is granted is
/// never granted and holds back no one. An honest vehicle at vmax is never refused.
#[test]
fn a_vehicle_that_jumps_is_a_suspect_and_cannot_free_its_zones() {
    use planner_core::crossing::ManagerError;
    let l = layout();
    // Two routes that cross, from different inlets.
    let (a, x) = (0..ROUTES)
        .flat_map(|a| (0..ROUTES).map(move |b| (a, b)))
        .find(|&(a, b)| {
            let (p, q) = (l.route(a).unwrap(), l.route(b).unwrap());
            l.conflict(a, b) && p.inlet != q.inlet && p.outlet != q.outlet
        })
        .unwrap();
    let exit = l.route(a).unwrap().path.exit();
    for alg in [
        Algorithm::AllWayStop,
        Algorithm::Fifo,
        Algorithm::ConcurrentFair,
        Algorithm::Pipelined,
    ] {
        let mut m = manager(&l, alg);
        // Vehicle 1 stopped at its line, granted, then 1 m inside A_S at 5 m/s.
        m.observe(&at(&l, 1, a, 0.5, 0.0), secs(0.0)).unwrap();
        m.update(secs(0.0));
        assert!(m.permitted(1), "{alg:?}");
        m.observe(&at(&l, 1, a, -1.0, 5.0), secs(0.3)).unwrap();
        // It claims to have jumped 15 m on, then to have left A_S.
        assert_eq!(
            m.observe(&at(&l, 1, a, -16.0, 5.0), secs(0.31)),
            Err(ManagerError::Implausible)
        );
        let e = entry(&m, 1);
        assert!(e.suspect && e.holds(), "{alg:?}");
        assert!(
            (e.to_line + 1.0).abs() < 1e-9,
            "frozen at its last trusted report"
        );
        let gone = CrossingReport {
            s: exit + HALF + 1.0,
            ..at(&l, 1, a, 0.0, 5.0)
        };
        assert_eq!(m.observe(&gone, secs(5.0)), Err(ManagerError::Distrusted));
        m.forget(1);
        assert!(m.holds(1), "{alg:?}: its word that it left is not taken");
        // A crossing route waits.
        for k in 0..100 {
            let t = 5.0 + 0.1 * f64::from(k);
            m.observe(&at(&l, 2, x, 0.5, 0.0), secs(t)).unwrap();
            m.update(secs(t));
            assert!(!m.permitted(2), "{alg:?}: granted over a suspect in A_S");
        }
    }
    // A vehicle that lies while it waits: never granted, and the others go.
    for alg in [
        Algorithm::Fifo,
        Algorithm::ConcurrentFair,
        Algorithm::Pipelined,
    ] {
        let mut m = manager(&l, alg);
        m.observe(&at(&l, 1, a, 10.0, 5.0), secs(0.0)).unwrap();
        assert_eq!(
            m.observe(&at(&l, 1, a, -5.0, 5.0), secs(0.01)),
            Err(ManagerError::Implausible)
        );
        for k in 0..20 {
            let t = 0.1 * f64::from(k);
            m.observe(&at(&l, 2, x, 0.5, 0.0), secs(t)).unwrap();
            m.update(secs(t));
        }
        assert!(!m.permitted(1) && m.permitted(2), "{alg:?}");
    }
    // Honest: 1 s of reports every 10 ms at vmax, and a lost second.
    let mut m = manager(&l, Algorithm::Fifo);
    let v = 27.8;
    for k in 0..100 {
        let t = 0.01 * f64::from(k);
        m.observe(&at(&l, 3, a, 45.0 - v * t, v), secs(t)).unwrap();
    }
    m.observe(&at(&l, 3, a, 45.0 - v * 2.0, v), secs(2.0))
        .unwrap();
    assert!(!entry(&m, 3).suspect);
}

/// With a roadside sensor, a vehicle that claims to be further on than it is from its
/// first report (no jump to catch) frees neither its conflict zones nor its route: the
/// manager takes it where it is measured, and flags the difference. Without one, the
/// pipelined manager frees the zone on the lie (what only a measurement can prevent).
#[test]
fn a_roadside_sensor_bounds_a_lie_that_never_jumps() {
    let l = layout();
    let (a, x) = (0..ROUTES)
        .flat_map(|a| (0..ROUTES).map(move |b| (a, b)))
        .find(|&(a, b)| {
            let (p, q) = (l.route(a).unwrap(), l.route(b).unwrap());
            l.conflict(a, b) && p.inlet != q.inlet && p.outlet != q.outlet
        })
        .unwrap();
    let end = l.zone_end[a][x];
    let entry = l.route(a).unwrap().path.entry();
    // Truly 1 m into A_S; it claims to be past its conflict zone with x by 5 m.
    let truth = entry + 1.0;
    let lie = entry + end + 5.0;
    let run = |sensor: bool| {
        let mut m = manager(&l, Algorithm::Pipelined);
        if sensor {
            m.set_roadside_sensor(Some(0.1)).unwrap();
        }
        let claim = CrossingReport {
            s: lie,
            ..at(&l, 1, a, 0.0, 5.0)
        };
        m.observe(&claim, secs(0.0)).unwrap();
        let measured = m.measure(1, truth);
        m.observe(&at(&l, 2, x, 0.5, 0.0), secs(0.0)).unwrap();
        m.update(secs(0.0));
        (m.permitted(2), measured, m.holds(1))
    };
    let (granted, _, _) = run(false);
    assert!(granted, "without a sensor the lie frees the zone");
    let (granted, measured, holds) = run(true);
    assert!(!granted, "with one it does not");
    assert_eq!(
        measured,
        Err(planner_core::crossing::ManagerError::Implausible)
    );
    assert!(holds);
    // An honest vehicle measured where it reports is not flagged, and leaves when the
    // sensor sees its rear past A_S.
    let mut m = manager(&l, Algorithm::Fifo);
    m.set_roadside_sensor(Some(0.1)).unwrap();
    let exit = l.route(a).unwrap().path.exit();
    m.observe(&at(&l, 1, a, -1.0, 5.0), secs(0.0)).unwrap();
    assert_eq!(m.measure(1, entry - HALF + 1.0), Ok(()));
    let gone = CrossingReport {
        s: exit + HALF + 1.0,
        ..at(&l, 1, a, 0.0, 5.0)
    };
    m.observe(&gone, secs(1.0)).unwrap();
    assert!(m.holds(1), "not off the list on its word alone");
    m.measure(1, exit + HALF + 0.95).unwrap();
    assert!(m.entries().is_empty());
    assert!(m.set_roadside_sensor(Some(f64::NAN)).is_err());
}

/// The roadside sensor's bounds, to the last bit: a measurement may trail the report
/// (taken after its rounding) by the sensor's error, [`PLAUSIBLE_POSITION_M`] and half the
/// bus's position step, and lead it by that plus what vmax covers in the notification
/// bound; one ulp further either way makes the vehicle a suspect. A vehicle leaves the
/// list when the measurement, less the error, puts its rear exactly at the end of A_S.
#[test]
fn a_roadside_measurement_is_judged_at_its_exact_bounds() {
    use planner_core::crossing::{Lease, PLAUSIBLE_POSITION_M};
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let (entry, exit) = {
        let p = &l.route(a).unwrap().path;
        (p.entry(), p.exit())
    };
    let (err, step) = (0.25, 0.25);
    let fresh = |report: f64| {
        let mut m = manager(&l, Algorithm::Fifo);
        m.set_roadside_sensor(Some(err)).unwrap();
        m.set_position_resolution(step).unwrap();
        m.set_vehicle_params(vehicles());
        let r = CrossingReport {
            s: report,
            ..at(&l, 1, a, 20.0, 5.0)
        };
        m.observe(&r, secs(0.0)).unwrap();
        m
    };
    let report = entry - HALF - 20.0;
    let progress = fresh(report).entries()[0].progress;
    let slack = err + PLAUSIBLE_POSITION_M + step / 2.0;
    // vmax 25 m/s over the 10 ms bound: 0.25 m, so both bounds are binary fractions that
    // a difference of positions can equal exactly (a tie is judged as the docs say).
    let lag = Lease::default().notify.as_secs::<f64>() * vehicles().v_max();
    assert_eq!(slack + lag, 1.125);
    // The last measured centres the bounds allow, as the manager computes (it subtracts
    // `entry` first): the lowest not more than `slack` behind the progress, the highest
    // not more than `slack + lag` ahead of it.
    let behind = |s: f64| progress - (s - entry);
    let ahead = |s: f64| (s - entry) - progress;
    let low = edge(
        progress + entry - slack,
        |s| behind(s) <= slack,
        f64::next_down,
    );
    let high = edge(
        progress + entry + slack + lag,
        |s| ahead(s) <= slack + lag,
        f64::next_up,
    );
    for (s, ok) in [
        (low, true),
        (high, true),
        (low.next_down(), false),
        (high.next_up(), false),
        (low - 0.01, false),
        (high + 0.01, false),
        (progress + entry, true),
    ] {
        let mut m = fresh(report);
        let got = m.measure(1, s);
        assert_eq!(got.is_ok(), ok, "measured at {s}: {got:?}");
        assert_eq!(entry_of(&m).suspect, !ok, "{s}");
    }
    // The bounds are the documented ones, exactly: a tie is allowed.
    assert_eq!((behind(low), ahead(high)), (slack, slack + lag));
    // Leaving: reported well past A_S, measured with its rear at the end of A_S.
    let gone = exit + HALF + 0.5;
    for (rear, leaves) in [(0.0, true), (-0.01, false), (0.01, true)] {
        let mut m = fresh(report);
        let r = CrossingReport {
            s: gone,
            ..at(&l, 1, a, 20.0, 5.0)
        };
        m.forget(1);
        m.observe(&at(&l, 1, a, -1.0, 5.0), secs(0.0)).unwrap();
        m.observe(&r, secs(2.0)).unwrap();
        assert_eq!(m.entries().len(), 1, "not off on its word");
        let mut s = exit + HALF + err + rear;
        if rear == 0.0 {
            while (s - entry) - err - HALF < exit - entry {
                s = s.next_up();
            }
        }
        m.measure(1, s).unwrap();
        assert_eq!(m.entries().is_empty(), leaves, "rear {rear} m past A_S");
    }
    // The error must be finite and not negative.
    for bad in [-0.01, f64::NAN, f64::INFINITY] {
        assert!(manager(&l, Algorithm::Fifo)
            .set_roadside_sensor(Some(bad))
            .is_err());
    }
    for good in [Some(0.0), None] {
        assert!(manager(&l, Algorithm::Fifo)
            .set_roadside_sensor(good)
            .is_ok());
    }
}

fn entry_of(m: &Manager<f64, 8>) -> planner_core::crossing::Entry<f64> {
    m.entries()[0]
}

/// The last value from `start` on, stepping by `next` one ulp at a time, for which `ok`
/// holds (`start` is within a few ulps of it).
fn edge(start: f64, ok: impl Fn(f64) -> bool, next: fn(f64) -> f64) -> f64 {
    let back = |x: f64| {
        if next(x) > x {
            x.next_down()
        } else {
            x.next_up()
        }
    };
    let mut x = start;
    for _ in 0..64 {
        match (ok(x), ok(next(x))) {
            (true, false) => return x,
            (true, true) => x = next(x),
            _ => x = back(x),
        }
    }
    panic!("no edge near {start}");
}

/// Table I with vmax 25 m/s.
fn vehicles() -> Params<f64> {
    let mut spec = *Params::<f64>::table_i().spec();
    spec.v_max = 25.0;
    Params::new(spec).unwrap()
}

/// With a roadside sensor, a vehicle is judged committed (too close to stop before its
/// line) where it may be by the measurement — up to the sensor's error ahead of it — not
/// only where it reports itself: a report just beyond dS(v) of the line, measured where
/// it reports, is committed once the error takes it within dS(v), and not without the
/// sensor.
#[test]
fn a_measurement_within_its_error_of_the_line_commits_the_vehicle() {
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let v = 10.0;
    let ds = planner_core::safety::d_s(&Params::<f64>::table_i(), v);
    let err = 1.0;
    for sensor in [false, true] {
        let mut m = manager(&l, Algorithm::Fifo);
        if sensor {
            m.set_roadside_sensor(Some(err)).unwrap();
        }
        let r = at(&l, 1, a, ds + 0.6, v);
        m.observe(&r, secs(0.0)).unwrap();
        assert!(!entry(&m, 1).committed, "its report alone: it can stop");
        m.measure(1, r.s).unwrap();
        m.observe(&r, secs(0.01)).unwrap();
        assert_eq!(entry(&m, 1).committed, sensor, "sensor {sensor}");
    }
}

/// Reports rounded to the bus's position step are taken as far forward as the rounding
/// allows when judging commitment: a front reported 0.1 m beyond dS(v) of the line on a
/// bus of 0.25 m steps may be 0.025 m within it.
#[test]
fn a_rounded_report_commits_where_the_rounding_allows() {
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let v = 10.0;
    let ds = planner_core::safety::d_s(&Params::<f64>::table_i(), v);
    for (step, committed) in [(0.0, false), (0.25, true)] {
        let mut m = manager(&l, Algorithm::Fifo);
        m.set_position_resolution(step).unwrap();
        m.observe(&at(&l, 1, a, ds + 0.1, v), secs(0.0)).unwrap();
        assert_eq!(entry(&m, 1).committed, committed, "step {step}");
    }
}

// ---- platoons ----

/// A platoon's scene: leader 1 on east-straight at its line, a vehicle 2 on a crossing
/// route at its line, arrived later, and leader 1's follower 3, `gap` metres (centre to
/// centre) behind 1 once 1 is 3 m past its line. Returns the manager after the scan at
/// `t` with 1 inside A_S, 2 waiting since 0.5 s, and 3 first heard at `t`.
fn platoon_scene(alg: Algorithm, gap: f64, t: f64) -> (Manager<f64, 8>, Layout<f64>) {
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let w = route(&l, 1, Movement::Straight);
    assert!(l.conflict(a, w));
    let mut m = manager(&l, alg);
    m.observe(&at(&l, 1, a, 0.5, 0.0), secs(0.0)).unwrap();
    m.update(secs(0.0));
    assert!(m.permitted(1));
    m.observe(&at(&l, 1, a, -3.0, 5.0), secs(0.5)).unwrap();
    m.observe(&at(&l, 2, w, 0.5, 0.0), secs(0.5)).unwrap();
    m.update(secs(0.5));
    assert!(!m.permitted(2), "crossing a holder's zone");
    assert_eq!(entry(&m, 2).waiting_since, Some(secs(0.5)));
    // 1's front is 3 m past the line, its centre 0.75 m past it.
    m.observe(&at(&l, 1, a, -3.0, 5.0), secs(t)).unwrap();
    m.observe(&at(&l, 2, w, 0.5, 0.0), secs(t)).unwrap();
    m.observe(&at(&l, 3, a, gap - 3.0, 8.0), secs(t)).unwrap();
    m.update(secs(t));
    (m, l)
}

/// A follower close behind a holder on its lane goes with it under PLATOON — ahead of an
/// earlier vehicle waiting on a conflicting route — and under no other algorithm.
/// A vehicle that fits beside every holder goes with them under PLATOON — ahead of an
/// earlier vehicle waiting on a conflicting route that could not go anyway (a holder
/// crosses it) — and under no other algorithm; near or far behind its leader alike.
#[test]
fn a_vehicle_joins_the_flow_past_one_that_could_not_go_only_under_platoon() {
    for (alg, joins) in [
        (Algorithm::Platoon, true),
        (Algorithm::Pipelined, false),
        (Algorithm::ConcurrentFair, false),
    ] {
        for gap in [10.0, 26.0] {
            let (m, _) = platoon_scene(alg, gap, 1.0);
            assert!(m.permitted(1) && !m.permitted(2), "{alg:?}");
            assert_eq!(m.permitted(3), joins, "{alg:?} {gap}");
            assert_eq!(entry(&m, 2).waiting_since, Some(secs(0.5)), "kept");
        }
    }
}

/// Trailing on a shared inlet: behind a holder still in its conflict zone with the
/// follower's route, a vehicle of its lane on the other route is granted under PLATOON
/// where the layout found that the pair trails (straight and left on the inner lane,
/// either way round; a right turn behind a straight on the outer lane) — not a straight
/// behind a right turn, whose tight arc swings the leader's rear across the straight,
/// not a vehicle of another length, and not under PIPE.
#[test]
fn a_vehicle_trails_its_lane_leader_onto_another_route_only_under_platoon() {
    let l = layout();
    let (s, left) = (
        route(&l, 0, Movement::Straight),
        route(&l, 0, Movement::Left),
    );
    let outer_s = l.route_index(0, 1, Movement::Straight).unwrap();
    let outer_r = l.route_index(0, 1, Movement::Right).unwrap();
    assert!(l.conflict(s, left) && l.conflict(outer_s, outer_r));
    let granted = |alg: Algorithm, lead: usize, follow: usize, length: f64| {
        let mut m = manager(&l, alg);
        m.observe(&at(&l, 1, lead, 0.5, 0.0), secs(0.0)).unwrap();
        m.update(secs(0.0));
        // The leader's centre 0.75 m past its line: in its zone with the follower's route.
        m.observe(&at(&l, 1, lead, -3.0, 5.0), secs(0.5)).unwrap();
        assert!(l.zone_end[lead][follow] > 0.75 + CONFLICT_SAMPLE_M);
        let entry = l.route(follow).unwrap().path.entry();
        let follower = CrossingReport {
            s: entry - length / 2.0 - 5.0,
            length,
            ..at(&l, 2, follow, 5.0, 5.0)
        };
        m.observe(&follower, secs(0.5)).unwrap();
        m.update(secs(0.5));
        assert!(m.permitted(1));
        m.permitted(2)
    };
    for (lead, follow, trails) in [
        (s, left, true),
        (left, s, true),
        (outer_s, outer_r, true),
        (outer_r, outer_s, false),
    ] {
        assert_eq!(l.may_trail(lead, follow), trails, "{lead} -> {follow}");
        assert_eq!(
            granted(Algorithm::Platoon, lead, follow, LENGTH),
            trails,
            "{lead} -> {follow}"
        );
        assert!(
            !granted(Algorithm::Pipelined, lead, follow, LENGTH),
            "PIPE {lead} -> {follow}"
        );
        assert!(
            !granted(Algorithm::Platoon, lead, follow, 4.0),
            "4 m {lead} -> {follow}"
        );
    }
}

/// Once the conflicting vehicle has waited PLATOON_MAX_WAIT, nothing joins past it: the
/// follower waits behind it (Theorem 5's bound); a moment before, it still joins.
#[test]
fn nothing_joins_past_a_vehicle_that_waited_the_longest_wait() {
    let wait = PLATOON_MAX_WAIT.as_secs::<f64>();
    let (m, _) = platoon_scene(Algorithm::Platoon, 20.0, 0.5 + wait);
    assert!(!m.permitted(3), "waited exactly the bound");
    let (m, _) = platoon_scene(Algorithm::Platoon, 20.0, 0.5 + wait - 0.01);
    assert!(m.permitted(3), "just under the bound");
}

/// A PLATOON manager whose vehicle 1 on `a` was granted at its line at t = 0 and stands
/// 3 m inside A_S at t = 0.5, when vehicle 2 on `z` arrived at its line; scanned at 0.5.
fn holder_and_waiter(l: &Layout<f64>, a: usize, z: usize) -> Manager<f64, 8> {
    let mut m = manager(l, Algorithm::Platoon);
    m.observe(&at(l, 1, a, 0.5, 0.0), secs(0.0)).unwrap();
    m.update(secs(0.0));
    m.observe(&at(l, 1, a, -3.0, 0.0), secs(0.5)).unwrap();
    m.observe(&at(l, 2, z, 0.5, 0.0), secs(0.5)).unwrap();
    m.update(secs(0.5));
    m
}

/// Only past vehicles that could not go: `z` (south, inner, straight) waits since 0.5 s
/// behind holder 1 (west, inner, straight, inside A_S) and by 61 s has waited the bound;
/// `y` (west, outer, straight) fits beside 1 but not beside `z`, so the bound refuses it;
/// `c` (south, outer, right) fits beside 1 and `z` but merges into `y`'s outlet. `y` could
/// go now, so `c` does not join past it — though without `y` it is granted.
#[test]
fn nothing_joins_past_a_vehicle_that_could_go() {
    let l = layout();
    let (a, z, y) = (
        route(&l, 0, Movement::Straight),
        route(&l, 1, Movement::Straight),
        l.route_index(0, 1, Movement::Straight).unwrap(),
    );
    let c = l.route_index(1, 1, Movement::Right).unwrap();
    assert!(l.conflict(a, z) && l.conflict(z, y) && l.conflict(y, c));
    assert!(!l.conflict(a, y) && !l.conflict(a, c) && !l.conflict(z, c));
    for with_y in [true, false] {
        let mut m = holder_and_waiter(&l, a, z);
        assert!(!m.permitted(2));
        for id in [1, 2] {
            let (r, to_line) = if id == 1 { (a, -3.0) } else { (z, 0.5) };
            m.observe(&at(&l, id, r, to_line, 0.0), secs(61.0)).unwrap();
        }
        if with_y {
            m.observe(&at(&l, 3, y, 0.5, 0.0), secs(61.0)).unwrap();
        }
        m.observe(&at(&l, 4, c, 0.5, 0.0), secs(61.0)).unwrap();
        m.update(secs(61.0));
        assert!(m.permitted(1) && !m.permitted(2) && !m.permitted(3));
        assert_eq!(m.permitted(4), !with_y, "with y: {with_y}");
    }
}

/// A flow may start in one scan: a vehicle granted now blocks a crossing one, and a
/// vehicle that fits beside the first joins it, while a follower of a vehicle that is
/// not granted gets nothing (it cannot pass it).
#[test]
fn a_vehicle_granted_in_the_same_scan_starts_the_flow() {
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let w = route(&l, 1, Movement::Straight);
    let mut m = manager(&l, Algorithm::Platoon);
    m.observe(&at(&l, 1, a, 0.5, 0.0), secs(0.0)).unwrap();
    m.observe(&at(&l, 2, w, 0.5, 0.0), secs(0.1)).unwrap();
    m.observe(&at(&l, 3, a, 10.0, 5.0), secs(0.2)).unwrap();
    m.update(secs(0.2));
    assert!(m.permitted(1) && !m.permitted(2) && m.permitted(3));
    // The crossing vehicle first: nobody of lane a is granted, so no platoon.
    let mut m = manager(&l, Algorithm::Platoon);
    m.observe(&at(&l, 2, w, 0.5, 0.0), secs(0.0)).unwrap();
    m.observe(&at(&l, 1, a, 0.5, 0.0), secs(0.1)).unwrap();
    m.observe(&at(&l, 3, a, 10.0, 5.0), secs(0.2)).unwrap();
    m.update(secs(0.2));
    assert!(m.permitted(2) && !m.permitted(1) && !m.permitted(3));
}

/// Nobody joins the flow behind a suspect on its own lane (its planner follows what the
/// suspect says of itself).
#[test]
fn nobody_joins_the_flow_behind_a_suspect() {
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let w = route(&l, 1, Movement::Straight);
    let mut m = manager(&l, Algorithm::Platoon);
    m.observe(&at(&l, 1, a, 0.5, 0.0), secs(0.0)).unwrap();
    m.update(secs(0.0));
    m.observe(&at(&l, 2, w, 0.5, 0.0), secs(0.5)).unwrap();
    m.update(secs(0.5));
    // 1 claims to have jumped 40 m: a suspect, holding its zones for good.
    assert_eq!(
        m.observe(&at(&l, 1, a, -40.0, 5.0), secs(0.6)),
        Err(ManagerError::Implausible)
    );
    m.observe(&at(&l, 3, a, 15.0, 5.0), secs(0.6)).unwrap();
    m.update(secs(0.6));
    assert!(entry(&m, 1).suspect && !m.permitted(3));
}

/// A suspect measured by the roadside sensor is managed by its measurements: its record
/// follows the sensor, it is granted as any vehicle, a permission it won by a lie is
/// withdrawn once the sensor puts it behind an unpermitted vehicle on its lane, it holds
/// its zones while surely past its line, and it leaves the list when measured gone.
/// Without a sensor a suspect is never granted (its word that it left would never be
/// taken).
#[test]
fn a_suspect_the_roadside_sensor_measures_is_managed_by_its_measurements() {
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let (start, exit) = {
        let p = &l.route(a).unwrap().path;
        (p.entry(), p.exit())
    };
    let centre = |to_line: f64| start - HALF - to_line;
    let err = 0.1;
    // Vehicle 1 claims to stand 0.5 m before its line; it stands 20 m before it.
    let lying = |sensor: bool| {
        let mut m = manager(&l, Algorithm::Fifo);
        if sensor {
            m.set_roadside_sensor(Some(err)).unwrap();
        }
        m.observe(&at(&l, 1, a, 0.5, 0.0), secs(0.0)).unwrap();
        m
    };
    let mut m = lying(true);
    assert_eq!(
        m.measure(1, centre(20.0)),
        Err(planner_core::crossing::ManagerError::Implausible)
    );
    m.measure(1, centre(20.0)).unwrap();
    let e = entry(&m, 1);
    assert!(e.suspect && e.managed() && !e.committed);
    assert!(
        (e.to_line - 20.0).abs() < 1e-9,
        "follows the sensor: {}",
        e.to_line
    );
    m.update(secs(0.1));
    assert!(m.permitted(1), "granted on its measurements");
    // Surely past its line (by more than the error): committed; just within it: not.
    m.measure(1, centre(-err + 0.01)).unwrap();
    assert!(!entry(&m, 1).committed);
    m.measure(1, centre(-err - 0.01)).unwrap();
    assert!(entry(&m, 1).committed);
    // Its report that it left changes nothing; the sensor's does.
    let gone = CrossingReport {
        s: exit + HALF + 1.0,
        ..at(&l, 1, a, 0.0, 5.0)
    };
    assert!(m.observe(&gone, secs(0.2)).is_err());
    assert!(m.holds(1));
    m.measure(1, exit + HALF + err - 0.01).unwrap();
    assert!(m.holds(1), "its rear may still be in A_S");
    m.measure(1, exit + HALF + err + 0.01).unwrap();
    assert!(m.entries().is_empty(), "measured gone");

    // Without a sensor the same lie, once caught, is never granted.
    let mut m = lying(false);
    let jump = CrossingReport {
        s: centre(0.5) + 30.0,
        ..at(&l, 1, a, 0.5, 0.0)
    };
    assert!(m.observe(&jump, secs(0.1)).is_err());
    m.update(secs(0.2));
    assert!(entry(&m, 1).suspect && !entry(&m, 1).managed());
    assert!(!m.permitted(1));

    // A permission won by a lie: vehicle 1 claims to be first at the line and is granted;
    // the sensor puts it behind vehicle 2, which waits unpermitted on the same lane.
    let mut m = lying(true);
    m.update(secs(0.0));
    assert!(m.permitted(1));
    m.observe(&at(&l, 2, a, 1.0, 0.0), secs(0.0)).unwrap();
    assert!(m.measure(1, centre(12.0)).is_err());
    assert!(entry(&m, 1).committed, "flagged holding a permission");
    m.measure(1, centre(12.0)).unwrap();
    m.update(secs(0.1));
    assert!(!m.permitted(1), "withdrawn: it cannot pass vehicle 2");
    m.update(secs(0.2));
    assert!(m.permitted(2), "the vehicle ahead goes first");

    // The roadside sensor's error is bounded as the onboard sensors' is.
    let mut m = manager(&l, Algorithm::Fifo);
    assert!(m.set_roadside_sensor(Some(1.01)).is_err());
    assert!(m.set_roadside_sensor(Some(1.0)).is_ok());
}

/// All-Way STOP serves only vehicles that stopped at their line. A measured suspect
/// reports nothing, so the sensor says when it stands there: its front within the stop
/// zone, widened by the sensor's error either way — and not beyond.
#[test]
fn a_measured_suspect_stops_at_its_line_by_the_sensor() {
    use planner_core::crossing::STOP_LINE_ZONE_M;
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let start = l.route(a).unwrap().path.entry();
    let centre = |to_line: f64| start - HALF - to_line;
    let err = 0.1;
    let served = |to_line: f64| {
        let mut m = manager(&l, Algorithm::AllWayStop);
        m.set_roadside_sensor(Some(err)).unwrap();
        // It claims to stand 40 m back (not stopped at its line); the sensor disagrees.
        m.observe(&at(&l, 1, a, 40.0, 0.0), secs(0.0)).unwrap();
        assert!(m.measure(1, centre(to_line)).is_err());
        m.measure(1, centre(to_line)).unwrap();
        m.update(secs(0.1));
        (entry(&m, 1).stopped_at.is_some(), m.permitted(1))
    };
    for to_line in [
        -err + 0.01,
        0.0,
        STOP_LINE_ZONE_M,
        STOP_LINE_ZONE_M + err - 0.01,
    ] {
        assert_eq!(
            served(to_line),
            (true, true),
            "front {to_line} m before its line"
        );
    }
    for to_line in [STOP_LINE_ZONE_M + err + 0.01, 20.0] {
        assert_eq!(
            served(to_line),
            (false, false),
            "front {to_line} m before its line"
        );
    }
    // Surely past its line: committed, not stopped there.
    assert_eq!(served(-err - 0.01), (false, false));
}

/// A measured suspect is committed only while its front is *surely* past its line: a
/// measurement that puts it exactly the sensor's error past it may be of a vehicle
/// standing at the line (values chosen exact in binary).
#[test]
fn a_measured_suspect_exactly_its_error_past_its_line_is_not_committed() {
    let l = layout();
    let a = route(&l, 0, Movement::Straight);
    let start = l.route(a).unwrap().path.entry();
    let err = 0.25;
    let mut m = manager(&l, Algorithm::Fifo);
    m.set_roadside_sensor(Some(err)).unwrap();
    m.observe(&at(&l, 1, a, 40.0, 0.0), secs(0.0)).unwrap();
    let centre = start - HALF + err;
    assert!(m.measure(1, centre).is_err(), "a suspect");
    m.measure(1, centre).unwrap();
    assert_eq!(entry(&m, 1).to_line, -err);
    assert!(!entry(&m, 1).committed);
}

/// Only the routes that block a vehicle count against its joining: `z` has waited the
/// bound (61 s) behind holder 1 but does not cross `c`; `y`, which crosses both holder 1
/// and `c`, could not go (stuck behind 1) and arrived just now. `c` joins the flow past
/// `y` — `z`'s long wait is not in its way.
#[test]
fn only_a_blocking_route_that_waited_the_bound_stops_a_joiner() {
    let l = layout();
    let n = l.routes.len();
    let distinct =
        |rs: [usize; 4]| (0..4).all(|i| (i + 1..4).all(|j| inlet(&l, rs[i]) != inlet(&l, rs[j])));
    let scene = (0..n)
        .flat_map(|a| (0..n).map(move |z| (a, z)))
        .flat_map(|(a, z)| (0..n).map(move |y| (a, z, y)))
        .flat_map(|(a, z, y)| (0..n).map(move |c| [a, z, y, c]))
        .find(|&[a, z, y, c]| {
            distinct([a, z, y, c])
                && l.conflict(a, z)
                && l.conflict(a, y)
                && l.conflict(y, c)
                && !l.conflict(a, c)
                && !l.conflict(z, c)
        });
    let [a, z, y, c] = scene.expect("the SPEC §8 layout has such routes");
    let mut m = holder_and_waiter(&l, a, z);
    assert!(m.permitted(1) && !m.permitted(2));
    m.observe(&at(&l, 1, a, -3.0, 0.0), secs(61.0)).unwrap();
    m.observe(&at(&l, 2, z, 0.5, 0.0), secs(61.0)).unwrap();
    m.observe(&at(&l, 3, y, 0.5, 0.0), secs(61.0)).unwrap();
    m.observe(&at(&l, 4, c, 0.5, 0.0), secs(61.0)).unwrap();
    m.update(secs(61.0));
    assert!(!m.permitted(2) && !m.permitted(3), "both cross holder 1");
    assert!(m.permitted(4), "routes {a} {z} {y} {c}");
}
