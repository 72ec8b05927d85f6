//! Single-lane platoons (Theorem 1): a leader driving an adversarial admissible profile,
//! followers each running their own planner-core instance, an independent monitor.

use super::experiment::{Experiment, RunError};
use super::shard::{combine_all, MergeError};
use crate::monitor::{Findings, Limits, Truth};
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::Body;
use planner_core::planner::Vehicle;
use planner_core::{
    BrakeLimit, CostWeights, FallbackReason, Invariant, Observation, Params, Planner, Real,
    ReusePolicy, StepStatus,
};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// How the platoon's leader drives: any profile within [0, vmax] and [amin, amax].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LeaderProfile {
    /// A new random acceleration in [amin, amax] every 0.2–2 s.
    Random,
    /// Cruise, then full braking to a stop, wait, full acceleration, and again.
    EmergencyStops,
    /// Alternating full acceleration and full braking phases of 1–4 s.
    StopAndGo,
}

/// One platoon experiment.
#[derive(Debug, Clone, Copy)]
pub struct PlatoonSpec {
    /// Number of vehicles, leader included (≥ 2).
    pub vehicles: usize,
    /// Simulated time (s).
    pub duration_s: f64,
    /// Leader behaviour.
    pub profile: LeaderProfile,
    /// Seed of the initial state and the leader's profile.
    pub seed: u64,
    /// Followers plan in f32 (as on the Cortex-M4F) instead of f64.
    pub f32_planners: bool,
    /// Followers reuse their certified previous plan ([`ReusePolicy::default`]) instead
    /// of solving every step.
    pub reuse: bool,
    /// The invariant the followers keep toward the vehicle ahead. Under
    /// [`Invariant::LeaderAware`] each follower credits the follower ahead of it (a
    /// cooperating planner that declares its braking limit) and starts as close as that
    /// allows; the adversarial leader is scripted, not cooperating, so its follower takes
    /// it as a wall, as it would any vehicle that does not keep the protocol.
    pub invariant: Invariant,
    /// Percent of the vehicles (leader included) that are trucks
    /// ([`crate::world::Body::TRUCK`]), each drawn at random; 0 draws nothing.
    pub trucks_percent: u8,
}

/// Result of a platoon run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlatoonOutcome {
    /// Monitor findings.
    pub findings: Findings,
    /// Planner steps taken.
    pub planner_steps: u64,
    /// Steps on which a planner applied the certified fallback.
    pub fallback_steps: u64,
    /// Of those: the invariant (with margin) did not hold.
    pub fallback_invariant: u64,
    /// Of those: no room to move (e.g. stopped behind a stopped vehicle): forced braking.
    pub fallback_no_room: u64,
    /// Of those: the solver stopped without a solution.
    pub fallback_solver: u64,
    /// Of those: the plan failed verification.
    pub fallback_verification: u64,
    /// Steps that applied the certified previous plan without a solve.
    pub reused_steps: u64,
    /// Follower steps closer to the vehicle ahead than Lemma 3's wall allows (always 0
    /// under the paper's invariant, where each would be a violation): how much the
    /// leader-aware invariant's credit is used.
    pub credited_steps: u64,
}

/// Horizon of the followers' planners.
pub const HORIZON: usize = 20;

struct Leader {
    profile: LeaderProfile,
    accel: f64,
    until: f64,
    phase: u8,
}

impl Leader {
    fn accel(&mut self, t: f64, lim: &Limits, rng: &mut ChaCha8Rng) -> f64 {
        if t >= self.until {
            match self.profile {
                LeaderProfile::Random => {
                    self.accel = rng.random_range(-lim.brake..lim.a_max);
                    self.until = t + rng.random_range(0.2..2.0);
                }
                LeaderProfile::EmergencyStops => {
                    self.phase = (self.phase + 1) % 3;
                    let (a, d) = match self.phase {
                        0 => (
                            rng.random_range(-0.5..lim.a_max),
                            rng.random_range(1.0..6.0),
                        ),
                        1 => (-lim.brake, rng.random_range(2.0..5.0)),
                        _ => (0.0, rng.random_range(0.0..3.0)),
                    };
                    self.accel = a;
                    self.until = t + d;
                    if self.phase == 2 {
                        // After a standstill, leave at full acceleration.
                        self.accel = lim.a_max;
                    }
                }
                LeaderProfile::StopAndGo => {
                    self.phase ^= 1;
                    self.accel = if self.phase == 0 {
                        lim.a_max
                    } else {
                        -lim.brake
                    };
                    self.until = t + rng.random_range(1.0..4.0);
                }
            }
        }
        self.accel
    }
}

/// A random platoon spec for case `i` of a Theorem 1 sweep (planners solving every step).
pub fn random_spec(i: u64, seed: u64) -> PlatoonSpec {
    let mut rng = crate::reference::instances::rng(seed.wrapping_mul(1_000_003).wrapping_add(i));
    let profile = match rng.random_range(0..3) {
        0 => LeaderProfile::Random,
        1 => LeaderProfile::EmergencyStops,
        _ => LeaderProfile::StopAndGo,
    };
    PlatoonSpec {
        vehicles: rng.random_range(2..=20),
        duration_s: rng.random_range(20.0..30.0),
        profile,
        seed: rng.random(),
        f32_planners: i % 4 == 3,
        reuse: false,
        invariant: Invariant::Paper,
        trucks_percent: 0,
    }
}

/// Runs a platoon (dispatching on the planners' precision).
pub fn run(spec: &PlatoonSpec) -> PlatoonOutcome {
    if spec.f32_planners {
        run_in::<f32>(spec)
    } else {
        run_in::<f64>(spec)
    }
}

fn run_in<F: Real>(spec: &PlatoonSpec) -> PlatoonOutcome {
    let lim = Limits::table_i();
    let mut rng = crate::reference::instances::rng(spec.seed);
    let mut cars = initial_platoon(spec, &lim, &mut rng);
    let n = cars.len();
    let policy = spec.reuse.then(ReusePolicy::<F>::default);
    let mut planners: Vec<Planner<F, HORIZON>> = cars[1..]
        .iter()
        .map(|c| {
            let params = params_of::<F>(c);
            let mut p = Planner::new(params, CostWeights::default()).expect("valid weights");
            p.set_reuse(policy).expect("the default policy is valid");
            p.set_invariant(spec.invariant);
            p
        })
        .collect();
    let mut leader = Leader {
        profile: spec.profile,
        accel: 0.0,
        until: 0.0,
        phase: 0,
    };
    let mut findings = Findings::new();
    let mut out = PlatoonOutcome {
        findings,
        planner_steps: 0,
        fallback_steps: 0,
        fallback_invariant: 0,
        fallback_no_room: 0,
        fallback_solver: 0,
        fallback_verification: 0,
        reused_steps: 0,
        credited_steps: 0,
    };
    let steps = (spec.duration_s / lim.h).round() as u64;
    let mut commands = vec![0.0f64; n];
    let mut seen: Vec<Vehicle<F>> = Vec::with_capacity(n);
    for step in 0..steps {
        let t = step as f64 * lim.h;
        findings.check(&lim, &cars, None, 1);
        out.credited_steps += closer_than_walls(&lim, &cars);
        // Every vehicle decides on the state at t, then all move.
        seen.clear();
        seen.extend(cars.iter().map(seen_as::<F>));
        let a = leader.accel(t, &lim, &mut rng);
        let v0 = cars[0].v;
        // Within its own limits: a truck leader's full braking is its own.
        commands[0] = (v0 + a * lim.h).clamp(
            (v0 - cars[0].brake * lim.h).max(0.0),
            (v0 + lim.a_max * lim.h).min(lim.v_max),
        );
        for (i, planner) in planners.iter_mut().enumerate() {
            commands[i + 1] = follower_command(planner, &cars[i + 1], &seen, &lim, &mut out);
        }
        for (c, &v) in cars.iter_mut().zip(commands.iter()) {
            c.v_before = c.v;
            c.v = v;
            c.x += v * lim.h;
        }
    }
    findings.check(&lim, &cars, None, 1);
    out.findings = findings;
    out
}

/// Followers in `cars` (front first) closer to the vehicle ahead than Lemma 3's wall
/// allows: gap − d0 ≤ dS(v).
fn closer_than_walls(lim: &Limits, cars: &[Truth]) -> u64 {
    let close = |w: &[Truth]| {
        let gap = w[0].x - w[1].x - 0.5 * (w[0].length + w[1].length);
        gap - lim.d0 <= lim.safe_distance_at(w[1].v, w[1].brake)
    };
    cars.windows(2).filter(|w| close(w)).count() as u64
}

/// Table I's parameters with `c`'s length and braking limit, in `F`.
fn params_of<F: Real>(c: &Truth) -> Params<F> {
    let spec = planner_core::ParamsSpec {
        length: F::from_f64(c.length),
        a_min: F::from_f64(-c.brake),
        ..planner_core::ParamsSpec::table_i()
    };
    // A body the platoon drew (a car or a truck) is always valid.
    Params::new(spec).unwrap_or_else(|_| Params::table_i())
}

/// How the followers see `c`: exactly where it is; with its speed and braking limit
/// when it keeps the invariant (a follower: it cooperates and declares its limit), so a
/// follower keeping the leader-aware invariant credits it; the scripted leader is a wall.
fn seen_as<F: Real>(c: &Truth) -> Vehicle<F> {
    let wall = Vehicle::wall(F::from_f64(c.x), F::from_f64(c.length));
    if !c.keeps_invariant {
        return wall;
    }
    Vehicle {
        v: F::from_f64(c.v),
        brake: BrakeLimit::from_mps2(c.brake),
        ..wall
    }
}

/// The platoon at t = 0: the leader at the front; each follower behind its predecessor
/// by the extent, d0, dS(v) and the f32 safety margin, plus a random extra — so the
/// invariant holds, with the planners' margins, from the start. Under the leader-aware
/// invariant a follower behind a follower starts closer by what it credits that one
/// with (never closer than the extent, d0 and the margin).
fn initial_platoon(spec: &PlatoonSpec, lim: &Limits, rng: &mut impl Rng) -> Vec<Truth> {
    let n = spec.vehicles.max(2);
    let margin = f64::from(f32::SAFETY_MARGIN_M) + 0.01;
    let aware = spec.invariant == Invariant::LeaderAware;
    let mut cars: Vec<Truth> = Vec::with_capacity(n);
    let mut x = 0.0;
    for i in 0..n {
        let v = rng.random_range(0.0..lim.v_max);
        let pct = spec.trucks_percent;
        let truck = pct > 0 && rng.random_range(0..100u8) < pct;
        let body = if truck { Body::TRUCK } else { Body::CAR };
        if let Some(ahead) = cars.last() {
            // The planners' credit (a lower bound of the monitor's exact one).
            let p = crate::world::vehicle::params(lim.v_max, body);
            let credit = if aware && i > 1 {
                planner_core::safety::leader_credit(&p, ahead.v, ahead.brake)
            } else {
                0.0
            };
            let room = (lim.safe_distance_at(v, body.brake) - credit).max(0.0);
            let extent = 0.5 * (ahead.length + body.length);
            x -= extent + lim.d0 + room + margin + rng.random_range(0.0..20.0);
        }
        cars.push(Truth {
            x,
            y: 0.5 * crate::world::LANE_WIDTH_M,
            theta: 0.0,
            length: body.length,
            width: crate::world::WIDTH_M,
            lane: 0,
            keeps_invariant: i > 0,
            leader_aware: aware && i > 0,
            brake: body.brake,
            v,
            v_before: v,
            mapped: false,
        });
    }
    cars
}

/// One follower's planner step on what it sees, counted into `out` by outcome.
fn follower_command<F: Real>(
    planner: &mut Planner<F, HORIZON>,
    me: &Truth,
    seen: &[Vehicle<F>],
    lim: &Limits,
    out: &mut PlatoonOutcome,
) -> f64 {
    let obs = Observation {
        x: F::from_f64(me.x),
        v_prev: F::from_f64(me.v),
        vehicles: seen,
        stop_line: None,
        target_x: F::ZERO,
        v_ref: planner.params().v_max(),
    };
    out.planner_steps += 1;
    let c = match planner.step(&obs) {
        Ok(c) => c,
        // Bad input cannot happen here; brake if it ever does.
        Err(_) => {
            out.fallback_steps += 1;
            return (me.v - me.brake * lim.h).max(0.0);
        }
    };
    if let StepStatus::Reused { .. } = c.status {
        out.reused_steps += 1;
    }
    if let StepStatus::Fallback(why) = c.status {
        out.fallback_steps += 1;
        match why {
            FallbackReason::InvariantViolated => out.fallback_invariant += 1,
            FallbackReason::NoRoom => out.fallback_no_room += 1,
            FallbackReason::Solver(e) => {
                out.fallback_solver += 1;
                if std::env::var_os("PLATOON_DEBUG").is_some() {
                    eprintln!("solver {e:?} at v={:?} gap={:?}", me.v, c.gap);
                }
            }
            // Verification; a single-lane planner has neither the lane sets nor steering,
            // so no other reason reaches here.
            _ => out.fallback_verification += 1,
        }
    }
    c.v.to_f64()
}

/// `host-sim platoons`: its cases, seed, and how the followers plan (a shard's header
/// leaves the invariant out when it is the paper's, as shards always had it).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, clap::Args)]
pub struct Platoons {
    /// Number of random platoons.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..))]
    pub cases: u64,
    /// Seed of the sweep.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The followers reuse their certified previous plan instead of solving every step
    /// (planner-core's `ReusePolicy::default()`).
    #[arg(long)]
    pub reuse: bool,
    /// The invariant every follower keeps toward the vehicle ahead (the adversarial
    /// leader, scripted, is a wall under either).
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = super::flags::invariant())]
    #[serde(
        default,
        skip_serializing_if = "super::flags::is_paper",
        with = "crate::world::invariant_serde"
    )]
    pub invariant: Invariant,
    /// Percent of the vehicles that are trucks (16.5 m, braking at 4.5 m/s²), drawn per
    /// vehicle, the leader too; 0 gives the platoons as they always were.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100))]
    #[serde(default, skip_serializing_if = "super::flags::is_zero")]
    pub trucks: u8,
}

impl Experiment for Platoons {
    const NAME: &'static str = "platoons";
    type Part = SweepSummary;
    type Report = SweepSummary;

    fn cases(&self) -> u64 {
        self.cases
    }

    fn run(&self, (first, end): (u64, u64), _threads: usize) -> Result<SweepSummary, RunError> {
        let following = Following {
            reuse: self.reuse,
            invariant: self.invariant,
            trucks_percent: self.trucks,
        };
        Ok(sweep_range(first, end, self.seed, following))
    }

    fn report(&self, parts: Vec<SweepSummary>) -> Result<SweepSummary, MergeError> {
        combine_all(parts)
    }
}

impl Judged for SweepSummary {
    /// Collisions, invariant and limit violations; a platoon has no goal but safety.
    fn verdict(&self) -> Verdict {
        let safety = Safety::of(
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            0,
        );
        Verdict::new(safety, true)
    }
}

/// Summary of a Theorem 1 sweep.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct SweepSummary {
    /// Platoons run.
    pub cases: u64,
    /// The invariant the followers kept (`paper`, `leader-aware`).
    pub invariant: String,
    /// Vehicles in all platoons.
    pub vehicles: u64,
    /// Planner steps.
    pub planner_steps: u64,
    /// Fallback steps.
    pub fallback_steps: u64,
    /// Of those, forced standstills (no room).
    pub fallback_no_room: u64,
    /// Of those, solver failures or failed verifications.
    pub fallback_solver_or_verification: u64,
    /// Steps that applied a certified previous plan without a solve (with `--reuse`).
    pub reused_steps: u64,
    /// Follower steps closer than Lemma 3's wall allows (leader-aware credit used).
    pub credited_steps: u64,
    /// Collisions seen by the monitor.
    pub collisions: u64,
    /// Invariant violations seen by the monitor.
    pub invariant_violations: u64,
    /// Speed/acceleration limit violations.
    pub limit_violations: u64,
    /// Smallest bumper gap (m; none over no case, written `null`).
    #[serde(deserialize_with = "null_as_infinity")]
    pub min_gap_m: f64,
    /// Wall time (s).
    pub wall_seconds: f64,
}

/// A gap written `null` (JSON has no infinity): no gap seen.
fn null_as_infinity<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

/// How a sweep's followers plan: whether they reuse certified plans, and the
/// invariant they keep.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Following {
    /// Followers reuse their certified previous plan.
    pub reuse: bool,
    /// The invariant they keep toward the vehicle ahead.
    pub invariant: Invariant,
    /// Percent of the vehicles that are trucks.
    pub trucks_percent: u8,
}

/// Runs `cases` random platoons of a sweep on all cores: (spec, outcome) per case, in
/// case order, the followers planning as `following` says.
pub fn run_cases(
    cases: u64,
    seed: u64,
    following: Following,
) -> Vec<(PlatoonSpec, PlatoonOutcome)> {
    run_range(0, cases, seed, following)
}

/// Runs the platoons `first..end` of a sweep on all cores, in case order.
pub fn run_range(
    first: u64,
    end: u64,
    seed: u64,
    following: Following,
) -> Vec<(PlatoonSpec, PlatoonOutcome)> {
    super::par::map_indexed(end.saturating_sub(first) as usize, 0, |i| {
        let spec = PlatoonSpec {
            reuse: following.reuse,
            invariant: following.invariant,
            trucks_percent: following.trucks_percent,
            ..random_spec(first + i as u64, seed)
        };
        let out = run(&spec);
        (spec, out)
    })
}

/// Runs `cases` random platoons on all cores and sums up what the monitor saw.
pub fn sweep(cases: u64, seed: u64, following: Following) -> SweepSummary {
    sweep_range(0, cases, seed, following)
}

/// [`sweep`] over the platoons `first..end` only (a shard).
pub fn sweep_range(first: u64, end: u64, seed: u64, following: Following) -> SweepSummary {
    let t0 = std::time::Instant::now();
    let mut total = SweepSummary {
        invariant: crate::world::invariant_name(following.invariant).into(),
        min_gap_m: f64::INFINITY,
        ..Default::default()
    };
    for (spec, out) in run_range(first, end, seed, following) {
        total.cases += 1;
        total.vehicles += spec.vehicles as u64;
        total.planner_steps += out.planner_steps;
        total.fallback_steps += out.fallback_steps;
        total.fallback_no_room += out.fallback_no_room;
        total.fallback_solver_or_verification += out.fallback_solver + out.fallback_verification;
        total.reused_steps += out.reused_steps;
        total.credited_steps += out.credited_steps;
        total.collisions += out.findings.collisions;
        total.invariant_violations += out.findings.invariant_violations;
        total.limit_violations += out.findings.limit_violations;
        total.min_gap_m = total.min_gap_m.min(out.findings.min_gap_m);
    }
    total.wall_seconds = t0.elapsed().as_secs_f64();
    total
}

impl core::fmt::Display for SweepSummary {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "Theorem 1: {} random platoons ({} invariant), {} vehicles, {} planner steps in {:.1} s\n  \
             {} collisions, {} invariant violations, {} limit violations; smallest gap {:.3} m\n  \
             fallback steps: {} ({} standstills with no room, {} solver or verification); \
             certified plan reuses: {}; steps closer than a wall allows: {}",
            self.cases,
            self.invariant,
            self.vehicles,
            self.planner_steps,
            self.wall_seconds,
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            self.min_gap_m,
            self.fallback_steps,
            self.fallback_no_room,
            self.fallback_solver_or_verification,
            self.reused_steps,
            self.credited_steps
        )
    }
}
