//! Property tests of the leader-aware invariant (docs/spec.md, "The leader-aware
//! invariant"): a follower that keeps it toward a cooperating leader never reaches the
//! leader, whatever the leader does within its limits (it never reverses and never brakes
//! harder than its own limit), for any pair of braking limits — a car behind a truck, a
//! truck behind a car.
//!
//! The plant is the simulator's: a speed is applied over a whole period (x += v h). The
//! follower reacts one period late (it keeps its speed for the period that was already
//! commanded), then applies the certified fallback, max braking at its own limit.

use planner_core::safety::{d_s, ghost_advance, leader_credit, least_travel};
use planner_core::{Params, ParamsSpec};
use proptest::prelude::*;

/// Table I with braking limit `brake` (m/s²).
fn with_brake(brake: f64) -> Params<f64> {
    Params::new(ParamsSpec {
        a_min: -brake,
        ..ParamsSpec::table_i()
    })
    .expect("a braking limit in [3, 10] m/s² is valid")
}

/// The exact least travel, summed period by period.
fn summed(v: f64, brake: f64, h: f64) -> f64 {
    let mut s = 0.0;
    let mut u = v;
    for _ in 0..100_000 {
        u = (u - brake * h).max(0.0);
        if u == 0.0 {
            break;
        }
        s += u * h;
    }
    s
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(10_000))]

    /// [`least_travel`] never claims more than a vehicle braking at its limit travels.
    #[test]
    fn least_travel_is_a_lower_bound(v in 0.0f64..27.8, brake in 3.0f64..10.0) {
        let p = with_brake(7.9);
        let lower = least_travel(&p, v, brake);
        let exact = summed(v, brake, p.h());
        prop_assert!(lower <= exact + 1e-9, "{lower} > {exact}");
        // And it is close: within |amin| h² / 8 of the exact sum.
        prop_assert!(exact - lower <= brake * p.h() * p.h() / 8.0 + 1e-9);
    }

    /// The lemma: from any state that keeps the leader-aware invariant, the follower's
    /// fallback never reaches the leader (bumper gap stays above d0 at every instant),
    /// while the leader does anything its limits allow.
    #[test]
    fn a_follower_keeping_the_invariant_never_reaches_its_leader(
        b_f in 3.0f64..10.0,
        b_l in 3.0f64..10.0,
        v_f in 0.0f64..27.8,
        v_l in 0.0f64..27.8,
        extra in 1e-6f64..5.0,
        moves in proptest::collection::vec(0.0f64..1.0, 1..1200),
    ) {
        let p = with_brake(b_f);
        let (h, d0) = (p.h(), p.d0());
        // The smallest room the invariant allows, plus `extra`: room + credit > dS.
        let credit = leader_credit(&p, v_l, b_l);
        let room = (d_s(&p, v_f) - credit).max(0.0) + extra;
        let (mut xf, mut xl) = (0.0, room + d0);
        let (mut uf, mut ul) = (v_f, v_l);
        for k in 0..moves.len().max(1200) {
            // The follower: its committed speed for one period, then max braking.
            if k > 0 {
                uf = (uf - b_f * h).max(0.0);
            }
            // The leader: any change from braking at its limit to accelerating at amax.
            let m = moves.get(k).copied().unwrap_or(0.0);
            let accel = -b_l + m * (b_l + p.a_max());
            ul = (ul + accel * h).clamp(0.0, p.v_max());
            xf += uf * h;
            xl += ul * h;
            // Both move linearly within the period: the gap is smallest at its ends.
            prop_assert!(xl - xf > d0 - 1e-9, "step {k}: gap {} ≤ d0", xl - xf);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5_000))]

    /// A ghost is never ahead of its vehicle: however a cooperating vehicle drives within
    /// its limits after a stamp, it has moved at least [`ghost_advance`] since, at every
    /// age; and the ghost stops no earlier than the stamp's credit says.
    #[test]
    fn the_ghost_is_never_ahead_of_its_vehicle(
        b_f in 3.0f64..10.0,
        b_l in 3.0f64..10.0,
        v in 0.0f64..27.8,
        moves in proptest::collection::vec(0.0f64..1.0, 1..600),
        extra_ms in 0u64..10,
    ) {
        let p = with_brake(b_f);
        let h = p.h();
        let (mut x, mut u) = (0.0, v);
        for k in 0..=moves.len() {
            // k whole periods after the stamp, and up to one period more.
            let age = k as f64 * h + extra_ms as f64 * 1e-3;
            let ghost = ghost_advance(&p, v, b_l, age);
            prop_assert!(ghost <= x + 1e-9, "k {k}: ghost {ghost} ahead of {x}");
            let m = moves.get(k).copied().unwrap_or(0.0);
            u = (u + (-b_l + m * (b_l + p.a_max())) * h).clamp(0.0, p.v_max());
            x += u * h;
        }
        // Judging it by its ghost moves no wall back: ghost + the credit of the ghost's
        // speed is never short of the stamp's credit.
        for k in [0usize, 1, 7, 50] {
            let age = k as f64 * h;
            let slowed = (v - b_l * h * k as f64).max(0.0);
            let stop = ghost_advance(&p, v, b_l, age) + leader_credit(&p, slowed, b_l);
            prop_assert!(stop >= leader_credit(&p, v, b_l) - 1e-9);
        }
    }

    /// A follower that keeps the leader-aware invariant toward a leader's stamped state
    /// never comes level with the leader's ghost, however long the leader stays silent:
    /// the ghost's rear stays more than d0 ahead of the follower's front, so the
    /// follower, judging the leader by its ghost, goes on crediting it (and never by its
    /// stamped position, which it may pass); `safety::leads` asks only that the rear be
    /// ahead of the front, d0 to spare. The follower here drives as close to its wall as
    /// the invariant lets it, reacting one period late. (A ghost braking at b' instead of
    /// the leader's own limit, or shrunk by cos θmax like the credit, fails this.)
    #[test]
    fn a_follower_keeping_the_invariant_never_comes_level_with_the_ghost(
        b_f in 3.0f64..10.0,
        b_l in 3.0f64..10.0,
        v_f in 0.0f64..27.8,
        v_l in 0.0f64..27.8,
        extra in 1e-6f64..5.0,
        steps in 1usize..1500,
    ) {
        let p = with_brake(b_f);
        let (h, d0, len) = (p.h(), p.d0(), p.length());
        let credit = leader_credit(&p, v_l, b_l);
        // The follower's centre at 0, the leader's stamped centre ahead: the invariant
        // holds with `extra` to spare.
        let x0 = (d_s(&p, v_f) - credit).max(0.0) + extra + d0 + len;
        let wall = x0 - len - d0 + credit;
        let (mut xf, mut uf) = (0.0, v_f);
        for k in 0..steps {
            let ghost = x0 + ghost_advance(&p, v_l, b_l, k as f64 * h);
            prop_assert!(
                ghost - len - xf > d0 - 1e-9,
                "step {k}: ghost {ghost}, follower {xf}: gap {} ≤ d0", ghost - len - xf
            );
            // The fastest speed for the next period that keeps x + h u + dS(u) ≤ wall.
            let mut next = (uf + p.a_max() * h).min(p.v_max());
            let brake = (uf - b_f * h).max(0.0);
            for _ in 0..60 {
                if xf + h * next + d_s(&p, next) <= wall || next <= brake {
                    break;
                }
                next = (next - 0.05).max(brake);
            }
            uf = next;
            xf += uf * h;
        }
    }
}

/// The credit takes the harder of the two limits: a car (7.9) behind a truck (4.5) is
/// credited the truck's travel at the car's limit, which is less than at the truck's.
#[test]
fn the_credit_takes_the_harder_of_the_two_limits() {
    let car = with_brake(7.9);
    let truck = with_brake(4.5);
    let v = 20.0;
    assert!(leader_credit(&car, v, 4.5) < leader_credit(&truck, v, 4.5));
    assert_eq!(leader_credit(&car, v, 4.5), leader_credit(&car, v, 7.9));
    assert_eq!(leader_credit(&truck, v, 7.9), leader_credit(&car, v, 7.9));
    // Along the road: cos θmax of the least travel along the path.
    let along = least_travel(&car, v, 7.9) * car.theta_max().cos();
    assert!((leader_credit(&car, v, 7.9) - along).abs() < 1e-12);
}

/// Where the ego stands in these tests: not at 0, so that a gap measured from the wrong
/// end shows.
const EGO_X: f64 = 100.0;

/// The single-lane planner's gap toward one vehicle ahead, as `planner` sees it from
/// [`EGO_X`]; `ahead.x` is taken relative to the ego.
fn gap_to(planner: &mut planner_core::Planner<f64, 20>, ahead: planner_core::Vehicle<f64>) -> f64 {
    let ahead = planner_core::Vehicle {
        x: ahead.x + EGO_X,
        ..ahead
    };
    let obs = planner_core::Observation {
        x: EGO_X,
        v_prev: 10.0,
        vehicles: &[ahead],
        stop_line: None,
        target_x: EGO_X,
        v_ref: 10.0,
    };
    planner.step(&obs).expect("a valid observation").gap
}

#[test]
fn the_single_lane_planner_credits_a_cooperating_leader_and_nothing_else() {
    use planner_core::{BrakeLimit, CostWeights, Invariant, Planner, Vehicle};
    let p = Params::<f64>::table_i();
    let new = |invariant| {
        let mut pl = Planner::<f64, 20>::new(p, CostWeights::default()).expect("valid");
        pl.set_invariant(invariant);
        assert_eq!(pl.invariant(), invariant);
        pl
    };
    let (mut paper, mut aware) = (new(Invariant::Paper), new(Invariant::LeaderAware));
    let wall = Vehicle::wall(30.0, 4.5);
    let leader = Vehicle {
        v: 12.0,
        brake: BrakeLimit::from_mps2(7.9),
        ..wall
    };
    let raw = 30.0 - 4.5 - p.d0();
    // Well within free_road_gap (no cap), credited or not.
    assert!(raw + leader_credit(&p, 12.0, 7.9) < planner_core::planner::free_road_gap(&p, 20));
    assert!(
        (gap_to(&mut paper, leader) - raw).abs() < 1e-12,
        "the paper's wall"
    );
    assert!(
        (gap_to(&mut aware, wall) - raw).abs() < 1e-12,
        "no limit: a wall"
    );
    let credited = raw + leader_credit(&p, 12.0, 7.9);
    assert!((gap_to(&mut aware, leader) - credited).abs() < 1e-12);
    // A weaker brake than the follower's own is taken at the follower's (a car behind a
    // truck); a harder one is credited less.
    let truck = Vehicle {
        brake: BrakeLimit::from_mps2(4.5),
        ..leader
    };
    assert!((gap_to(&mut aware, truck) - credited).abs() < 1e-12);
    let hard = Vehicle {
        brake: BrakeLimit::from_mps2(10.0),
        ..leader
    };
    let less = raw + leader_credit(&p, 12.0, 10.0);
    assert!((gap_to(&mut aware, hard) - less).abs() < 1e-12);
    assert!(less < credited);
    // Over a bus, its speed may have been rounded up by half a step: credited from below.
    aware.set_bus_resolution(0.0, 0.5).expect("valid");
    let lower = raw + leader_credit(&p, 12.0 - 0.25, 7.9);
    assert!((gap_to(&mut aware, leader) - lower).abs() < 1e-12);
}

#[test]
fn a_vehicle_not_ahead_of_the_front_is_not_credited() {
    use planner_core::{BrakeLimit, CostWeights, Invariant, Planner, Vehicle};
    let p = Params::<f64>::table_i();
    let mut aware = Planner::<f64, 20>::new(p, CostWeights::default()).expect("valid");
    aware.set_invariant(Invariant::LeaderAware);
    // Its wall at exactly the ego's position (x̄ − x = 0), and just behind it: no credit.
    for raw in [0.0, -0.2] {
        let x = raw + 4.5 + p.d0();
        let beside = Vehicle {
            v: 20.0,
            brake: BrakeLimit::from_mps2(7.9),
            ..Vehicle::wall(x, 4.5)
        };
        assert!(
            (gap_to(&mut aware, beside) - raw).abs() < 1e-12,
            "raw {raw}"
        );
    }
    // Just ahead: credited.
    let x = 0.01 + 4.5 + p.d0();
    let ahead = Vehicle {
        v: 20.0,
        brake: BrakeLimit::from_mps2(7.9),
        ..Vehicle::wall(x, 4.5)
    };
    assert!(gap_to(&mut aware, ahead) > 0.01 + 1.0);
}

/// The red team's case: a leader goes silent (or its later words are refused) while its
/// follower is close behind on the credit; the follower passes the leader's stamped
/// centre. Judged by that stamp the leader would be behind it and dropped — no wall at all
/// — so it is judged by its ghost, and keeps its credit and its wall.
#[test]
fn a_silent_leader_whose_stamp_the_follower_passed_keeps_its_credit() {
    use planner_core::{BrakeLimit, CostWeights, Invariant, Planner, Vehicle};
    let p = Params::<f64>::table_i();
    let mut aware = Planner::<f64, 20>::new(p, CostWeights::default()).expect("valid");
    aware.set_invariant(Invariant::LeaderAware);
    let stamped = Vehicle {
        v: 12.0,
        brake: BrakeLimit::from_mps2(7.9),
        ..Vehicle::wall(-1.0, 4.5)
    };
    let raw = -1.0 - 4.5 - p.d0();
    let silent = Vehicle {
        age: 2.0,
        ..stamped
    };
    let credited = raw + leader_credit(&p, 12.0, 7.9);
    assert!(credited > 0.5, "{credited}");
    assert!((gap_to(&mut aware, silent) - credited).abs() < 1e-12);
    // Heard this period at that place, it is a vehicle beside or behind: no obstacle.
    let free = planner_core::planner::free_road_gap(&p, 20);
    assert!((gap_to(&mut aware, stamped) - free).abs() < 1e-12);
    // A wall (no limit) is judged where it stands, however old.
    let wall = Vehicle {
        age: 2.0,
        ..Vehicle::wall(-1.0, 4.5)
    };
    assert!((gap_to(&mut aware, wall) - free).abs() < 1e-12);
}

#[test]
fn a_speed_that_is_not_a_number_is_refused() {
    use planner_core::{BrakeLimit, CostWeights, InputError, Observation, Planner, Vehicle};
    let p = Params::<f64>::table_i();
    let mut planner = Planner::<f64, 20>::new(p, CostWeights::default()).expect("valid");
    for v in [f64::NAN, f64::INFINITY] {
        // With or without a braking limit: the planner checks what it is given.
        for brake in [None, BrakeLimit::from_mps2(7.9)] {
            let ahead = [Vehicle {
                v,
                brake,
                ..Vehicle::wall(30.0, 4.5)
            }];
            let obs = Observation {
                x: 0.0,
                v_prev: 10.0,
                vehicles: &ahead,
                stop_line: None,
                target_x: 0.0,
                v_ref: 10.0,
            };
            assert_eq!(planner.step(&obs), Err(InputError::NotFinite), "v {v}");
        }
    }
}

#[test]
fn the_view_hands_over_the_limit_and_age_of_every_cooperating_vehicle() {
    use planner_core::heapless::Vec;
    use planner_core::{BrakeLimit, Instant, VehicleState, WorldView};
    let t = |ms| Instant::from_millis(ms);
    let state = |id, stamp, cooperative, brake| VehicleState {
        id,
        x: 50.0,
        y: 1.8,
        theta: 0.0,
        v: 12.0,
        omega: 0.0,
        lane: 0,
        alpha: None,
        beta: None,
        stamp: t(stamp),
        cooperative,
        brake,
        length: None,
    };
    let b = BrakeLimit::from_mps2(7.9);
    let mut view = WorldView::<f64, 8>::new(9);
    for s in [
        state(1, 1_000, true, b),    // fresh, cooperating, declared: credited
        state(2, 1_000, false, b),   // not cooperating
        state(3, 1_000, true, None), // no limit declared
        state(4, 500, true, b),      // half a second old: credited, with its age
        state(5, 1, true, b),        // silent for a second: still credited
    ] {
        view.update(&s, t(1_000)).expect("taken");
    }
    let mut out = Vec::new();
    view.lane_leaders(0, 4.5, t(1_000), &mut out);
    let brake_of = |id: usize| out[id - 1].brake;
    assert_eq!(
        [
            brake_of(1),
            brake_of(2),
            brake_of(3),
            brake_of(4),
            brake_of(5)
        ],
        [b, None, None, b, b]
    );
    let ages: std::vec::Vec<f64> = out.iter().map(|c| c.age).collect();
    assert_eq!(ages, [0.0, 0.0, 0.0, 0.5, 0.999]);
    assert!(out
        .iter()
        .all(|c| c.v == 12.0 && c.x == 50.0 && c.length == 4.5));
    // The plain view hands over walls only.
    view.lane_vehicles(0, 4.5, &mut out);
    assert!(out.iter().all(|c| c.brake.is_none()));
    // Another lane's vehicles are not handed over.
    view.lane_leaders(1, 4.5, t(1_000), &mut out);
    assert!(out.is_empty());
}
