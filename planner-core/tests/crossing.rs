//! The intersection manager: the liveness gap of the paper's Concurrent Crossing (SPEC
//! §7) on a constructed arrival stream, the bounded wait of the starvation-free variant,
//! and the permission invariants of every algorithm.

use planner_core::crossing::{Algorithm, CrossingReport, Manager};
use planner_core::intersection::{Layout, LayoutSpec, CONFLICT_SAMPLE_M, ROUTES};
use planner_core::{Instant, Params};

/// `t` seconds into a test, 1,000 s after the managers' start (past their quiet time).
fn secs(t: f64) -> Instant {
    Instant::from_micros(((1000.0 + t) * 1e6).round() as u64)
}

/// A manager that started at the epoch: its start-up quiet time is over by [`secs`]`(0)`.
fn manager<const CAP: usize>(l: &Layout<f64>, alg: Algorithm) -> Manager<f64, CAP> {
    let mut m = Manager::new(l.clone(), alg);
    m.update(Instant::EPOCH);
    m
}

fn layout() -> Layout<f64> {
    let p = Params::<f64>::table_i();
    Layout::new(&p, LayoutSpec::spec8(&p)).unwrap()
}

/// Routes a, x, y with a ⊗ x, a ⊗ y and x, y compatible.
fn starving_triple(l: &Layout<f64>) -> (u8, u8, u8) {
    for a in 0..ROUTES {
        for x in 0..ROUTES {
            for y in 0..ROUTES {
                if l.conflict(a, x) && l.conflict(a, y) && !l.conflict(x, y) && x != a && y != a {
                    return (a as u8, x as u8, y as u8);
                }
            }
        }
    }
    panic!("no such routes in the layout");
}

#[derive(Clone, Copy)]
enum At {
    Waiting,
    Inside,
    Gone,
}

fn report(l: &Layout<f64>, id: u16, route: u8, at: At) -> CrossingReport<f64> {
    let path = l.route(usize::from(route)).unwrap().path;
    let s = match at {
        At::Waiting => path.entry() - 0.5 - 2.25,
        At::Inside => path.entry() + 3.0,
        At::Gone => path.exit() + 2.25 + 0.1,
    };
    CrossingReport {
        id,
        route,
        s,
        v: if matches!(at, At::Waiting) { 0.0 } else { 10.0 },
        length: 4.5,
        brake: None,
    }
}

/// The constructed stream: x- and y-vehicles alternate, each arriving while the other
/// kind holds a permission, so some route conflicting with a's is always held. Returns
/// the time at which the a-vehicle (arrived at t = 1, before every y and every later x)
/// was first permitted, if ever within 40 cycles.
fn starve(algorithm: Algorithm) -> Option<u32> {
    let l = layout();
    let (a, x, y) = starving_triple(&l);
    let mut m = manager::<64>(&l, algorithm);
    // Vehicle ids: a = 1; stream vehicles 100.. alternate routes x, y.
    let mut stream: Vec<(u16, u8)> = Vec::new();
    let mut next_id = 100u16;
    let mut inside_since: std::collections::HashMap<u16, u32> = Default::default();
    let mut first_permit = None;
    for cycle in 0..40u32 {
        let t = cycle;
        // Arrivals: the first x at t = 0, a at t = 1, then one stream vehicle per cycle,
        // alternating y, x, y, …
        if cycle == 0 {
            stream.push((next_id, x));
            next_id += 1;
        } else {
            stream.push((next_id, if cycle % 2 == 1 { y } else { x }));
            next_id += 1;
        }
        for &(id, r) in stream.iter() {
            let at = match inside_since.get(&id) {
                Some(&since) if t >= since + 2 => At::Gone,
                Some(_) => At::Inside,
                None => At::Waiting,
            };
            m.observe(&report(&l, id, r, at), secs(f64::from(t)))
                .unwrap();
        }
        stream.retain(|(id, _)| inside_since.get(id).is_none_or(|&s| t < s + 2));
        if cycle >= 1 {
            let at = match first_permit {
                None => At::Waiting,
                Some(p) if t < p + 2 => At::Inside,
                Some(_) => At::Gone,
            };
            m.observe(&report(&l, 1, a, at), secs(f64::from(t)))
                .unwrap();
        }
        m.update(secs(100.0));
        // Invariant of every algorithm: permitted routes are pairwise compatible, except
        // the pipelined algorithm's followers on one route.
        let held: Vec<_> = m.entries().iter().filter(|e| e.permitted).collect();
        for (i, p) in held.iter().enumerate() {
            for q in held.iter().skip(i + 1) {
                let pipelined_follow = algorithm.pipelined() && p.route == q.route;
                assert!(
                    !l.conflict(usize::from(p.route), usize::from(q.route)) || pipelined_follow,
                    "{algorithm:?}: conflicting routes {} and {} both permitted",
                    p.route,
                    q.route
                );
            }
        }
        for &(id, _) in stream.iter() {
            if m.permitted(id) {
                inside_since.entry(id).or_insert(t);
            }
        }
        if first_permit.is_none() && m.permitted(1) {
            first_permit = Some(t);
        }
    }
    first_permit
}

#[test]
fn concurrent_crossing_as_written_starves_an_earlier_vehicle() {
    assert_eq!(
        starve(Algorithm::Concurrent),
        None,
        "the paper's algorithm lets later vehicles pass forever"
    );
}

#[test]
fn the_fair_variant_bounds_the_wait() {
    // a arrives at t = 1 behind the first x (held until it leaves at t = 2): permitted
    // as soon as that x is out, before any later conflicting vehicle.
    let t = starve(Algorithm::ConcurrentFair).expect("never starved");
    assert!(t <= 3, "permitted at {t}");
    let t = starve(Algorithm::Pipelined).expect("never starved");
    assert!(t <= 3, "permitted at {t}");
}

#[test]
fn fifo_and_stop_1_permit_one_at_a_time_and_bad_reports_change_nothing() {
    let l = layout();
    for alg in [Algorithm::Fifo, Algorithm::AllWayStopSingle] {
        let mut m = manager::<8>(&l, alg);
        for (id, r) in [(1u16, 0u8), (2, 8), (3, 5)] {
            m.observe(&report(&l, id, r, At::Waiting), secs(f64::from(id)))
                .unwrap();
        }
        m.update(secs(100.0));
        let held: Vec<_> = m
            .entries()
            .iter()
            .filter(|e| e.permitted)
            .map(|e| e.id)
            .collect();
        assert_eq!(held, vec![1], "{alg:?}");
        m.update(secs(100.0));
        assert_eq!(m.entries().iter().filter(|e| e.permitted).count(), 1);
        // Vehicle 1 leaves: the next in order is served.
        m.observe(&report(&l, 1, 0, At::Gone), secs(9.0)).unwrap();
        m.update(secs(100.0));
        assert!(m.permitted(2) && !m.permitted(3), "{alg:?}");
        assert_eq!(m.crossed(), 1);
        let before = m.entries().to_vec();
        let mut bad = report(&l, 3, 5, At::Waiting);
        bad.s = f64::NAN;
        assert!(m.observe(&bad, secs(10.0)).is_err());
        bad = report(&l, 3, 5, At::Waiting);
        bad.route = 200;
        assert!(m.observe(&bad, secs(10.0)).is_err());
        bad = report(&l, 3, 6, At::Waiting);
        assert!(m.observe(&bad, secs(10.0)).is_err(), "route change");
        assert_eq!(m.entries(), &before[..]);
    }
    // Both All-Way STOPs serve only vehicles that have stopped at their line (a vehicle
    // still rolling toward it, 1.5 m out at 2 m/s, can stop: dS(2) = 0.27 m).
    for alg in [Algorithm::AllWayStop, Algorithm::AllWayStopSingle] {
        let mut m = manager::<8>(&l, alg);
        let mut moving = report(&l, 1, 0, At::Waiting);
        moving.v = 2.0;
        moving.s -= 1.0;
        m.observe(&moving, secs(0.0)).unwrap();
        m.update(secs(100.0));
        assert!(!m.permitted(1), "{alg:?}");
        m.observe(&report(&l, 1, 0, At::Waiting), secs(1.0))
            .unwrap();
        m.update(secs(100.0));
        assert!(m.permitted(1), "{alg:?}");
    }
}

/// All-Way STOP as drivers keep it: stopped vehicles on routes that do not conflict go
/// together; a vehicle never goes ahead of an earlier-stopped one it conflicts with, nor
/// while a conflicting one holds A_S; STOP-1 lets one go at a time.
#[test]
fn all_way_stop_lets_stopped_vehicles_that_do_not_conflict_go_together() {
    let l = layout();
    let route = |heading: u8| {
        l.route_index(heading, 0, planner_core::intersection::Movement::Straight)
            .unwrap() as u8
    };
    let (east, north, west) = (route(0), route(1), route(2));
    assert!(!l.conflict(usize::from(east), usize::from(west)));
    assert!(l.conflict(usize::from(east), usize::from(north)));
    assert!(l.conflict(usize::from(north), usize::from(west)));
    // East and west stopped first: both go under STOP, one under STOP-1.
    for (alg, together) in [
        (Algorithm::AllWayStop, true),
        (Algorithm::AllWayStopSingle, false),
    ] {
        let mut m = manager::<8>(&l, alg);
        m.observe(&report(&l, 1, east, At::Waiting), secs(1.0))
            .unwrap();
        m.observe(&report(&l, 2, west, At::Waiting), secs(2.0))
            .unwrap();
        m.observe(&report(&l, 3, north, At::Waiting), secs(3.0))
            .unwrap();
        m.update(secs(3.0));
        assert!(m.permitted(1) && !m.permitted(3), "{alg:?}");
        assert_eq!(m.permitted(2), together, "{alg:?}");
    }
    // North stopped between them: west waits for north, which waits for east.
    let mut m = manager::<8>(&l, Algorithm::AllWayStop);
    m.observe(&report(&l, 1, east, At::Waiting), secs(1.0))
        .unwrap();
    m.observe(&report(&l, 3, north, At::Waiting), secs(2.0))
        .unwrap();
    m.observe(&report(&l, 2, west, At::Waiting), secs(3.0))
        .unwrap();
    m.update(secs(3.0));
    assert!(m.permitted(1) && !m.permitted(3) && !m.permitted(2));
    // East gone: north goes; west still waits (north holds A_S).
    m.observe(&report(&l, 1, east, At::Gone), secs(4.0))
        .unwrap();
    m.update(secs(4.0));
    assert!(m.permitted(3) && !m.permitted(2));
    // Stopped at the same instant on conflicting routes: the priority order (by lane, in
    // Ψ's order) decides.
    let lane = |r: u8| l.inlet_index(l.route(usize::from(r)).unwrap().inlet);
    let (first, second) = if lane(east) < lane(north) {
        (1, 3)
    } else {
        (3, 1)
    };
    let mut m = manager::<8>(&l, Algorithm::AllWayStop);
    m.observe(&report(&l, 3, north, At::Waiting), secs(1.0))
        .unwrap();
    m.observe(&report(&l, 1, east, At::Waiting), secs(1.0))
        .unwrap();
    m.update(secs(1.0));
    assert!(m.permitted(first) && !m.permitted(second));
    // A vehicle that has not stopped yet is not served, and holds back no one.
    let mut m = manager::<8>(&l, Algorithm::AllWayStop);
    let mut rolling = report(&l, 3, north, At::Waiting);
    rolling.v = 2.0;
    rolling.s -= 1.0;
    m.observe(&rolling, secs(1.0)).unwrap();
    m.observe(&report(&l, 2, west, At::Waiting), secs(2.0))
        .unwrap();
    m.update(secs(2.0));
    assert!(!m.permitted(3) && m.permitted(2));
}

/// Reports rounded by a bus (0.01 m) may put a vehicle up to 5 mm ahead of itself: with
/// the resolution set, the manager keeps it until its rear is surely past A_S.
#[test]
fn position_resolution_keeps_a_vehicle_until_it_has_surely_left() {
    let l = layout();
    let exit = l.route(0).unwrap().path.exit();
    let mut almost = report(&l, 1, 0, At::Inside);
    let mut exact = manager::<8>(&l, Algorithm::Fifo);
    let mut rounded = manager::<8>(&l, Algorithm::Fifo);
    assert!(rounded.set_position_resolution(-0.01).is_err());
    assert!(rounded.set_position_resolution(f64::NAN).is_err());
    assert!(rounded.set_position_resolution(1.0).is_err());
    rounded.set_position_resolution(0.01).unwrap();
    for m in [&mut exact, &mut rounded] {
        m.observe(&almost, secs(1.0)).unwrap();
        m.update(secs(100.0));
        assert!(m.holds(1));
    }
    // Reported rear 3 mm past the exit: it may still be 2 mm inside.
    almost.s = exit + 0.5 * almost.length + 0.003;
    exact.observe(&almost, secs(2.0)).unwrap();
    rounded.observe(&almost, secs(2.0)).unwrap();
    assert_eq!((exact.crossed(), exact.entries().len()), (1, 0));
    assert_eq!((rounded.crossed(), rounded.entries().len()), (0, 1));
    assert!(rounded.holds(1));
    // 6 mm past: surely out.
    almost.s += 0.003;
    rounded.observe(&almost, secs(3.0)).unwrap();
    assert_eq!((rounded.crossed(), rounded.entries().len()), (1, 0));
}

/// With reports rounded to 0.01 m, a vehicle ahead on the same route is taken 5 mm
/// longer at each end: the follower's gap shrinks by exactly half a step.
#[test]
fn crossing_planner_bus_resolution_lengthens_the_vehicles_it_hears_of() {
    use planner_core::crossing::CrossingPlanner;
    use planner_core::{CostWeights, Planner};
    let l = layout();
    let p = Params::<f64>::table_i();
    let entry = l.route(0).unwrap().path.entry();
    let gap = |res: f64| {
        let planner = Planner::<f64, 20>::new(p, CostWeights::default()).unwrap();
        let mut c = CrossingPlanner::<f64, 20, 8>::new(planner, 1, 0, 4.5);
        c.set_bus_resolution(res, 0.0).unwrap();
        c.hear_grant(1, secs(10.0));
        let ahead = CrossingReport {
            id: 2,
            route: 0,
            s: entry - 10.0,
            v: 5.0,
            length: 4.5,
            brake: None,
        };
        c.hear_report(&ahead, secs(0.0)).unwrap();
        c.step(&l, entry - 40.0, 5.0, secs(0.0)).unwrap().gap
    };
    let (exact, rounded) = (gap(0.0), gap(0.01));
    assert!(
        (exact - rounded - 0.005).abs() < 1e-12,
        "{exact} vs {rounded}"
    );
    let planner = Planner::<f64, 20>::new(p, CostWeights::default()).unwrap();
    let mut c = CrossingPlanner::<f64, 20, 8>::new(planner, 1, 0, 4.5);
    assert!(c.set_bus_resolution(f64::INFINITY, 0.0).is_err());
    assert!(c.set_bus_resolution(-1e-3, 0.0).is_err());
}

/// A queue on one inlet lane: the leader 0.5 m before its line, the follower 10 m
/// behind it. Their routes are chosen so that the paper's tie-break (route index Ψ)
/// ranks the follower first.
fn queue(l: &Layout<f64>) -> (CrossingReport<f64>, CrossingReport<f64>) {
    use planner_core::intersection::Movement;
    let leader_route = l.route_index(0, 0, Movement::Left).unwrap() as u8;
    let follower_route = l.route_index(0, 0, Movement::Straight).unwrap() as u8;
    assert!(follower_route < leader_route, "Ψ puts the follower first");
    let leader = report(l, 1, leader_route, At::Waiting);
    let mut follower = report(l, 2, follower_route, At::Waiting);
    follower.s = leader.s - 10.0;
    follower.v = 0.0;
    (leader, follower)
}

/// The queue deadlock the liveness sweeps found, first cause: vehicles that arrive together (all that start
/// inside A_C) were ordered by Ψ, which can rank a follower before its leader on the
/// same lane. Every live algorithm now serves the leader first.
#[test]
fn vehicles_arriving_together_are_served_in_lane_order() {
    let l = layout();
    let (leader, follower) = queue(&l);
    for alg in [
        Algorithm::Fifo,
        Algorithm::ConcurrentFair,
        Algorithm::Pipelined,
    ] {
        let mut m = manager::<8>(&l, alg);
        m.observe(&follower, secs(0.0)).unwrap();
        m.observe(&leader, secs(0.0)).unwrap();
        m.update(secs(100.0));
        assert!(m.permitted(1), "{alg:?}: the leader is served first");
        assert!(!m.permitted(2), "{alg:?}: not the follower ahead of it");
    }
    // The paper's algorithm as written keeps Ψ: the follower is permitted, the leader
    // (sharing its inlet, hence conflicting) is not — the deadlock it cannot leave.
    let mut m = manager::<8>(&l, Algorithm::Concurrent);
    m.observe(&follower, secs(0.0)).unwrap();
    m.observe(&leader, secs(0.0)).unwrap();
    for _ in 0..3 {
        m.update(secs(100.0));
        assert!(m.permitted(2) && !m.permitted(1));
    }
}

/// Second cause: a follower can register first (its leader's reports were lost or
/// delayed) and be permitted; it cannot use the permission past its unpermitted leader.
/// The permission is withdrawn and passes to the leader.
#[test]
fn a_permission_blocked_by_an_unpermitted_leader_is_withdrawn() {
    let l = layout();
    let (leader, follower) = queue(&l);
    let mut m = manager::<8>(&l, Algorithm::Fifo);
    m.observe(&follower, secs(0.0)).unwrap();
    m.update(secs(100.0));
    assert!(m.permitted(2));
    m.observe(&leader, secs(1.0)).unwrap();
    m.update(secs(100.0));
    assert!(m.permitted(1) && !m.permitted(2));
}

/// A manager that restarts while a lease it gave before is still valid: the vehicle
/// holding that lease enters A_S on it, so nothing crossing its route may be granted
/// until that vehicle has been heard inside A_S (then it holds its zones) — whatever the
/// algorithm. The quiet time at start-up is what guarantees it; without it the restarted
/// manager would grant the crossing route at once.
#[test]
fn a_restarted_manager_grants_nothing_an_old_lease_could_conflict_with() {
    use planner_core::crossing::Lease;
    use planner_core::Duration;
    let l = layout();
    let (ra, _, _) = starving_triple(&l);
    // A crossing route from another inlet lane: `a` drives up to and across `b`'s line.
    let inlet = |r: u8| l.route(usize::from(r)).unwrap().inlet;
    let rb = (0..ROUTES as u8)
        .find(|&r| l.conflict(usize::from(ra), usize::from(r)) && inlet(r) != inlet(ra))
        .unwrap();
    let lease = Lease::default();
    let ms = |k: u64| secs(0.0).saturating_add(Duration::from_millis(k));
    let (entry, exit) = {
        let p = l.route(usize::from(ra)).unwrap().path;
        (p.entry(), p.exit())
    };
    for alg in Algorithm::ALL {
        // The old manager granted `a` at 0 ms (lease until 100 ms); it went down at 5 ms
        // and a new one starts at 10 ms. `a` drives on at 10 m/s from 7 m before its line
        // (able to stop there until its lease lapses: dS(10) = 6.4 m); then, too close to
        // stop, it enters A_S at 710 ms and is out 3.0 s later. The new manager hears `b`
        // waiting at its line at once, `a` (its reports delayed) from 20 ms on: by
        // arrival, `b` comes first.
        let mut m = Manager::<f64, 8>::new(l.clone(), alg);
        m.set_lease(lease).unwrap();
        let a_at = |t: u64| CrossingReport {
            id: 1,
            route: ra,
            s: entry - 2.25 - 7.0 + 10.0 * (t - 10) as f64 * 1e-3,
            v: 10.0,
            length: 4.5,
            brake: None,
        };
        let mut t = 10;
        let mut granted_b_at = None;
        while t <= 5000 {
            let a = a_at(t);
            if t >= 20 && a.s - 2.25 < exit + 1.0 {
                m.observe(&a, ms(t)).unwrap();
            }
            m.observe(&report(&l, 2, rb, At::Waiting), ms(t)).unwrap();
            m.update(ms(t));
            if m.permitted(2) && granted_b_at.is_none() {
                granted_b_at = Some(t);
            }
            t += 10;
        }
        // Out of A_S — or, for the pipelined algorithm, past its conflict zone with b.
        let clear = if alg.pipelined() {
            entry + l.zone_end[usize::from(ra)][usize::from(rb)] + CONFLICT_SAMPLE_M
        } else {
            exit + 2.25
        };
        let a_out = 10 + ((clear - (entry - 2.25 - 7.0)) / 10.0 * 1e3) as u64;
        assert!(
            granted_b_at.is_some_and(|g| g >= a_out),
            "{alg:?}: b granted at {granted_b_at:?} ms, a clear of it at {a_out} ms"
        );
    }
}

/// The quiet time is the lease, then twice the notification bound; before a manager's
/// first update it is quiet too.
#[test]
fn quiet_time_follows_the_lease() {
    use planner_core::crossing::Lease;
    use planner_core::Duration;
    let l = layout();
    let mut m = Manager::<f64, 8>::new(l, Algorithm::Fifo);
    let lease = Lease {
        length: Duration::from_millis(150),
        notify: Duration::from_millis(40),
    };
    assert_eq!(lease.quiet(), Duration::from_millis(230));
    m.set_lease(lease).unwrap();
    assert!(m.quiet(Instant::from_secs(5)));
    m.update(Instant::from_secs(5));
    assert!(m.quiet(Instant::from_millis(5_229)));
    assert!(!m.quiet(Instant::from_millis(5_230)));
    assert_eq!(
        m.lease_until(Instant::from_secs(7)),
        Instant::from_millis(7_150)
    );
    assert!(m
        .set_lease(Lease {
            length: Duration::ZERO,
            ..lease
        })
        .is_err());
}

/// A vehicle that can no longer stop before its line (its lease lapsed while it was too
/// close, or an earlier incarnation of the manager granted it) holds its zones as a
/// permission would; one that can still stop does not. Rounding is taken against the
/// manager: the vehicle as far forward and as fast as the reports allow.
#[test]
fn a_vehicle_that_cannot_stop_before_its_line_holds_its_zones() {
    let l = layout();
    // Two routes that cross, from different inlets.
    let (ra, rb) = (0..ROUTES)
        .flat_map(|a| (0..ROUTES).map(move |b| (a, b)))
        .find(|&(a, b)| {
            let (x, y) = (l.route(a).unwrap(), l.route(b).unwrap());
            l.conflict(a, b) && x.inlet != y.inlet && x.outlet != y.outlet
        })
        .map(|(a, b)| (a as u8, b as u8))
        .unwrap();
    let entry = l.route(usize::from(ra)).unwrap().path.entry();
    // Front `gap` metres before the line at speed `v`.
    let at = |gap: f64, v: f64| CrossingReport {
        id: 1,
        route: ra,
        s: entry - 2.25 - gap,
        v,
        length: 4.5,
        brake: None,
    };
    let p = Params::<f64>::table_i();
    let ds = |v: f64| planner_core::safety::d_s(&p, v);
    for alg in Algorithm::ALL {
        for (gap, v, committed) in [
            (ds(5.0) - 0.01, 5.0, true),
            (ds(5.0) + 0.01, 5.0, false),
            (0.5, 0.0, false),
            (0.02, 1.0, true),
        ] {
            let mut m = manager::<8>(&l, alg);
            m.observe(&at(gap, v), secs(0.0)).unwrap();
            assert_eq!(m.holds(1), committed, "{alg:?} gap {gap} v {v}");
            // A crossing route waiting at its line is never granted over a committed one.
            m.observe(&report(&l, 2, rb, At::Waiting), secs(0.0))
                .unwrap();
            m.update(secs(100.0));
            if committed {
                assert!(!m.permitted(2), "{alg:?}: granted over a committed vehicle");
            }
        }
        // With rounding: 4 mm too far out and 0.009 m/s too slow to count exactly, but
        // within half a step of 0.01 m and 0.02 m/s.
        let mut m = manager::<8>(&l, alg);
        m.set_position_resolution(0.01).unwrap();
        m.set_speed_resolution(0.02).unwrap();
        m.observe(&at(ds(5.009) + 0.004, 5.0), secs(0.0)).unwrap();
        assert!(m.holds(1), "{alg:?}: rounding taken for the vehicle");
    }
}
