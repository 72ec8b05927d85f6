//! Tests of `lane_change`'s private steps, written against the mutants
//! `cargo mutants -f planner-core/src/lane_change.rs` (now `lane_change/`) found unnoticed (docs/mutants.md):
//! the lengths of (23)(24), the reference S-curve, the bookkeeping of a change (declare,
//! hold, start, complete, re-centre), the sets of (15)(21) with sensing, the fusion of
//! vehicles behind, (17) and the entry check at their boundaries, and the step's
//! shortcut for straight lane keeping. Each test states the rule it pins.

use super::certify::*;
use super::gaps::*;
use super::steer::*;
use super::*;
use crate::free_space::D_TURN_M;
use crate::lanes::Band;
use crate::safety::BrakeLimit;
use crate::unicycle::{lateral_half_extent, step};
use heapless::Vec;

type Lp = LanePlanner<f64, 20>;

fn params() -> Params<f64> {
    Params::table_i()
}

fn planner(lane: u8) -> Lp {
    LanePlanner::new(params(), CostWeights::default(), lane).expect("valid")
}

fn road(lanes: u8) -> Road<f64> {
    Road {
        lanes,
        lane_width: 3.6,
        end_x: None,
    }
}

fn at(x: f64, y: f64, theta: f64) -> Pose<f64> {
    Pose { x, y, theta }
}

/// An observation on a two-lane road, keeping lane `target`.
fn obs<'a>(
    pose: Pose<f64>,
    v: f64,
    others: &'a [Other<f64>],
    target: u8,
) -> LaneObservation<'a, f64> {
    LaneObservation {
        pose,
        v_prev: v,
        omega_prev: 0.0,
        others,
        road: road(2),
        target_lane: target,
        target: 0.0,
        v_ref: v,
    }
}

fn sensed(id: u16, x: f64, v: f64, lane: u8, alpha: Option<u8>) -> Other<f64> {
    Other {
        alpha,
        cooperative: false,
        sensed: true,
        ..Other::v2v(id, x, v, 4.5, lane, 0.0)
    }
}

/// The last x in [lo, hi] at which `clear(x)` holds, for `clear` true at lo and false at
/// hi (monotone), to 0.1 mm.
fn boundary(lo: f64, hi: f64, clear: impl Fn(f64) -> bool) -> f64 {
    assert!(
        clear(lo) && !clear(hi),
        "the boundary must lie in [{lo}, {hi}]"
    );
    let (mut a, mut b) = (lo, hi);
    while b - a > 1e-4 {
        let m = 0.5 * (a + b);
        if clear(m) {
            a = m;
        } else {
            b = m;
        }
    }
    a
}

#[test]
fn lemma_12_lengths_and_the_commitment_distance_are_those_of_23_24() {
    let p = params();
    // LC(ρ) = 2 sqrt(Wl (2ρ − Wl)) − ρ θ, Wl = 3.6.
    let lc = lane_change_length(&p, 20.0, 0.05);
    assert!(
        (lc - (2.0 * (3.6f64 * 36.4).sqrt() - 1.0)).abs() < 1e-12,
        "{lc}"
    );
    assert!((lane_change_length(&p, 10.0, 0.0) - 2.0 * (3.6f64 * 16.4).sqrt()).abs() < 1e-12);
    // dC = max{dS(v), LC}: LC wins slowly, dS fast.
    let ds_slow = safety::d_s(&p, 5.0);
    assert!(lc > ds_slow && (d_c(&p, 5.0, 20.0, 0.05) - lc).abs() < 1e-12);
    let ds_fast = safety::d_s(&p, 27.0);
    assert!(ds_fast > lc && (d_c(&p, 27.0, 20.0, 0.05) - ds_fast).abs() < 1e-12);
    // (23): M (dS + dC), for M = 1 and 3.
    let one = commitment_distance(&p, 1, 5.0, 20.0, 0.05);
    assert!((one - (ds_slow + lc)).abs() < 1e-12, "{one}");
    let three = commitment_distance(&p, 3, 27.0, 20.0, 0.05);
    assert!((three - 3.0 * 2.0 * ds_fast).abs() < 1e-9, "{three}");
    assert_eq!(commitment_distance(&p, 0, 27.0, 20.0, 0.05), 0.0);
}

#[test]
fn recentring_takes_two_seconds_of_travel_and_at_least_8_m() {
    assert_eq!(recentre_length(10.0), 20.0);
    assert_eq!(recentre_length(5.0), 10.0);
    assert_eq!(recentre_length(3.0), 8.0);
    assert_eq!(recentre_length(0.0), 8.0);
}

#[test]
fn the_reference_is_the_quintic_s_curve_from_its_start() {
    let r = Reference {
        x0: 100.0,
        y0: 1.8,
        y1: 5.4,
        len: 40.0,
    };
    for u in [0.1f64, 0.25, 0.5, 0.8] {
        let (y, th) = r.at(100.0 + 40.0 * u);
        // s(u) = 10u³ − 15u⁴ + 6u⁵ and s'(u) = 30u² − 60u³ + 30u⁴, written out.
        let s = 10.0 * u * u * u - 15.0 * u.powi(4) + 6.0 * u.powi(5);
        let ds = 30.0 * u * u - 60.0 * u.powi(3) + 30.0 * u.powi(4);
        assert!((y - (1.8 + 3.6 * s)).abs() < 1e-12, "y at u = {u}");
        assert!(
            (th - (3.6 * ds / 40.0).atan()).abs() < 1e-12,
            "θ at u = {u}"
        );
    }
    // Before the start and after the end: the end values, straight.
    assert_eq!(r.at(90.0), (1.8, 0.0));
    assert_eq!(r.at(150.0), (5.4, 0.0));
}

#[test]
fn straightening_brings_the_heading_to_zero_at_the_turning_limit() {
    let p = params();
    let v = [10.0; 20];
    let theta = 0.3;
    let w = straightening_plan(&p, theta, &v);
    let limit = 10.0 / p.rho_min();
    // Far from straight: as fast as ρmin allows, then exactly what is left, then 0.
    assert!((w[0] + limit).abs() < 1e-12, "{}", w[0]);
    let turned: f64 = w.iter().map(|wk| wk * p.h()).sum();
    assert!((turned + theta).abs() < 1e-12, "θ ends at 0: {turned}");
    assert!(w.iter().all(|wk| wk.abs() <= limit + 1e-12));
    assert_eq!(w[19], 0.0);
    let last_turn = w.iter().rposition(|&wk| wk != 0.0).expect("turns");
    assert!(w[..last_turn].iter().all(|&wk| (wk + limit).abs() < 1e-12));
}

#[test]
fn the_qp_band_is_tightened_by_the_margin_or_the_clearance_left() {
    let p = params();
    let lanes = Band { lo: 3.6, hi: 10.8 };
    let e = ext_of(&p, 0.0);
    let (lo, hi) = qp_band(&p, at(0.0, 7.2, 0.0), lanes);
    assert!(
        (lo - 3.65).abs() < 1e-12 && (hi - 10.75).abs() < 1e-12,
        "{lo} {hi}"
    );
    // 2 cm from the lower edge: tightened there by the 2 cm only.
    let (lo, hi) = qp_band(&p, at(0.0, 3.6 + e + 0.02, 0.0), lanes);
    assert!(
        (lo - 3.62).abs() < 1e-9 && (hi - 10.75).abs() < 1e-12,
        "{lo} {hi}"
    );
    // 3 cm from the upper edge, tilted.
    let et = ext_of(&p, 0.1);
    let (lo, hi) = qp_band(&p, at(0.0, 10.8 - et - 0.03, 0.1), lanes);
    assert!(
        (lo - 3.65).abs() < 1e-12 && (hi - 10.77).abs() < 1e-9,
        "{lo} {hi}"
    );
    // Touching an edge: not tightened there at all.
    let (lo, _) = qp_band(&p, at(0.0, 3.6 + e, 0.0), lanes);
    assert!((lo - 3.6).abs() < 1e-12, "{lo}");
}

fn ext_of(p: &Params<f64>, theta: f64) -> f64 {
    0.5 * (p.length() * theta.sin().abs() + p.width() * theta.cos().abs())
}

#[test]
fn an_intention_is_known_from_fresh_cooperative_data_and_of_a_vehicle_that_does_not_cooperate() {
    let mut pl = planner(0);
    pl.set_notify_latency(0.125).expect("valid");
    let fresh = Other::v2v(5, 50.0, 10.0, 4.5, 1, 0.0625);
    let old = Other { age: 0.25, ..fresh };
    let at_bound = Other {
        age: 0.125,
        ..fresh
    };
    let rogue = Other {
        cooperative: false,
        ..old
    };
    let return_of_5 = sensed(5, 50.0, 10.0, 1, None);
    let return_of_6 = sensed(6, 50.0, 10.0, 1, None);
    let all = [fresh, return_of_5, return_of_6];
    let o = obs(at(0.0, 1.8, 0.0), 10.0, &all, 0);
    assert!(pl.intent_known(&o, &fresh));
    assert!(
        !pl.intent_known(&o, &old),
        "older than the notification bound"
    );
    assert!(
        !pl.intent_known(&o, &at_bound),
        "exactly the bound is not younger"
    );
    assert!(
        pl.intent_known(&o, &rogue),
        "it changes lanes only by what it declared"
    );
    assert!(
        pl.intent_known(&o, &return_of_5),
        "a return takes its V2V record's"
    );
    assert!(
        !pl.intent_known(&o, &return_of_6),
        "a return without a record: unknown"
    );
}

/// What `for_each_behind` hands on: (id, worst x, worst v, cooperates).
fn behind(pl: &Lp, o: &LaneObservation<'_, f64>, m: u8) -> Vec<(u16, f64, f64, bool), 16> {
    let mut seen = Vec::new();
    let _ = pl.for_each_behind(o, m, |c, cx, cv, coop| {
        seen.push((c.id, cx, cv, coop))
            .expect("room for every vehicle");
        Ok(())
    });
    seen
}

#[test]
fn vehicles_behind_are_fused_per_vehicle_and_taken_at_their_worst() {
    let p = params();
    let mut pl = planner(0);
    pl.set_sensing(Some(Sensing::radar())).expect("valid");
    let x = 100.0;
    // 5: a return and its V2V record (cooperative); 6: a return alone; 7: a return 5 cm
    // ahead of the ego (within the 0.1 m error, so maybe behind); 8: a V2V record alone,
    // not cooperating; 9: in the target lane but ahead.
    let others = [
        Other::v2v(5, 89.5, 9.0, 4.5, 1, 0.0),
        sensed(5, 90.0, 10.0, 1, None),
        sensed(6, 80.0, 12.0, 1, None),
        sensed(7, x + 0.05, 11.0, 1, None),
        Other {
            cooperative: false,
            ..Other::v2v(8, 70.0, 13.0, 4.5, 1, 0.0)
        },
        Other::v2v(9, 130.0, 13.0, 4.5, 1, 0.0),
    ];
    let o = obs(at(x, 1.8, 0.0), 10.0, &others, 1);
    let seen = behind(&pl, &o, 1);
    let phantom = (u16::MAX, x - p.length() - 100.0, p.v_max(), false);
    let want = [
        (5, 90.1, 10.1, true),
        (6, 80.1, 12.1, false),
        (7, x + 0.15, 11.1, false),
        (8, 70.0, 13.0, false),
        phantom,
    ];
    assert_eq!(seen.len(), want.len(), "{seen:?}");
    for (s, w) in seen.iter().zip(want.iter()) {
        assert_eq!((s.0, s.3), (w.0, w.3), "{seen:?}");
        assert!(
            (s.1 - w.1).abs() < 1e-9 && (s.2 - w.2).abs() < 1e-9,
            "{s:?} vs {w:?}"
        );
    }
    // On three lanes, changing from 0 into 1: a vehicle behind in lane 0 that declared a
    // change into 1 counts; a return in lane 0 counts if its V2V record declared one; a
    // cooperative vehicle in lane 2 counts only while its intention is not known (data
    // older than the notification bound), as does a return there whose record is old.
    let mut pl = planner(0);
    pl.set_sensing(Some(Sensing::radar())).expect("valid");
    pl.set_notify_latency(0.05).expect("valid");
    let declaring = |id: u16, x: f64| Other {
        alpha: Some(1),
        ..Other::v2v(id, x, 10.0, 4.5, 0, 0.0)
    };
    let list = [
        declaring(11, 90.0),
        Other::v2v(12, 88.0, 10.0, 4.5, 2, 0.0),
        Other::v2v(13, 86.0, 10.0, 4.5, 2, 0.1),
        Other::v2v(14, 84.0, 10.0, 4.5, 0, 0.0),
        declaring(15, 82.0),
        sensed(15, 82.0, 10.0, 0, None),
        Other::v2v(16, 80.0, 10.0, 4.5, 2, 0.1),
        sensed(16, 80.0, 10.0, 2, None),
        sensed(17, 78.0, 10.0, 2, None),
    ];
    let o = LaneObservation {
        road: Road {
            lanes: 3,
            ..road(2)
        },
        ..obs(at(x, 1.8, 0.0), 10.0, &list, 1)
    };
    let ids: Vec<(u16, bool), 16> = behind(&pl, &o, 1)
        .iter()
        .filter(|s| s.0 != u16::MAX)
        .map(|s| (s.0, s.3))
        .collect();
    assert_eq!(ids, [(11, true), (13, true), (15, true), (16, true)]);
}

#[test]
fn the_gaps_give_vehicles_entering_my_lanes_the_entry_allowance_and_leaders_none() {
    let p = params();
    let mut pl = planner(0);
    pl.set_sensing(Some(Sensing::radar())).expect("valid");
    let x = 100.0;
    let len = p.length();
    let allowance = pl.entry_allowance(10.0);
    assert!(allowance > 0.1);
    // A leader in my lane: in (15), and in (21) (ahead in ≺, in my lane) with the
    // allowance.
    let leader = [Other::v2v(5, 140.0, 10.0, 4.5, 0, 0.0)];
    let o = obs(at(x, 1.8, 0.0), 10.0, &leader, 0);
    let (safe, all) = pl.gaps(&o, None, None);
    let g = 140.0 - 0.5 * (4.5 + len) - p.d0() - x;
    assert!((safe.expect("a leader") - g).abs() < 1e-9, "{safe:?}");
    assert!(
        (all.expect("a leader") - (g - allowance)).abs() < 1e-9,
        "{all:?}"
    );
    // A return in my lane 5 cm behind the ego: maybe ahead, so in (15); behind in ≺ and
    // already in my lane, so not entering it: no allowance.
    let beside = [sensed(7, x - 0.05, 10.0, 0, None)];
    let o = obs(at(x, 1.8, 0.0), 10.0, &beside, 0);
    let (safe, all) = pl.gaps(&o, None, None);
    let g = (x - 0.15) - 0.5 * (4.5 + len) - p.d0() - x;
    assert!((safe.expect("maybe ahead") - g).abs() < 1e-9, "{safe:?}");
    assert_eq!(safe, all);
    // A return straddling into my lane 5 cm behind the ego (so maybe ahead): in front,
    // taken 0.1 m nearer, and entering my lane: the allowance too.
    let cut_in = [sensed(6, x - 0.05, 10.0, 1, Some(0))];
    let o = obs(at(x, 1.8, 0.0), 10.0, &cut_in, 0);
    let (safe, all) = pl.gaps(&o, None, None);
    let g = (x - 0.15) - 0.5 * (4.5 + len) - p.d0() - x;
    assert!((safe.expect("in front") - g).abs() < 1e-9, "{safe:?}");
    assert!(
        (all.expect("in front") - (g - allowance)).abs() < 1e-9,
        "{all:?}"
    );
    // Nothing known: the end of the forward range, less d0.
    let o = obs(at(x, 1.8, 0.0), 10.0, &[], 0);
    assert_eq!(pl.gaps(&o, None, None), (Some(149.5), Some(149.5)));
    // The bus's rounding: half a position step at each end of a heard vehicle.
    let mut pl = planner(0);
    pl.set_bus_resolution(0.25, 0.125).expect("valid");
    let o = obs(at(x, 1.8, 0.0), 10.0, &leader, 0);
    let (safe, _) = pl.gaps(&o, None, None);
    let g = 140.0 - 0.5 * (4.5 + len + 0.25) - p.d0() - x;
    assert!((safe.expect("a leader") - g).abs() < 1e-9, "{safe:?}");
}

#[test]
fn clear_of_and_the_entry_check_take_the_datas_age_plus_the_lead() {
    let mut pl = planner(0);
    pl.set_bus_resolution(0.25, 0.125).expect("valid");
    let x = 100.0;
    let with = |cx: f64, age: f64| {
        [Other {
            cooperative: false,
            ..Other::v2v(8, cx, 15.0, 4.5, 1, age)
        }]
    };
    // clear_of at its boundary: room = x − ½(Lc + L + step) − d0 − cx − reach − margin > dS.
    let p = params();
    let c = with(0.0, 0.0)[0];
    let o = obs(at(x, 1.8, 0.0), 10.0, &[], 0);
    let tau = 0.3;
    let (reach, v_up) = unaware_reach(&p, 15.0 + 0.0625, tau);
    let edge = x
        - 0.5 * (4.5 + p.length() + 0.25)
        - p.d0()
        - reach
        - <f64 as Real>::SAFETY_MARGIN_M
        - safety::d_s(&p, v_up);
    assert!(pl.clear_of(&o, &c, edge - 1e-6, 15.0, tau));
    assert!(!pl.clear_of(&o, &c, edge + 1e-6, 15.0, tau));
    // The entry check: age 0.2 s plus a lead of 0.1 s.
    let b = boundary(0.0, x, |cx| pl.clear_of(&o, &c, cx, 15.0, 0.3));
    for (cx, ok) in [(b - 0.01, true), (b + 0.01, false)] {
        let list = with(cx, 0.2);
        let o = obs(at(x, 1.8, 0.0), 10.0, &list, 1);
        assert_eq!(pl.entry_ok(&o, 1, 0.1), ok, "at {cx}");
    }
}

#[test]
fn a_cooperating_vehicle_behind_is_inflated_by_the_notification_bound_at_a_start() {
    let mut pl = planner(0);
    pl.set_notify_latency(0.125).expect("valid");
    pl.steps = 100; // past the first notification bound: the road ahead is known
    let x = 100.0;
    let age = 0.0625;
    let probe = Other::v2v(8, 0.0, 15.0, 4.5, 1, age);
    let o = obs(at(x, 1.8, 0.0), 10.0, &[], 1);
    // (17) with τ = age + (notify − h).
    let b = boundary(0.0, x, |cx| {
        pl.clear_of(&o, &probe, cx, 15.0, age + 0.125 - 0.01)
    });
    for (cx, ok) in [(b - 0.01, true), (b + 0.01, false)] {
        let list = [Other { x: cx, ..probe }];
        let o = obs(at(x, 1.8, 0.0), 10.0, &list, 1);
        let got = pl.start_check(&o, 1);
        assert_eq!(got.is_ok(), ok, "at {cx}: {got:?}");
    }
}

#[test]
fn a_start_needs_the_current_turn_to_stay_in_the_widened_band_beyond_dl() {
    let p = params();
    let pl = planner(0);
    let v = 10.0;
    let pose = at(100.0, 1.8, -0.015);
    // Turning right (toward the road's edge) ever tighter: where the arc leaves the two
    // lanes shrunk by W/2 moves in; the start is refused once that is within dL.
    let widened = road(2).band(0, Some(1)).shrunk(0.5 * p.width());
    let fits = |w: f64| {
        FreeSpace::new(&p, pose, v, w, widened, 1e3)
            .is_ok_and(|fs| fs.d_h > fs.d_l && fs.lemma5_angles())
    };
    let w = -boundary(0.0, 2.0, |w| fits(-w));
    for (omega, ok) in [(w + 0.001, true), (w - 0.001, false)] {
        let o = LaneObservation {
            omega_prev: omega,
            ..obs(pose, v, &[], 1)
        };
        let got = pl.start_check(&o, 1);
        assert_eq!(got.is_ok(), ok, "ω = {omega}: {got:?}");
        if !ok {
            assert_eq!(got, Err(StartBlock::FreeSpace));
        }
    }
}

#[test]
fn a_driven_change_off_the_centre_gets_a_new_curve_to_it() {
    let mut pl = planner(0);
    pl.alpha = Some(1);
    let centre = 5.4;
    // Off by 0.5 m (more than half of CENTRED_M), below and above: a new curve.
    for y in [centre - 0.5, centre + 0.5] {
        pl.reference = None;
        pl.rejoin(&obs(at(300.0, y, 0.0), 12.0, &[], 1), 1);
        assert_eq!(
            pl.reference,
            Some(Reference {
                x0: 300.0,
                y0: y,
                y1: centre,
                len: 24.0
            })
        );
    }
    // Off by 0.2 m: close enough.
    pl.reference = None;
    pl.rejoin(&obs(at(300.0, centre - 0.2, 0.0), 12.0, &[], 1), 1);
    assert_eq!(pl.reference, None);
    // A curve not yet driven is kept; one driven to its end is replaced.
    let curve = Reference {
        x0: 250.0,
        y0: 1.8,
        y1: centre,
        len: 50.0,
    };
    pl.reference = Some(curve);
    pl.rejoin(&obs(at(299.0, centre - 0.5, 0.0), 12.0, &[], 1), 1);
    assert_eq!(pl.reference, Some(curve));
    pl.rejoin(&obs(at(300.0, centre - 0.5, 0.0), 12.0, &[], 1), 1);
    assert_eq!(pl.reference.map(|r| r.x0), Some(300.0));
}

#[test]
fn lane_keeping_recentres_beyond_5_cm_and_drops_a_driven_curve() {
    let mut pl = planner(0);
    let o = |x: f64, y: f64| obs(at(x, y, 0.0), 12.0, &[], 0);
    pl.recentre(&o(10.0, 1.8 + 0.02));
    assert_eq!(pl.reference, None, "within 5 cm");
    for y in [1.8 - 0.1, 1.8 + 0.1] {
        pl.reference = None;
        pl.recentre(&o(10.0, y));
        assert_eq!(
            pl.reference,
            Some(Reference {
                x0: 10.0,
                y0: y,
                y1: 1.8,
                len: 24.0
            })
        );
    }
    // Kept while driven, dropped at its end (and not renewed once centred).
    pl.recentre(&o(33.0, 1.85));
    assert_eq!(pl.reference.map(|r| r.x0), Some(10.0));
    pl.recentre(&o(34.0, 1.8));
    assert_eq!(pl.reference, None);
    // At its end but still off: a new one from here.
    pl.reference = Some(Reference {
        x0: 10.0,
        y0: 1.7,
        y1: 1.8,
        len: 24.0,
    });
    pl.recentre(&o(34.0, 1.7));
    assert_eq!(pl.reference.map(|r| r.x0), Some(34.0));
    // During a change the curve is the change's.
    pl.alpha = Some(1);
    pl.reference = None;
    pl.recentre(&o(40.0, 1.0));
    assert_eq!(pl.reference, None);
}

#[test]
fn a_change_starts_once_its_intention_has_been_out_for_the_notification_bound() {
    let mut pl = planner(0);
    pl.set_notify_latency(0.05).expect("valid");
    pl.steps = 100; // past the first notification bound: the road ahead is known
    let o = obs(at(100.0, 1.8, 0.0), 12.0, &[], 1);
    assert_eq!(pl.update_lanes(&o), Some(LaneEvent::Declared(1)));
    for held in 1..5 {
        pl.beta_steps = held;
        assert_eq!(pl.update_lanes(&o), None, "held {held} periods of 5");
        assert_eq!(pl.alpha, None);
    }
    pl.beta_steps = 5;
    assert_eq!(pl.update_lanes(&o), Some(LaneEvent::Started(1)));
    let r = pl.reference.expect("a curve");
    assert_eq!((r.x0, r.y0, r.y1), (100.0, 1.8, 5.4));
    // Down from lane 1 is the mirror image: the same length.
    let mut down = planner(1);
    down.set_notify_latency(0.05).expect("valid");
    down.steps = 100;
    let o = obs(at(100.0, 5.4, 0.0), 12.0, &[], 0);
    assert_eq!(down.update_lanes(&o), Some(LaneEvent::Declared(0)));
    down.beta_steps = 5;
    assert_eq!(down.update_lanes(&o), Some(LaneEvent::Started(0)));
    let d = down.reference.expect("a curve");
    assert_eq!((d.y0, d.y1), (5.4, 1.8));
    assert!((d.len - r.len).abs() < 1e-9, "{} vs {}", d.len, r.len);
    // The length: a quintic's peak curvature 5.77 Δy / len² at the radius the free space
    // allows with dS + D_TURN_M free ahead (above the 16 m floor at these speeds).
    let p = params();
    let band = road(2).band(0, Some(1)).shrunk(0.5 * p.width());
    for v in [4.0, 12.0] {
        let mut pl = planner(0);
        pl.steps = 100;
        pl.beta = Some(1);
        pl.beta_steps = 1;
        let o = obs(at(100.0, 1.8, 0.0), v, &[], 1);
        assert_eq!(pl.update_lanes(&o), Some(LaneEvent::Started(1)));
        let len = pl.reference.expect("a curve").len;
        let free = safety::d_s(&p, v) + D_TURN_M;
        let fs = FreeSpace::new(&p, at(100.0, 1.8, 0.0), v, 0.0, band, free).expect("inside");
        let want = (5.77 * 3.6 / fs.arc_h.kappa_plus).sqrt();
        assert!(
            want > MIN_CHANGE_LENGTH_M + 0.5 && (len - want).abs() < 1e-9,
            "{len} vs {want}"
        );
    }
}

#[test]
fn bad_speed_input_changes_nothing() {
    let mut pl = planner(0);
    for v in [-0.5, 28.0] {
        let o = obs(at(100.0, 1.8, 0.0), v, &[], 1);
        assert_eq!(
            pl.step(&o),
            Err(LaneInputError::Speed(InputError::SpeedOutOfRange))
        );
        assert_eq!((pl.beta(), pl.beta_steps, pl.steps), (None, 0, 0));
    }
}

#[test]
fn straight_lane_keeping_skips_the_lateral_qp_and_nothing_else_does() {
    let mut pl = planner(0);
    let cmd = pl
        .step(&obs(at(100.0, 1.8, 0.0), 12.0, &[], 0))
        .expect("valid");
    assert_eq!(cmd.lateral_iterations, 0);
    assert!(matches!(cmd.status, StepStatus::Solved { .. }), "{cmd:?}");
    for (pose, omega) in [
        (at(100.0, 1.8, 0.01), 0.0),
        (at(100.0, 1.9, 0.0), 0.0),
        (at(100.0, 1.8, 0.0), 0.01),
    ] {
        let mut pl = planner(0);
        let o = LaneObservation {
            omega_prev: omega,
            ..obs(pose, 12.0, &[], 0)
        };
        let cmd = pl.step(&o).expect("valid");
        assert!(cmd.lateral_iterations > 0, "{pose:?} ω {omega}: {cmd:?}");
    }
}

#[test]
fn the_step_bounds_its_speed_by_where_the_current_turn_leaves_the_band() {
    let p = params();
    let mut pl = planner(0);
    let pose = at(100.0, 1.8, -0.02);
    let o = LaneObservation {
        omega_prev: -0.5,
        ..obs(pose, 12.0, &[], 0)
    };
    let band = road(2).band(0, None).shrunk(0.5 * p.width());
    let fs = FreeSpace::new(&p, pose, 12.0, -0.5, band, free_road_gap(&p, 20)).expect("inside");
    let d = fs.d_h_hat.expect("the turn leaves the lane");
    let cmd = pl.step(&o).expect("valid");
    assert!((cmd.gap - d).abs() < 1e-9, "{} vs {d}", cmd.gap);
}

#[test]
fn entering_the_target_lane_waits_for_the_vehicles_behind_to_stop_for_it() {
    let p = params();
    let mut pl = planner(0);
    pl.alpha = Some(1);
    let lane1 = road(2).band(1, None);
    // Heading for lane 1 at 0.5 rad near its edge at 20 m/s: the first step stays out,
    // the braking tail (straightening at ρmin swings the front corner up) goes in.
    let theta = 0.5;
    let v = [20.0; 20];
    let w = [0.0; 20];
    let (pose, j) = (0..300)
        .map(|i| at(100.0, 3.6 - ext_of(&p, theta) - 0.001 * f64::from(i), theta))
        .find_map(|q| {
            let q1 = step(q, 20.0, 0.0, p.h());
            let j = first_overlap(&p, q1, 20.0, lane1)?;
            (j >= 1 && !overlaps(&p, q, lane1)).then_some((q, j))
        })
        .expect("a pose whose tail, not its first step, enters lane 1");
    let lead = p.h() * (j as f64 + 1.0);
    let probe = Other {
        cooperative: false,
        ..Other::v2v(8, 0.0, 15.0, 4.5, 1, 0.0)
    };
    let list_at = |cx: f64| [Other { x: cx, ..probe }];
    let clear = |cx: f64| {
        let list = list_at(cx);
        pl.entry_ok(&obs(pose, 20.0, &list, 1), 1, lead)
    };
    let b = boundary(0.0, 100.0, clear);
    for (cx, ok) in [(b - 0.01, true), (b + 0.01, false)] {
        let list = list_at(cx);
        assert_eq!(
            pl.entering_ok(&obs(pose, 20.0, &list, 1), &v, &w),
            ok,
            "at {cx}"
        );
    }
    // Once in lane 1, nothing more to wait for.
    let inside = at(100.0, 4.0, 0.0);
    let list = list_at(b + 0.01);
    assert!(pl.entering_ok(&obs(inside, 20.0, &list, 1), &v, &w));
}

#[test]
fn a_lateral_plan_the_exact_check_refuses_is_never_applied() {
    // Near the lane's upper edge, heading out at 0.1 rad and turning back: the free space
    // ahead is long enough for the speed plan, but no yaw-rate plan (the QP's or the
    // straightening one) keeps the exact rectangle in the lane with a certified tail:
    // the fallback, never a "solved" command.
    let p = params();
    let (v, theta, y) = (5.0, 0.1, 2.64);
    let omega = -0.25 * v / p.rho_min();
    let pose = at(100.0, y, theta);
    let band = road(2).band(0, None).shrunk(0.5 * p.width());
    let fs = FreeSpace::new(&p, pose, v, omega, band, free_road_gap(&p, 20)).expect("inside");
    assert!(
        fs.d_h > 5.0 * fs.d_l,
        "room ahead for the speed plan: {fs:?}"
    );
    let mut pl = planner(0);
    let o = LaneObservation {
        omega_prev: omega,
        ..obs(pose, v, &[], 0)
    };
    let cmd = pl.step(&o).expect("valid");
    assert_eq!(cmd.status, StepStatus::Fallback(FallbackReason::Lateral));
    assert_eq!((cmd.v, cmd.omega), pl.braking_command(theta, v));
}

#[test]
fn a_fallback_is_a_yield_only_while_15_alone_still_holds_with_the_margin() {
    // A leader in my lane: (15) counts it as it is, (21) with the entry allowance. Where
    // (15) ∪ (21) fails the invariant, the fallback is a yield if (15) alone holds with
    // the planner's margin, and a violated invariant if it holds only without it.
    let p = params();
    let v = 10.0;
    let x = 100.0;
    let margin = <f64 as Real>::SAFETY_MARGIN_M;
    let ds = safety::d_s(&p, v);
    let allowance = planner(0).entry_allowance(v);
    assert!(allowance > 4.0 * margin, "{allowance}");
    let leader_at = |gap: f64| {
        [Other::v2v(
            5,
            x + gap + 0.5 * (4.5 + p.length()) + p.d0(),
            v,
            4.5,
            0,
            0.0,
        )]
    };
    for (gap, why) in [
        (ds + margin + 0.5 * allowance, FallbackReason::Yield),
        (ds + 0.5 * margin, FallbackReason::InvariantViolated),
    ] {
        let list = leader_at(gap);
        let mut pl = planner(0);
        let cmd = pl.step(&obs(at(x, 1.8, 0.0), v, &list, 0)).expect("valid");
        assert_eq!(
            cmd.status,
            StepStatus::Fallback(why),
            "gap {gap} over dS {ds}"
        );
    }
}

#[test]
fn a_start_needs_16_with_the_planners_margin() {
    // A vehicle ahead in the target lane: (16) on the gap to it (with the entry
    // allowance it gets as a vehicle in α) must hold with SAFETY_MARGIN_M to spare.
    let p = params();
    let mut pl = planner(0);
    pl.steps = 100;
    let (x, v) = (100.0, 10.0);
    let margin = <f64 as Real>::SAFETY_MARGIN_M;
    let ds = safety::d_s(&p, v);
    let ahead = |cx: f64| [Other::v2v(5, cx, v, 4.5, 1, 0.0)];
    let probe = ahead(150.0);
    let gap_at_150 = pl
        .gaps(&obs(at(x, 1.8, 0.0), v, &probe, 1), Some(1), None)
        .1
        .expect("ahead");
    for (extra, ok) in [(1.5 * margin, true), (0.5 * margin, false)] {
        let list = ahead(150.0 - gap_at_150 + ds + extra);
        let o = obs(at(x, 1.8, 0.0), v, &list, 1);
        let gap = pl.gaps(&o, Some(1), None).1.expect("ahead");
        assert!((gap - (ds + extra)).abs() < 1e-9, "{gap}");
        let got = pl.start_check(&o, 1);
        assert_eq!(
            got,
            if ok { Ok(()) } else { Err(StartBlock::Ahead) },
            "{extra}"
        );
    }
}

#[test]
fn a_rectangle_exactly_touching_a_lane_does_not_overlap_it() {
    // `overlaps` is about the lane's interior: touching its edge is not being in it
    // (the entry check still applies, and the tail's first overlap is the next step).
    // The lane's edges are placed where the rectangle's edge is, as the same f64 sum.
    let p = params();
    for theta in [0.0, 0.1] {
        let e = lateral_half_extent(p.length(), p.width(), theta);
        let y = 2.0;
        let above_me = Band {
            lo: y + e,
            hi: y + e + 3.6,
        };
        assert!(
            !overlaps(&p, at(0.0, y, theta), above_me),
            "from below, θ {theta}"
        );
        let below_me = Band {
            lo: y - e - 3.6,
            hi: y - e,
        };
        assert!(
            !overlaps(&p, at(0.0, y, theta), below_me),
            "from above, θ {theta}"
        );
        let nudge = Band {
            lo: above_me.lo - 1e-9,
            ..above_me
        };
        assert!(overlaps(&p, at(0.0, y, theta), nudge));
    }
}

#[test]
fn a_truck_behind_is_given_the_room_it_needs_to_stop_at_its_own_limit() {
    let mut pl = planner(0);
    let p = params();
    let x = 100.0;
    let o = obs(at(x, 1.8, 0.0), 10.0, &[], 0);
    let tau = 0.3;
    let (reach, v_up) = unaware_reach(&p, 15.0, tau);
    // (17) at its boundary for a vehicle behind braking at `b`, 16.5 m long.
    let edge = |b: f64| {
        x - 0.5 * (16.5 + p.length())
            - p.d0()
            - reach
            - <f64 as Real>::SAFETY_MARGIN_M
            - safety::d_s_braking(&p, v_up, b)
    };
    let truck = |brake| Other {
        brake,
        ..Other::v2v(8, 0.0, 15.0, 16.5, 1, 0.0)
    };
    // Declared 4.5 m/s²: the truck's own dS, far longer than a car's.
    let declared = truck(BrakeLimit::from_mps2(4.5));
    assert!(edge(4.5) < edge(p.brake()) - 10.0);
    assert!(pl.clear_of(&o, &declared, edge(4.5) - 1e-6, 15.0, tau));
    assert!(!pl.clear_of(&o, &declared, edge(4.5) + 1e-6, 15.0, tau));
    // Declared none: the paper's homogeneous fleet by default (the ego's own limit)...
    let silent = truck(None);
    assert!(pl.clear_of(&o, &silent, edge(p.brake()) - 1e-6, 15.0, tau));
    assert!(!pl.clear_of(&o, &silent, edge(p.brake()) + 1e-6, 15.0, tau));
    // ...and the weakest limit in traffic once it is set.
    pl.set_weakest_brake(4.5).expect("valid");
    assert!(!pl.clear_of(&o, &silent, edge(p.brake()) - 1e-6, 15.0, tau));
    assert!(pl.clear_of(&o, &silent, edge(4.5) - 1e-6, 15.0, tau));
    // A car that declared its limit is still taken at its own.
    let car = Other {
        brake: BrakeLimit::from_mps2(7.9),
        ..Other::v2v(9, 0.0, 15.0, 4.5, 1, 0.0)
    };
    let car_edge = edge(p.brake()) + 0.5 * (16.5 - 4.5);
    assert!(pl.clear_of(&o, &car, car_edge - 1e-6, 15.0, tau));
    // Above the ego's own limit counts as its own; nonsense is refused and changes nothing.
    pl.set_weakest_brake(20.0).expect("valid");
    assert_eq!(pl.weakest_brake(), p.brake());
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert_eq!(pl.set_weakest_brake(bad), Err(ConfigError::InvalidBrake));
        assert_eq!(pl.weakest_brake(), p.brake());
    }
}
