//! Unit tests of the multi-lane planner.

use super::certify::*;
use super::gaps::*;
use super::*;
use crate::lanes::{in_yield_set, Band, Key};
use crate::unicycle::step;

#[test]
fn an_unaware_vehicle_reaches_at_most_amax_then_vmax() {
    let p = Params::<f64>::table_i();
    let (a, vm) = (p.a_max(), p.v_max());
    let (reach, v1) = unaware_reach(&p, 10.0, 1.0);
    assert!((reach - (10.0 + 0.5 * a)).abs() < 1e-12 && (v1 - (10.0 + a)).abs() < 1e-12);
    let (reach, v1) = unaware_reach(&p, 0.0, 0.5);
    assert!((reach - 0.125 * a).abs() < 1e-12 && (v1 - 0.5 * a).abs() < 1e-12);
    // Near vmax the cap binds, on the distance and the speed.
    let (reach, v1) = unaware_reach(&p, vm - 0.1, 10.0);
    assert!((reach - 10.0 * vm).abs() < 1e-9 && v1 == vm);
}

#[test]
fn yielding_is_decided_on_where_the_other_vehicle_is_now() {
    // Its data is 0.5 s old: it was 1 m behind, at 20 m/s it is now 9 m ahead.
    let ego = Key {
        x: 100.0,
        v: 10.0,
        lane: 0,
        id: 1,
    };
    let mut c = Other::v2v(2, 99.0, 20.0, 4.5, 0, 0.5);
    c.beta = Some(1);
    let now = Other { x: 109.0, ..c };
    let then = in_yield_set(&ego, None, Some(1), &c);
    let want = in_yield_set(&ego, None, Some(1), &now);
    assert_ne!(then, want, "the test needs the age to matter");
    assert_eq!(yields_to(&ego, None, Some(1), &c, 0.0), want);
}

#[test]
fn margins_are_what_their_docs_say() {
    let p = Params::<f64>::table_i();
    let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).expect("valid");
    pl.set_notify_latency(0.1).expect("valid");
    pl.set_sensing(Some(Sensing::radar())).expect("valid");
    let v = 12.0;
    let tau = 0.5;
    let (reach, v_up) = unaware_reach(&p, v, tau);
    let margin = reach + safety::d_s(&p, v_up) - safety::d_s(&p, v);
    assert!((pl.unaware_margin(v, tau) - margin).abs() < 1e-12);
    assert!(margin > reach, "a faster vehicle needs more room to stop");
    // τ = max(h, 2 (notify − h)) = 0.18 s; errors 0.1 m and 0.1 m/s.
    let t = 2.0 * (0.1 - p.h());
    let (e, ev) = (0.1, 0.1);
    let want =
        2.0 * e + pl.unaware_margin(v + ev, t) + safety::d_s(&p, v + ev) - safety::d_s(&p, v);
    assert!((pl.entry_allowance(v) - want).abs() < 1e-12);
}

/// On a one-lane road, the ego at x = 0 on its lane's centre, straight, at `v` (its
/// reference too), among `others`.
fn one_lane(v: f64, others: &[Other<f64>]) -> LaneObservation<'_, f64> {
    LaneObservation {
        pose: Pose {
            x: 0.0,
            y: 1.8,
            theta: 0.0,
        },
        v_prev: v,
        omega_prev: 0.0,
        others,
        road: Road {
            lanes: 1,
            lane_width: 3.6,
            end_x: None,
        },
        target_lane: 0,
        target: 0.0,
        v_ref: v,
    }
}

/// A follower at vmax, `gap` m of wall distance behind a leader at vmax, after its
/// first steps (so nothing ahead is unheard of): its command under `invariant`.
fn follow(invariant: Invariant, gap: f64, leader: impl Fn(&mut Other<f64>)) -> LaneCommand<f64> {
    let p = Params::<f64>::table_i();
    let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).expect("valid");
    pl.set_invariant(invariant);
    pl.steps = 100;
    let v = p.v_max();
    let x_leader = gap + p.length() + p.d0();
    let mut c = Other::v2v(2, x_leader, v, p.length(), 0, 0.0);
    c.brake = safety::BrakeLimit::from_mps2(p.brake());
    leader(&mut c);
    let others = [c];
    let obs = one_lane(v, &others);
    pl.step(&obs).expect("a valid observation")
}

#[test]
fn a_cooperating_leader_is_credited_with_its_least_travel_and_nothing_else_is() {
    let p = Params::<f64>::table_i();
    let v = p.v_max();
    // Half the follower's stopping distance: the paper's invariant is broken.
    let gap = 0.5 * safety::d_s(&p, v);
    let paper = follow(Invariant::Paper, gap, |_| {});
    assert!(matches!(paper.status, StepStatus::Fallback(_)), "{paper:?}");
    let aware = follow(Invariant::LeaderAware, gap, |_| {});
    assert!(
        !matches!(aware.status, StepStatus::Fallback(_)),
        "{aware:?}"
    );
    // What the planner reports is capped where no constraint of the horizon can bind.
    let free = crate::planner::free_road_gap(&p, 20);
    let want = (gap + safety::leader_credit(&p, v, p.brake())).min(free);
    assert!((aware.gap - want).abs() < 1e-9, "{} vs {want}", aware.gap);
    // No credit for what carries no braking limit over V2V (the views give none for a
    // vehicle that does not cooperate), nor for a vehicle whose rear is not ahead.
    type Case = (&'static str, f64, fn(&mut Other<f64>));
    let cases: [Case; 3] = [
        ("no limit declared", gap, |c| c.brake = None),
        ("a sensor return", gap, |c| c.sensed = true),
        ("beside", -1.0, |_| {}),
    ];
    for (why, g, f) in cases {
        let c = follow(Invariant::LeaderAware, g, f);
        assert!(c.gap <= g + 1e-9, "{why}: gap {} > {g}", c.gap);
    }
    // A credit is never withdrawn: not when the leader falls silent, nor when its later
    // words are refused (the view then marks it as not cooperating and keeps the limit
    // of its last trusted message). The wall stays where its stamp puts it.
    type Kept = (&'static str, fn(&mut Other<f64>));
    let kept: [Kept; 2] = [
        ("silent for a second", |c| c.age = 1.0),
        ("distrusted since", |c| c.cooperative = false),
    ];
    for (why, f) in kept {
        let c = follow(Invariant::LeaderAware, gap, f);
        assert!((c.gap - want).abs() < 1e-9, "{why}: {} vs {want}", c.gap);
    }
    // A leader with a weaker brake is taken to brake at the follower's limit: its
    // stop is placed earlier than it can be, never later (what makes comparing
    // stopping points enough). A stronger one is credited less.
    let weak = follow(Invariant::LeaderAware, gap, |c| {
        c.brake = safety::BrakeLimit::from_mps2(1.0)
    });
    assert!(
        (weak.gap - want).abs() < 1e-9,
        "a weak brake is not credited more"
    );
    let strong = follow(Invariant::LeaderAware, gap, |c| {
        c.brake = safety::BrakeLimit::from_mps2(20.0)
    });
    // (The leader is also in the yield set (21), whose gap keeps the entry allowance.)
    let pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).expect("valid");
    let less = gap + safety::leader_credit(&p, v, 20.0) - pl.entry_allowance(v);
    assert!((strong.gap - less).abs() < 1e-9, "{} vs {less}", strong.gap);
}

/// On a bus that rounds speeds, a leader's credit is taken at its speed half a step
/// lower (the bus may have rounded it up): exactly leader_credit(v − step/2) more than the
/// wall, in the front set (15).
#[test]
fn the_credit_takes_the_leaders_speed_half_a_bus_step_lower() {
    let p = Params::<f64>::table_i();
    let v = 15.0;
    let leader = Other {
        brake: safety::BrakeLimit::from_mps2(p.brake()),
        ..Other::v2v(2, 40.0, v, p.length(), 0, 0.0)
    };
    let others = [leader];
    let obs = one_lane(v, &others);
    let front = |invariant| {
        let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).expect("valid");
        pl.set_bus_resolution(0.25, 0.125).expect("valid");
        pl.set_invariant(invariant);
        pl.steps = 100;
        pl.gaps(&obs, None, None).0.expect("a leader")
    };
    let credit = front(Invariant::LeaderAware) - front(Invariant::Paper);
    let want = safety::leader_credit(&p, v - 0.0625, p.brake());
    assert!((credit - want).abs() < 1e-9, "{credit} vs {want}");
    assert!(want < safety::leader_credit(&p, v, p.brake()) - 0.05);
}

/// The lane [0, 3.6] m and the table's vehicle.
fn lane0() -> Band<f64> {
    Band { lo: 0.0, hi: 3.6 }
}

/// The half-extent across the road, computed here: ½ (L |sin θ| + W |cos θ|).
fn ext(p: &Params<f64>, theta: f64) -> f64 {
    0.5 * (p.length() * theta.sin().abs() + p.width() * theta.cos().abs())
}

#[test]
fn a_pose_is_in_its_band_to_the_edge_and_not_beyond() {
    let p = Params::<f64>::table_i();
    for theta in [0.0, 0.1, -0.2] {
        let e = ext(&p, theta);
        let at = |y: f64| pose_ok(&p, Pose { x: 0.0, y, theta }, lane0());
        assert!(at(e + 1e-9) && at(3.6 - e - 1e-9), "{theta}");
        assert!(!at(e - 1e-6) && !at(3.6 - e + 1e-6), "{theta}");
    }
    let two = Band { lo: 0.0, hi: 7.2 };
    let tilted = |theta: f64| {
        pose_ok(
            &p,
            Pose {
                x: 0.0,
                y: 3.6,
                theta,
            },
            two,
        )
    };
    assert!(tilted(p.theta_max() - 1e-9) && !tilted(p.theta_max() + 1e-6));
    assert!(tilted(p.theta_min() + 1e-9) && !tilted(p.theta_min() - 1e-6));
}

#[test]
fn overlapping_means_reaching_into_the_lanes_interior() {
    let p = Params::<f64>::table_i();
    let upper = Band { lo: 3.6, hi: 7.2 };
    for theta in [0.0, 0.15] {
        let e = ext(&p, theta);
        let at = |y: f64| overlaps(&p, Pose { x: 0.0, y, theta }, upper);
        assert!(
            !at(3.6 - e - 1e-6),
            "touching from below is not overlapping"
        );
        assert!(at(3.6 - e + 1e-6) && at(5.4) && at(7.2 + e - 1e-6));
        assert!(!at(7.2 + e + 1e-6) && !at(-20.0) && !at(30.0));
    }
}

#[test]
fn the_braking_tail_enters_a_lane_only_while_moving() {
    let p = Params::<f64>::table_i();
    let upper = Band { lo: 7.2, hi: 10.8 };
    // Heading for the lane above at 0.5 rad, 1 cm short of it: straightening at ρmin
    // swings the front corner up faster than the rear comes down (above ~0.35 rad),
    // so at speed it gets in.
    let theta = 0.5;
    let pose = Pose {
        x: 0.0,
        y: 7.2 - ext(&p, theta) - 0.01,
        theta,
    };
    let enters = first_overlap(&p, pose, 20.0, upper);
    assert!(matches!(enters, Some(j) if j > 0 && j < 20), "{enters:?}");
    // Standing still it never does.
    assert_eq!(first_overlap(&p, pose, 0.0, upper), None);
    // Already in: step 0.
    let inside = Pose { y: 7.0, ..pose };
    assert_eq!(first_overlap(&p, inside, 20.0, upper), Some(0));
}

/// The two lanes of a change, [0, 7.2] m.
fn two_lanes() -> Band<f64> {
    Band { lo: 0.0, hi: 7.2 }
}

/// A pose inside the two lanes near their upper edge, heading out at `theta`, at
/// speed `v`, whose braking tail leaves them (found by scanning y; asserted to exist).
fn leaving_pose(p: &Params<f64>, theta: f64, v: f64) -> Pose<f64> {
    (0..400)
        .map(|i| Pose {
            x: 0.0,
            y: 7.2 - ext(p, theta) - 0.001 * f64::from(i),
            theta,
        })
        .find(|&q| pose_ok(p, q, two_lanes()) && !braking_tail_ok(p, q, v, two_lanes()))
        .expect("a pose inside whose braking tail leaves the lanes")
}

#[test]
fn the_fallback_certificate_follows_the_tail_to_standstill() {
    let p = Params::<f64>::table_i();
    let q = leaving_pose(&p, 0.5, 25.0);
    // The tail really leaves: simulate it here.
    let (mut r, mut v, mut left) = (q, 25.0, false);
    while v > 0.0 {
        v = safety::max_braking_command(&p, v);
        r = step(r, v, straighten(&p, r.theta, v), p.h());
        left |= !pose_ok(&p, r, two_lanes());
    }
    assert!(left);
    // Straight and inside: certified at once; standing still and tilted: too.
    assert!(braking_tail_ok(
        &p,
        Pose {
            theta: 0.0,
            y: 3.6,
            ..q
        },
        25.0,
        two_lanes()
    ));
    assert!(braking_tail_ok(&p, q, 0.0, two_lanes()));
}

#[test]
fn a_plan_is_verified_with_its_turning_radius_and_the_tail_after_its_first_step() {
    const N: usize = 20;
    let p = Params::<f64>::table_i();
    let v = [20.0; N];
    let straight = Pose {
        x: 0.0,
        y: 1.8,
        theta: 0.0,
    };
    // ρ ≥ ρmin: |ω| ≤ v / ρmin, to the rounding.
    let turn = |k: f64| {
        let mut w = [0.0; N];
        w[0] = k * 20.0 / p.rho_min();
        w[1] = -w[0];
        w
    };
    assert!(verify_lateral(&p, straight, &v, &turn(1.0), lane0()));
    assert!(!verify_lateral(&p, straight, &v, &turn(1.01), lane0()));
    // A plan turning toward the upper edge, ending at 0.5 rad next to it: every state
    // inside, the tail from the state after its first step (nearly straight) certified,
    // the tail from its last state not — the certificate is the first step's.
    let two = two_lanes();
    // ρ = 20 / 2.5 = 8 m ≥ ρmin; θ grows by 0.025 per step to 0.5.
    let w = [2.5; N];
    for i in 0..600 {
        let q0 = Pose {
            x: 0.0,
            y: 1.0 + 0.01 * f64::from(i),
            theta: 0.0,
        };
        let mut q = q0;
        let mut inside = true;
        for &wk in &w {
            q = step(q, 20.0, wk, p.h());
            inside &= pose_ok(&p, q, two);
        }
        let q1 = step(q0, 20.0, w[0], p.h());
        if inside && braking_tail_ok(&p, q1, 20.0, two) && !braking_tail_ok(&p, q, 20.0, two) {
            assert!(verify_lateral(&p, q0, &v, &w, two));
            return;
        }
    }
    panic!("no plan whose last state's tail leaves while its first state's does not");
}

/// The braking-tail checks as they were before the straight-line shortcut: every
/// step simulated on the unicycle until standstill or the cap.
fn full_tail<F: Real>(p: &Params<F>, pose: Pose<F>, v_prev: F, band: Band<F>) -> bool {
    if !pose_ok(p, pose, band) {
        return false;
    }
    if pose.theta == F::ZERO {
        return true;
    }
    let (mut q, mut v) = (pose, v_prev);
    for _ in 0..MAX_TAIL_STEPS {
        if !(v > F::ZERO) {
            return true;
        }
        v = safety::max_braking_command(p, v);
        q = step(q, v, straighten(p, q.theta, v), p.h());
        if !pose_ok(p, q, band) {
            return false;
        }
    }
    false
}

fn full_overlap<F: Real>(p: &Params<F>, pose: Pose<F>, v_prev: F, lane: Band<F>) -> Option<usize> {
    let (mut q, mut v) = (pose, v_prev);
    for j in 0..MAX_TAIL_STEPS {
        if overlaps(p, q, lane) {
            return Some(j);
        }
        if !(v > F::ZERO) {
            return None;
        }
        v = safety::max_braking_command(p, v);
        q = step(q, v, straighten(p, q.theta, v), p.h());
    }
    Some(MAX_TAIL_STEPS)
}

/// Random poses near a lane edge, headings, speeds and bands, in `F`, for Table I and
/// for a period so short that the tail outlasts [`MAX_TAIL_STEPS`]: the shortcut
/// returns exactly what the full simulation returns, and it is really taken.
fn shortcut_agrees<F: Real>(p: &Params<F>) -> usize {
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut r = move || {
        seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        F::from_f64(((seed >> 11) as f64) / ((1u64 << 53) as f64))
    };
    let mut straightened = 0;
    for _ in 0..3000 {
        let theta = (r() - F::HALF) * F::from_f64(1.0);
        let v = r() * F::from_f64(28.0);
        let lo = F::from_f64(-0.5) * r();
        let band = Band {
            lo,
            hi: lo + F::from_f64(3.6) + F::from_f64(3.6) * r(),
        };
        let y = band.lo + (band.hi - band.lo) * r();
        let pose = Pose {
            x: F::ZERO,
            y,
            theta,
        };
        assert_eq!(
            braking_tail_ok(p, pose, v, band),
            full_tail(p, pose, v, band),
            "{pose:?} v={v:?} {band:?}"
        );
        let lane = Band {
            lo: band.hi,
            hi: band.hi + F::from_f64(3.6),
        };
        assert_eq!(
            first_overlap(p, pose, v, lane),
            full_overlap(p, pose, v, lane)
        );
        // Did the tail reach θ = 0 exactly while still moving (the shortcut's case)?
        let (mut q, mut w) = (pose, v);
        for _ in 0..MAX_TAIL_STEPS {
            if !(w > F::ZERO) {
                break;
            }
            w = safety::max_braking_command(p, w);
            q = step(q, w, straighten(p, q.theta, w), p.h());
            if q.theta == F::ZERO && w > F::ZERO {
                straightened += 1;
                break;
            }
        }
    }
    straightened
}

#[test]
fn the_straight_tail_shortcut_answers_what_the_full_simulation_does() {
    let short = |p: Params<f64>| {
        Params::new(crate::params::ParamsSpec {
            h: 1e-4,
            ..*p.spec()
        })
        .expect("valid")
    };
    for (name, n) in [
        ("f64", shortcut_agrees(&Params::<f64>::table_i())),
        ("f32", shortcut_agrees(&Params::<f32>::table_i())),
        (
            "f64, h = 0.1 ms",
            shortcut_agrees(&short(Params::table_i())),
        ),
    ] {
        assert!(
            n > 1000,
            "{name}: the tail reached θ = 0 in only {n} of 3000 cases"
        );
    }
    // At the cap's edge: speeds around the one from which max braking takes exactly
    // MAX_TAIL_STEPS steps, with a slight heading (straight after a few steps), on
    // both sides of the edge and in agreement with the full simulation.
    let p = short(Params::table_i());
    let band = Band { lo: 0.0, hi: 7.2 };
    let lane = Band { lo: 7.2, hi: 10.8 };
    let pose = Pose {
        x: 0.0,
        y: 3.6,
        theta: 0.01,
    };
    let edge = MAX_TAIL_STEPS as f64 * p.h() * p.brake();
    let (mut certified, mut refused) = (0, 0);
    for i in 0..400 {
        let v = edge - 2.0 * p.h() * p.brake() + 1e-5 * f64::from(i);
        let full = full_tail(&p, pose, v, band);
        assert_eq!(braking_tail_ok(&p, pose, v, band), full, "v = {v}");
        assert_eq!(
            first_overlap(&p, pose, v, lane),
            full_overlap(&p, pose, v, lane)
        );
        if full {
            certified += 1;
        } else {
            refused += 1;
        }
    }
    assert!(certified > 0 && refused > 0, "{certified} / {refused}");
    let p32 = Params::<f32>::table_i();
    let short32 = Params::new(crate::params::ParamsSpec {
        h: 1e-4,
        ..*p32.spec()
    })
    .expect("valid");
    assert!(shortcut_agrees(&short32) > 1000);
}

/// Two lanes, the ego at x = 0 on lane 0's centre at 15 m/s wanting lane 1, and one
/// vehicle 1 km behind in lane 1 at 15 m/s (clear of (17) at any age here) whose data is
/// `age` s old: why the change may
/// not start, if it may not, with the bus's latency bound `notify`.
fn start_with_one_behind(notify: f64, age: f64) -> Result<(), StartBlock> {
    let p = Params::<f64>::table_i();
    let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).expect("valid");
    pl.set_notify_latency(notify).expect("valid");
    // Long after its first steps: nothing ahead is unheard of, whatever the latency.
    pl.steps = 1000;
    let others = [Other::v2v(2, -1000.0, 15.0, p.length(), 1, age)];
    let obs = LaneObservation {
        road: Road {
            lanes: 2,
            lane_width: 3.6,
            end_x: None,
        },
        target_lane: 1,
        ..one_lane(15.0, &others)
    };
    pl.start_check(&obs, 1)
}

#[test]
fn data_is_stale_only_beyond_what_the_bus_explains() {
    let p = Params::<f64>::table_i();
    // The synchronous bus (notify = h): stale beyond STALE_AFTER_S.
    assert_eq!(start_with_one_behind(p.h(), 0.2), Ok(()));
    assert_eq!(
        start_with_one_behind(p.h(), STALE_AFTER_S + 0.01),
        Err(StartBlock::Stale(2))
    );
    // A bus whose messages take up to 1.13 s (1 s of delay, 12 periods of losses): data
    // 1.1 s old is what it delivers, not stale; the change may start ((17) inflated by
    // the age and the bound), and data older than the bound by STALE_AFTER_S is stale.
    let notify = 1.13;
    assert_eq!(start_with_one_behind(notify, 1.1), Ok(()));
    assert_eq!(
        start_with_one_behind(notify, notify - p.h() + STALE_AFTER_S + 0.01),
        Err(StartBlock::Stale(2))
    );
}

/// `start_with_one_behind`'s road with the radar on and trucks about (the weakest braking
/// limit 4.5 m/s²), a car 25.3 m behind (centres) at 15 m/s in lane 1 seen by the radar,
/// and, if `heard`, its V2V record too, declaring a braking limit of 7.9 m/s² and, if
/// `cooperative`, that it cooperates.
fn start_beside_a_seen_car(heard: bool, cooperative: bool) -> Result<(), StartBlock> {
    let p = Params::<f64>::table_i();
    let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).expect("valid");
    pl.set_sensing(Some(Sensing::radar())).expect("valid");
    pl.set_weakest_brake(4.5).expect("valid");
    pl.steps = 1000;
    let mut v2v = Other::v2v(2, -25.3, 15.0, p.length(), 1, 0.0);
    v2v.brake = safety::BrakeLimit::from_mps2(p.brake());
    v2v.cooperative = cooperative;
    let seen = Other {
        sensed: true,
        cooperative: false,
        brake: None,
        ..v2v
    };
    let both = [v2v, seen];
    let others = if heard { &both[..] } else { &both[1..] };
    let obs = LaneObservation {
        road: Road {
            lanes: 2,
            lane_width: 3.6,
            end_x: None,
        },
        target_lane: 1,
        ..one_lane(15.0, others)
    };
    pl.start_check(&obs, 1)
}

#[test]
fn a_seen_car_that_declares_its_braking_limit_is_taken_at_it() {
    // About 20 m of room behind the ego: a car braking at 7.9 m/s² from 15 m/s needs
    // 14.6 m, the weakest vehicle (4.5 m/s²) 25.5 m.
    assert_eq!(start_beside_a_seen_car(true, true), Ok(()));
    // Seen only: nothing is known of it, so it may brake like the weakest.
    assert_eq!(
        start_beside_a_seen_car(false, true),
        Err(StartBlock::Behind(2))
    );
    // Heard, but it does not cooperate: its word is not taken.
    assert_eq!(
        start_beside_a_seen_car(true, false),
        Err(StartBlock::Behind(2))
    );
}

/// A planner changing from lane 1 into lane 0 of two, after its first steps, and the
/// lane event of its next step's bookkeeping at `pose` with v_{t−h} = `v_prev`.
fn completes_at(y: f64, theta: f64, v_prev: f64) -> Option<LaneEvent> {
    let p = Params::<f64>::table_i();
    let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 1).expect("valid");
    pl.steps = 100;
    pl.alpha = Some(0);
    let obs = LaneObservation {
        pose: Pose { x: 0.0, y, theta },
        v_prev,
        road: Road {
            lanes: 2,
            lane_width: 3.6,
            end_x: None,
        },
        target_lane: 0,
        ..one_lane(v_prev, &[])
    };
    pl.update_lanes(&obs)
}

#[test]
fn a_change_stopped_inside_its_lane_heading_for_the_centre_ends_there() {
    // Where the dead-end sweep's case stopped: 0.67 m above lane 0's centre line (1.8 m),
    // heading −0.055 rad, its rectangle inside lane 0 (top corner at 3.44 of 3.6 m).
    let done = Some(LaneEvent::Completed(0));
    assert_eq!(completes_at(2.47, -0.055, 0.0), done);
    // Not while it moves: it can still drive its S-curve to the centre.
    assert_eq!(completes_at(2.47, -0.055, 0.5), None);
    // Not heading away from the centre, nor straight, off the line: it could not steer
    // back without its rear corner leaving the lane first.
    assert_eq!(completes_at(2.47, 0.055, 0.0), None);
    assert_eq!(completes_at(2.47, 0.0, 0.0), None);
    // The same below the centre line (an overshoot): toward the centre is +θ there.
    assert_eq!(completes_at(1.2, 0.055, 0.0), done);
    assert_eq!(completes_at(1.2, 0.0, 0.0), None);
    assert_eq!(completes_at(1.2, -0.055, 0.0), None);
    // Not with a corner still in lane 1 (top corner at 3.62 m).
    assert_eq!(completes_at(2.65, -0.055, 0.0), None);
    // Centred and straight it completes, moving or not, as it always did.
    assert_eq!(completes_at(1.8, 0.0, 10.0), done);
}
