//! Property tests of the paper's multi-lane lemmas (Sec. IV) on our free-space and
//! unicycle code, and behaviour tests of the multi-lane planner.

use planner_core::free_space::FreeSpace;
use planner_core::lane_change::{
    braking_tail_ok, LaneEvent, LaneObservation, LanePlanner, StartBlock,
};
use planner_core::lanes::{Band, Other, Road};
use planner_core::safety::{d_s, max_braking_command};
use planner_core::unicycle::{chord, step, Pose};
use planner_core::{
    CostWeights, FallbackReason, InputError, LaneInputError, Params, Real, StepStatus,
};
use proptest::prelude::*;

fn p() -> Params<f64> {
    Params::table_i()
}

/// One step of (1) exactly as the paper writes it (not our chord form).
fn paper_step(q: Pose<f64>, v: f64, w: f64, h: f64) -> Pose<f64> {
    if w == 0.0 {
        return Pose {
            x: q.x + v * h * q.theta.cos(),
            y: q.y + v * h * q.theta.sin(),
            theta: q.theta,
        };
    }
    Pose {
        x: q.x + v / w * ((q.theta + w * h).sin() - q.theta.sin()),
        y: q.y - v / w * ((q.theta + w * h).cos() - q.theta.cos()),
        theta: q.theta + w * h,
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 10_000,
        // Lemma 7's hypothesis dH > dL excludes a share of the random states.
        max_global_rejects: 200_000,
        ..ProptestConfig::default()
    })]

    /// Lemma 6: D(v, ω) ≤ D(v, 0), with D measured on the paper's own formula (1); and
    /// our chord form of (1) agrees with it.
    #[test]
    fn lemma_6(v in 0.0f64..27.8, rho in 5.3f64..1e4, ccw in any::<bool>(), theta in -0.5f64..0.5) {
        let h = p().h();
        let w = if ccw { v / rho } else { -v / rho };
        let q = Pose { x: 3.0, y: 2.0, theta };
        let a = paper_step(q, v, w, h);
        let d = (a.x - q.x).hypot(a.y - q.y);
        let d0 = {
            let b = paper_step(q, v, 0.0, h);
            (b.x - q.x).hypot(b.y - q.y)
        };
        // The paper's (v/ω)(…) form cancels: its rounding grows like ε·ρ.
        let tol = 1e-15 * (10.0 + rho);
        prop_assert!(d <= d0 + tol, "D(v,ω) = {d} > D(v,0) = {d0}");
        let c = step(q, v, w, h);
        prop_assert!((c.x - a.x).abs() < tol && (c.y - a.y).abs() < tol);
        prop_assert!((chord(v, w, h) - d).abs() < tol);
        // Our chord form has no cancellation, so the inequality holds there exactly.
        prop_assert!(chord(v, w, h) <= chord(v, 0.0, h));
    }

    /// Lemma 7: if dH > dL, max braking with any turning radius in ⟦ρH⟧ (straight, the
    /// sharpest left and right turns the region allows, and the current radius when it is
    /// in the region) keeps the vehicle in the band, satisfies x_{k+1} ≤ x̄ − dS(v_k) and
    /// stops — checked on the free space our code builds.
    #[test]
    fn lemma_7(
        v_prev in 0.0f64..27.8,
        lanes in prop::sample::select(vec![(0u8, 0u8), (0, 1), (1, 0), (1, 2)]),
        y_frac in 0.05f64..0.95,
        theta in -0.2f64..0.2,
        w_prev in -0.3f64..0.3,
        extra in 0.01f64..80.0,
    ) {
        let p = p();
        let road = Road { lanes: 3, lane_width: 3.6, end_x: None };
        let band = road.band(lanes.0, Some(lanes.1)).shrunk(0.5 * p.width());
        let y = band.lo + y_frac * (band.hi - band.lo);
        let pose = Pose { x: 0.0, y, theta };
        let gap = d_s(&p, v_prev) + extra;
        let w_prev = w_prev.clamp(-v_prev / p.rho_min(), v_prev / p.rho_min());
        let fs = FreeSpace::new(&p, pose, v_prev, w_prev, band, gap).unwrap();
        prop_assume!(fs.d_h > fs.d_l);
        prop_assume!(fs.arc_h.theta_plus > 0.0 && fs.arc_h.theta_minus < 0.0);
        let mut curvatures = vec![0.0, fs.arc_h.kappa_plus, -fs.arc_h.kappa_minus];
        let k_prev = if v_prev > 0.0 { w_prev / v_prev } else { 0.0 };
        if k_prev <= fs.arc_h.kappa_plus && -k_prev <= fs.arc_h.kappa_minus {
            curvatures.push(k_prev);
        }
        for kappa in curvatures {
            let (mut q, mut v, mut path) = (pose, v_prev, 0.0);
            let mut stopped = false;
            for _ in 0..400 {
                v = max_braking_command(&p, v);
                q = step(q, v, v * kappa, p.h());
                path += v * p.h();
                // (v): inside the band; (iv): x_{k+1} − x_t ≤ path ≤ dH − dS(v_k).
                prop_assert!(q.y >= band.lo - 1e-9 && q.y <= band.hi + 1e-9,
                    "κ={kappa}: y={} outside [{}, {}]", q.y, band.lo, band.hi);
                prop_assert!(q.x - pose.x <= path + 1e-12);
                prop_assert!(path + d_s(&p, v) <= fs.d_h + 1e-9);
                if v == 0.0 { stopped = true; break; }
            }
            prop_assert!(stopped);
        }
    }
}

fn other(id: u16, x: f64, v: f64, lane: u8) -> Other<f64> {
    Other::v2v(id, x, v, 4.5, lane, 0.0)
}

fn obs<'a>(
    x: f64,
    y: f64,
    v: f64,
    others: &'a [Other<f64>],
    target: u8,
) -> LaneObservation<'a, f64> {
    LaneObservation {
        pose: Pose { x, y, theta: 0.0 },
        v_prev: v,
        omega_prev: 0.0,
        others,
        road: Road {
            lanes: 3,
            lane_width: 3.6,
            end_x: None,
        },
        target_lane: target,
        target: 0.0,
        v_ref: v,
    }
}

#[test]
fn declares_then_starts_then_completes() {
    let mut pl = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), 0).unwrap();
    let c = pl.step(&obs(0.0, 1.8, 15.0, &[], 1)).unwrap();
    assert_eq!(c.event, Some(LaneEvent::Declared(1)));
    assert_eq!(c.beta, Some(1));
    assert_eq!((pl.lane(), pl.alpha(), pl.beta()), (0, None, Some(1)));
    // Drive the exact model until the change completes.
    let (mut q, mut v, mut w) = (
        Pose {
            x: 0.0,
            y: 1.8,
            theta: 0.0,
        },
        c.v,
        c.omega,
    );
    let mut started = false;
    for _ in 0..1000 {
        q = step(q, v, w, 0.01);
        let mut o = obs(q.x, q.y, v, &[], 1);
        o.pose = q;
        o.omega_prev = w;
        let c = pl.step(&o).unwrap();
        assert!(
            matches!(c.status, StepStatus::Solved { .. }),
            "{:?}",
            c.status
        );
        if c.event == Some(LaneEvent::Started(1)) {
            started = true;
            assert_eq!((pl.lane(), pl.alpha(), pl.beta()), (0, Some(1), None));
        }
        if c.event == Some(LaneEvent::Completed(1)) {
            assert!(started);
            assert_eq!((c.lane, c.alpha, c.beta), (1, None, None));
            assert_eq!((pl.lane(), pl.alpha(), pl.beta()), (1, None, None));
            assert!(
                (q.y - 5.4).abs() < 0.5,
                "ends near lane 1's centre, y = {}",
                q.y
            );
            return;
        }
        v = c.v;
        w = c.omega;
    }
    panic!("the change did not complete in 10 s");
}

/// SPEC's choice: (17) is tested against every vehicle behind in the target lane, not
/// only the nearest: a fast vehicle further back blocks the start.
#[test]
fn every_vehicle_behind_is_checked() {
    let p = p();
    let near_slow = other(2, -12.0, 1.0, 1);
    let far_fast = other(3, -40.0, 27.8, 1);
    assert!(
        d_s(&p, 27.8) + 5.0 > 40.0,
        "the far one needs more room than it has"
    );
    for others in [vec![near_slow], vec![near_slow, far_fast]] {
        let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
        pl.step(&obs(0.0, 1.8, 15.0, &others, 1)).unwrap();
        let c = pl.step(&obs(0.15, 1.8, 15.0, &others, 1)).unwrap();
        let started = c.event == Some(LaneEvent::Started(1));
        assert_eq!(started, others.len() == 1, "others: {}", others.len());
    }
}

/// SPEC §9: a vehicle behind in the target lane known only from stale data blocks the
/// start, however far back it is.
#[test]
fn stale_data_behind_blocks_a_start() {
    for (age, starts) in [(0.0, true), (0.3, false)] {
        let mut far = other(2, -200.0, 0.0, 1);
        far.age = age;
        let others = [far];
        let mut pl = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), 0).unwrap();
        pl.step(&obs(0.0, 1.8, 15.0, &others, 1)).unwrap();
        let c = pl.step(&obs(0.15, 1.8, 15.0, &others, 1)).unwrap();
        assert_eq!(c.event == Some(LaneEvent::Started(1)), starts, "age {age}");
    }
}

/// The Yield Protocol: a vehicle ahead in ≺ (same x, higher lane) that intends to enter
/// my lane is my leader; I brake (and stay safe), it does not.
#[test]
fn the_lower_vehicle_yields() {
    let mut me = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), 0).unwrap();
    let mut them = other(2, 0.0, 15.0, 1);
    them.beta = Some(0);
    let c = me.step(&obs(0.0, 1.8, 15.0, &[them], 0)).unwrap();
    assert_eq!(c.status, StepStatus::Fallback(FallbackReason::Yield));
    assert!((c.v - (15.0 - 0.079)).abs() < 1e-12);
    // Behind me in ≺ (lower lane), the same intention does not make me yield.
    let mut me = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), 1).unwrap();
    let mut low = other(2, 0.0, 15.0, 0);
    low.beta = Some(1);
    let c = me.step(&obs(0.0, 5.4, 15.0, &[low], 1)).unwrap();
    assert!(matches!(c.status, StepStatus::Solved { .. }));
}

/// (17) is tested against the vehicles changing into the target lane too, not only those
/// in it (SPEC's C⁻_t): a fast vehicle behind, two lanes over, that has started a change
/// into lane 1 blocks the ego's start into lane 1; the same vehicle staying in its lane
/// (its intention known and fresh) does not.
#[test]
fn vehicles_changing_into_the_target_lane_block_a_start() {
    let p = p();
    let mut coming = other(2, -30.0, 27.8, 2);
    assert!(d_s(&p, 27.8) > 30.0, "it could not stop behind the ego");
    let pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
    let check = |one: Other<f64>| {
        let others = [one];
        pl.start_check(&obs(0.0, 1.8, 15.0, &others, 1), 1)
    };
    assert_eq!(check(coming), Ok(()), "staying in lane 2");
    coming.alpha = Some(1);
    assert_eq!(
        check(coming),
        Err(StartBlock::Behind(2)),
        "changing into lane 1"
    );
    // In lane 1 itself: blocked too; far enough back: not.
    assert_eq!(check(other(3, -30.0, 27.8, 1)), Err(StartBlock::Behind(3)));
    assert_eq!(check(other(3, -60.0 - d_s(&p, 27.8), 27.8, 1)), Ok(()));
    // And through step(): declared, then held back while the changer comes.
    let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
    for k in 0..5 {
        let c = pl
            .step(&obs(0.15 * k as f64, 1.8, 15.0, &[coming], 1))
            .unwrap();
        assert_ne!(c.event, Some(LaneEvent::Started(1)), "step {k}");
    }
}

/// The Yield Protocol (20)(21), directly: a vehicle ahead in ≺ that declared my lane is my
/// leader — my command keeps the invariant toward it (slower than without it); one
/// already changing into my lane is my leader too; one declaring another lane is not.
#[test]
fn a_vehicle_declaring_my_lane_ahead_is_yielded_to() {
    let p = p();
    let free = {
        let mut me = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
        me.step(&obs(0.0, 1.8, 20.0, &[], 0)).unwrap().v
    };
    let gap = 4.5 + 0.5 + d_s(&p, 20.0) + 1.0;
    for (beta, alpha, yields) in [
        (Some(0), None, true),
        (None, Some(0), true),
        (Some(2), None, false),
        (None, None, false),
    ] {
        let mut ahead = other(2, gap, 10.0, 1);
        ahead.beta = beta;
        ahead.alpha = alpha;
        let mut me = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
        let c = me.step(&obs(0.0, 1.8, 20.0, &[ahead], 0)).unwrap();
        if yields {
            assert!(
                c.v < free - 0.01,
                "β {beta:?} α {alpha:?}: {} vs {free}",
                c.v
            );
            // It keeps the invariant toward the slower vehicle ahead at its next position.
            let room = gap - 4.5 - 0.5 - c.v * 0.01 + 10.0 * 0.01;
            assert!(room >= d_s(&p, c.v) - 1e-9, "β {beta:?} α {alpha:?}");
        } else {
            assert!(
                (c.v - free).abs() < 1e-9,
                "β {beta:?} α {alpha:?}: {} vs {free}",
                c.v
            );
        }
    }
}

#[test]
fn bad_input_is_rejected_and_changes_nothing() {
    let mut pl = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), 0).unwrap();
    let o = obs(0.0, 1.8, 15.0, &[], 2);
    let mut bad = o;
    bad.pose.y = f64::NAN;
    assert_eq!(pl.step(&bad), Err(LaneInputError::NotFinite));
    let mut bad = o;
    bad.target_lane = 3;
    assert_eq!(pl.step(&bad), Err(LaneInputError::NoSuchLane));
    let mut bad = o;
    bad.pose.y = 5.0;
    assert_eq!(pl.step(&bad), Err(LaneInputError::OutsideBand));
    let ghost = [other(2, 30.0, 10.0, 7)];
    assert_eq!(
        pl.step(&obs(0.0, 1.8, 15.0, &ghost, 2)),
        Err(LaneInputError::NoSuchLane)
    );
    assert_eq!((pl.lane(), pl.alpha(), pl.beta()), (0, None, None));
    // A road end must be a finite coordinate in range, and so must every neighbour's
    // values; a finite road end far ahead is fine.
    let mut end = o;
    end.road.end_x = Some(5000.0);
    assert!(pl.step(&end).is_ok());
    let mut pl = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), 0).unwrap();
    let mut bad = o;
    bad.road.end_x = Some(f64::NAN);
    assert_eq!(pl.step(&bad), Err(LaneInputError::NotFinite));
    let mut bad = o;
    bad.road.end_x = Some(2.0 * f64::MAX_COORD_M);
    assert_eq!(
        pl.step(&bad),
        Err(LaneInputError::Speed(InputError::OutOfRange))
    );
    for field in 0..4 {
        let mut c = other(2, 30.0, 10.0, 1);
        match field {
            0 => c.x = f64::NAN,
            1 => c.v = f64::INFINITY,
            2 => c.length = f64::NAN,
            _ => c.age = f64::NAN,
        }
        let cs = [c];
        assert_eq!(
            pl.step(&obs(0.0, 1.8, 15.0, &cs, 2)),
            Err(LaneInputError::NotFinite),
            "{field}"
        );
    }
    // The fallback certificate rejects a tail that leaves the band.
    let lane0 = Band { lo: 0.0, hi: 3.6 };
    let heading_out = Pose {
        x: 0.0,
        y: 2.6,
        theta: 0.4,
    };
    assert!(!braking_tail_ok(&p(), heading_out, 27.0, lane0));
    assert!(braking_tail_ok(
        &p(),
        Pose {
            theta: 0.0,
            ..heading_out
        },
        27.0,
        lane0
    ));
}

/// The same lane change planned in f32 (the Cortex-M4F precision) completes on the exact
/// model without a fallback.
#[test]
fn lane_change_in_f32() {
    let p32 = Params::<f32>::table_i();
    let mut pl = LanePlanner::<f32, 20>::new(p32, CostWeights::default(), 0).unwrap();
    let road = Road {
        lanes: 2,
        lane_width: 3.6f32,
        end_x: None,
    };
    let (mut q, mut v, mut w) = (
        Pose {
            x: 0.0f32,
            y: 1.8,
            theta: 0.0,
        },
        15.0f32,
        0.0f32,
    );
    for k in 0..1000 {
        let o = LaneObservation {
            pose: q,
            v_prev: v,
            omega_prev: w,
            others: &[],
            road,
            target_lane: 1,
            target: 0.0,
            v_ref: 15.0,
        };
        let c = pl.step(&o).unwrap();
        assert!(
            matches!(c.status, StepStatus::Solved { .. }),
            "step {k}: {:?}",
            c.status
        );
        if c.event == Some(LaneEvent::Completed(1)) {
            assert!((q.y - 5.4).abs() < 0.5);
            return;
        }
        q = step(q, c.v, c.omega, 0.01);
        v = c.v;
        w = c.omega;
    }
    panic!("no completion in f32");
}

/// SPEC §9 on a bus with latency L: β is held for L before a start, and (17) assumes the
/// vehicle behind goes on unaware for L − h more (here it is just far enough back for
/// the paper's synchronous bus, and too close for L = 0.2 s). A non-finite latency is
/// refused and changes nothing.
#[test]
fn notification_latency_delays_the_start_and_widens_seventeen() {
    let p = p();
    let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
    assert_eq!(pl.notify_latency(), p.h());
    assert!(pl.set_notify_latency(f64::NAN).is_err());
    assert_eq!(pl.notify_latency(), p.h());
    // Empty road: the start comes exactly 0.2 s (20 periods) after the declaration.
    pl.set_notify_latency(0.2).unwrap();
    let first = pl.step(&obs(0.0, 1.8, 15.0, &[], 1)).unwrap();
    assert_eq!(first.event, Some(LaneEvent::Declared(1)));
    let mut started_at = None;
    for k in 1..40 {
        let c = pl.step(&obs(0.15 * k as f64, 1.8, 15.0, &[], 1)).unwrap();
        if c.event == Some(LaneEvent::Started(1)) {
            started_at = Some(k);
            break;
        }
    }
    assert_eq!(started_at, Some(20));
    // A vehicle behind at 15 m/s with 1 m more than (17) needs on the synchronous bus.
    let room = d_s(&p, 15.0) + 1.0;
    let behind = other(2, -(room + 4.5 + p.d0() + 0.001), 15.0, 1);
    for (latency, starts) in [(p.h(), true), (0.2, false)] {
        let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
        pl.set_notify_latency(latency).unwrap();
        let mut started = false;
        for k in 0..25 {
            // Both move at 15 m/s: the gap stays.
            let mut b = behind;
            b.x += 0.15 * k as f64;
            let c = pl.step(&obs(0.15 * k as f64, 1.8, 15.0, &[b], 1)).unwrap();
            started |= c.event == Some(LaneEvent::Started(1));
        }
        assert_eq!(started, starts, "latency {latency}");
    }
}

/// Two vehicles side by side, each wanting the other's lane, known to each other only as
/// a CAN bus rounds them (x to 0.01 m). A is at 10.004 (heard at 10.00), B at 10.002
/// (heard at 10.00): with exact own positions each sees the other behind, neither yields,
/// and (17) keeps both from starting for as long as they stay abreast. With the bus
/// resolution set, both decide ≺ on rounded values, agree that A ≺ B (same x and speed,
/// lower lane), and exactly A yields.
#[test]
fn bus_resolution_makes_side_by_side_vehicles_agree_on_the_order() {
    let p = p();
    let mut b_heard = other(2, 10.00, 15.0, 1);
    b_heard.beta = Some(0);
    let mut a_heard = other(1, 10.00, 15.0, 0);
    a_heard.beta = Some(1);
    let yields = |lane: u8, x: f64, heard: Other<f64>, target: u8, resolution: bool| {
        let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), lane).unwrap();
        if resolution {
            pl.set_bus_resolution(0.01, 0.02).unwrap();
        }
        let y = (f64::from(lane) + 0.5) * 3.6;
        let c = pl.step(&obs(x, y, 15.0, &[heard], target)).unwrap();
        c.status == StepStatus::Fallback(FallbackReason::Yield)
    };
    // Exact own values: neither yields (the deadlock).
    assert!(!yields(0, 10.004, b_heard, 1, false));
    assert!(!yields(1, 10.002, a_heard, 0, false));
    // Rounded: A yields to B, B does not yield to A.
    assert!(yields(0, 10.004, b_heard, 1, true));
    assert!(!yields(1, 10.002, a_heard, 0, true));
    // Bad resolutions are refused and change nothing.
    let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
    for (pos, speed) in [
        (f64::NAN, 0.02),
        (0.01, -0.02),
        (1.0, 0.02),
        (0.01, f64::INFINITY),
    ] {
        assert!(pl.set_bus_resolution(pos, speed).is_err());
    }
    let c = pl.step(&obs(10.004, 1.8, 15.0, &[b_heard], 1)).unwrap();
    assert_ne!(c.status, StepStatus::Fallback(FallbackReason::Yield));
}

/// The resolution's safety side: a vehicle behind heard at the edge of (17) blocks the
/// start once half a step of position and speed is allowed for, not before.
#[test]
fn bus_resolution_widens_seventeen_by_half_a_step() {
    let p = p();
    let room = d_s(&p, 15.0);
    // Just enough room on exact data: 2 mm over (17) with the planner's margin.
    let behind = other(2, -(room + 4.5 + p.d0() + 0.002), 15.0, 1);
    for (resolution, starts) in [(false, true), (true, false)] {
        let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
        if resolution {
            pl.set_bus_resolution(0.01, 0.02).unwrap();
        }
        let mut started = false;
        for k in 0..5 {
            let mut b = behind;
            b.x += 0.15 * k as f64;
            let c = pl.step(&obs(0.15 * k as f64, 1.8, 15.0, &[b], 1)).unwrap();
            started |= c.event == Some(LaneEvent::Started(1));
        }
        assert_eq!(started, starts, "resolution {resolution}");
    }
}

/// Drives the exact model from `q` at speed `v` toward `target` on an empty 3-lane road;
/// returns the poses at which changes completed, or `None` after `steps` steps.
fn drive_changes(
    mut q: Pose<f64>,
    mut v: f64,
    lane: u8,
    target: u8,
    steps: usize,
) -> Vec<Pose<f64>> {
    let mut pl = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), lane).unwrap();
    let mut w = 0.0;
    let mut done = Vec::new();
    for _ in 0..steps {
        let mut o = obs(q.x, q.y, v, &[], target);
        o.pose = q;
        o.omega_prev = w;
        let c = pl.step(&o).unwrap();
        if let Some(LaneEvent::Completed(_)) = c.event {
            done.push(q);
            if c.lane == target {
                return done;
            }
        }
        (v, w) = (c.v, c.omega);
        q = step(q, v, w, 0.01);
    }
    done
}

/// The dead-end sweep's failures: a change used to complete as soon as the rectangle was
/// inside the new lane — millimetres from its edge, still heading toward the centre. From there
/// the lateral QP (band tightened by 5 cm) found its own start state infeasible, the
/// straightening fallback pinned θ at 0, and at the edge with θ = 0 no turn within the
/// horizon keeps the rear corner in the lane: the vehicle never steered again. It must
/// go on into the next lane.
#[test]
fn a_vehicle_at_its_lanes_edge_still_changes_lanes() {
    // The rotated rectangle 5 mm inside lane 1's lower edge.
    let theta: f64 = 0.015;
    let edge = 3.6 + 2.25 * theta.sin() + 0.85 * theta.cos() + 0.005;
    let q = Pose {
        x: 0.0,
        y: edge,
        theta,
    };
    let done = drive_changes(q, 13.0, 1, 2, 1500);
    assert_eq!(done.len(), 1, "the change 1 → 2 completes within 15 s");
}

/// Two changes in a row (0 → 1 → 2) complete, each near the new lane's centre line, so
/// the second starts from where Lemma 12's S-curve ends.
#[test]
fn successive_changes_complete_near_the_centre_line() {
    use planner_core::lane_change::CENTRED_M;
    let q = Pose {
        x: 0.0,
        y: 1.8,
        theta: 0.0,
    };
    let done = drive_changes(q, 15.0, 0, 2, 3000);
    assert_eq!(done.len(), 2, "both changes complete within 30 s");
    for (pose, centre) in done.iter().zip([5.4, 9.0]) {
        assert!(
            (pose.y - centre).abs() <= CENTRED_M,
            "completed at y = {} (centre {centre})",
            pose.y
        );
    }
}

/// Survivors of the mutation audit in `LanePlanner::check` and the road end's gap
/// (docs/mutants.md).
#[test]
fn input_limits_sit_exactly_where_the_docs_say() {
    let p = p();
    let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
    let o = obs(0.0, 1.8, 15.0, &[], 0);
    let far = 2.0 * f64::MAX_COORD_M;
    let oor = Err(LaneInputError::Speed(InputError::OutOfRange));
    let mut bad = o;
    bad.pose.x = far;
    assert_eq!(pl.step(&bad), oor);
    for c in [
        other(2, far, 10.0, 1),
        Other::v2v(2, 30.0, 10.0, far, 1, 0.0),
    ] {
        let cs = [c];
        assert_eq!(pl.step(&obs(0.0, 1.8, 15.0, &cs, 0)), oor);
    }
    let zero = [Other::v2v(2, 30.0, 10.0, 0.0, 1, 0.0)];
    assert_eq!(
        pl.step(&obs(0.0, 1.8, 15.0, &zero, 0)),
        Err(LaneInputError::Speed(InputError::BadLength))
    );
    // A lane exactly as wide as the vehicle is too narrow.
    let mut narrow = o;
    narrow.road.lane_width = p.width();
    narrow.pose.y = 0.5 * p.width();
    assert_eq!(pl.step(&narrow), Err(LaneInputError::LaneTooNarrow));
    // The band: the rectangle may touch the lane's edges, not cross them.
    let hw = 0.5 * p.width();
    for (y, ok) in [
        (hw, true),
        (hw - 1e-6, false),
        (3.6 - hw, true),
        (3.6 - hw + 1e-6, false),
    ] {
        let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
        let mut at = o;
        at.pose.y = y;
        let got = pl.step(&at);
        assert_eq!(got.is_ok(), ok, "y = {y}: {got:?}");
        if !ok {
            assert_eq!(got, Err(LaneInputError::OutsideBand));
        }
    }
}

#[test]
fn the_road_end_is_an_obstacle_at_its_extent_adjusted_position() {
    let p = p();
    let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).unwrap();
    let mut o = obs(40.0, 1.8, 10.0, &[], 0);
    o.road.end_x = Some(80.0);
    // After the first steps (the notification bound of the start) the gap is the road
    // end's, x_R − L/2 − d0 − x (37.25 m: below the free-road cap of the horizon).
    let mut c = pl.step(&o).unwrap();
    for _ in 0..50 {
        c = pl.step(&o).unwrap();
    }
    let want = 80.0 - 0.5 * p.length() - p.d0() - 40.0;
    assert!((c.gap - want).abs() < 1e-9, "{} against {want}", c.gap);
}

/// A sensed vehicle ahead is taken `position_error_m` nearer than measured (its true rear
/// may be that much closer); one heard over V2V is taken where it says it was.
#[test]
fn a_sensed_vehicle_ahead_is_taken_its_position_error_nearer() {
    let sensing = planner_core::sensing::Sensing {
        ahead_m: 150.0,
        behind_m: 100.0,
        position_error_m: 0.5,
        speed_error_mps: 0.0,
    };
    let command = |x: f64, sensed: bool| {
        let mut pl = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), 0).unwrap();
        pl.set_sensing(Some(sensing)).unwrap();
        let mut o = other(2, x, 10.0, 0);
        o.sensed = sensed;
        let others = [o];
        let c = pl.step(&obs(0.0, 1.8, 15.0, &others, 0)).unwrap();
        (c.v, c.omega)
    };
    // Close enough that the gap shapes the plan.
    for x in [22.0, 24.0, 26.0] {
        assert_eq!(command(x, true), command(x - 0.5, false), "at {x}");
        assert_ne!(command(x, true), command(x, false), "at {x}");
    }
}

/// With sensors, the road beyond the forward range is unknown and not taken as free: at
/// vmax with the shortest range allowed the planner slows, and less the longer the range.
#[test]
fn the_end_of_the_forward_range_is_not_free_road() {
    let vmax = p().v_max();
    let command = |sensing: Option<planner_core::sensing::Sensing<f64>>| {
        let mut pl = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), 0).unwrap();
        pl.set_sensing(sensing).unwrap();
        pl.step(&obs(0.0, 1.8, vmax, &[], 0)).unwrap().v
    };
    let free = command(None);
    let least = planner_core::sensing::Sensing::min_range(&p());
    let blind: Vec<f64> = [least, least + 0.5, least + 1.0]
        .into_iter()
        .map(|ahead_m| {
            command(Some(planner_core::sensing::Sensing {
                ahead_m,
                behind_m: 100.0,
                position_error_m: 0.0,
                speed_error_mps: 0.0,
            }))
        })
        .collect();
    assert!(
        blind[0] < blind[1] && blind[1] < blind[2] && blind[2] < free,
        "{blind:?} {free}"
    );
}

/// The entry check: a change under way whose rectangle is not yet in the
/// target lane does not enter it in front of a vehicle there that does not cooperate and
/// could not stop behind it; with the lane clear, the same step steers in.
#[test]
fn a_change_under_way_waits_for_a_vehicle_behind_that_cannot_stop() {
    let mut pl = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), 0).unwrap();
    let (mut q, mut v, mut w) = (
        Pose {
            x: 0.0,
            y: 1.8,
            theta: 0.0,
        },
        15.0,
        0.0,
    );
    for _ in 0..300 {
        let mut o = obs(q.x, q.y, v, &[], 1);
        o.pose = q;
        o.omega_prev = w;
        let c = pl.step(&o).unwrap();
        (v, w) = (c.v, c.omega);
        q = step(q, v, w, 0.01);
        if c.event == Some(LaneEvent::Started(1)) {
            break;
        }
    }
    assert_eq!(pl.alpha(), Some(1), "the change started");
    // Still in lane 0 with its whole rectangle.
    assert!(q.y + 0.5 * p().width() < 3.6, "y = {}", q.y);
    // A vehicle 12 m behind the ego in lane 1 at 25 m/s, not cooperating: it would not
    // brake for the ego.
    let held_back = |q: Pose<f64>, v: f64, w: f64, pl: &LanePlanner<f64, 20>| {
        let mut fast = other(9, q.x - 12.0, 25.0, 1);
        fast.cooperative = false;
        let others = [fast];
        let mut o = obs(q.x, q.y, v, &others, 1);
        o.pose = q;
        o.omega_prev = w;
        pl.clone().step(&o).unwrap()
    };
    let mut refused = 0;
    // Drive the change with the lane clear until the rectangle reaches lane 1; at every
    // step, ask what the planner would do with the fast vehicle there.
    while q.y + 0.5 * p().width() < 3.6 {
        let mut o = obs(q.x, q.y, v, &[], 1);
        o.pose = q;
        o.omega_prev = w;
        let clear = pl.step(&o).unwrap();
        let held = held_back(q, v, w, &pl);
        // Held back: it turns toward lane 1 less (straightening within Ω's rate).
        if held.omega < clear.omega - 1e-9 {
            refused += 1;
        }
        (v, w) = (clear.v, clear.omega);
        q = step(q, v, w, 0.01);
    }
    assert!(refused > 0, "the fast vehicle never held the change back");
}

/// Sensor fusion at the start of a change: a vehicle behind in the target lane
/// known only from the ego's sensor is taken as one that does not cooperate; with a
/// V2V record of the same vehicle it is trusted to (cooperation is what the vehicle is,
/// not how fresh its record: entering stays guarded by the entry check).
/// Trusting never blocks a start that distrust allows, and somewhere it allows one.
#[test]
fn a_sensed_vehicle_behind_is_trusted_to_cooperate_only_with_a_v2v_record() {
    let mut pl = LanePlanner::<f64, 20>::new(p(), CostWeights::default(), 0).unwrap();
    pl.set_sensing(Some(planner_core::sensing::Sensing::radar()))
        .unwrap();
    let check = |others: &[Other<f64>]| pl.start_check(&obs(0.0, 1.8, 15.0, others, 1), 1);
    let mut trusted_start = 0;
    // Centimetre by centimetre: the difference is one period of unaware motion (h).
    for d in (500..8000).map(|cm| f64::from(cm) / 100.0) {
        let mut seen = other(2, -d, 15.0, 1);
        seen.sensed = true;
        let record = other(2, -d, 15.0, 1);
        let alone = check(&[seen]);
        let both = check(&[seen, record]);
        if alone.is_ok() {
            assert_eq!(both, Ok(()), "{d} m");
        } else if both.is_ok() {
            assert_eq!(alone, Err(StartBlock::Behind(2)), "{d} m");
            trusted_start += 1;
        }
    }
    assert!(trusted_start > 0, "a fresh record never made a difference");
}
