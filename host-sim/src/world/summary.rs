//! What a run produced: the `--json` summary of `host-sim run`.

use super::vehicle::{Counters, Vehicle};
use super::{Arrivals, SolverChoice, World, WorldSpec};
use crate::bus::{Bus, FaultStats};
use crate::monitor::liveness::Deadlock;
use crate::monitor::Findings;
use crate::verdict::{Judged, Safety, Verdict};
use serde::Serialize;

/// A liar's states and reports, as planners took them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Lies {
    /// Heard by planners (one per lie and receiver).
    pub heard: u64,
    /// Of those, taken into a view.
    pub taken: u64,
}

/// Lane changes of a run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LaneChangeStats {
    /// Planner-driven vehicles.
    pub vehicles: usize,
    /// How many are in their target lane with no change pending.
    pub in_target_lane: usize,
    /// Lane changes completed.
    pub changes: usize,
    /// When the last vehicle reached its target lane (s), if all did.
    pub all_done_at_s: Option<f64>,
    /// Longest x-distance driven from declaring an intention to completing the change (m).
    pub max_distance_m: f64,
}

/// Junction crossings of a run (present when the world has junctions).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CrossingStats {
    /// The managers' algorithm (of the first junction).
    pub algorithm: &'static str,
    /// Junctions crossed (a vehicle crossing two counts twice).
    pub crossed: u64,
    /// Mean time from arrival (entering A_C) to leaving A_C (s).
    pub crossing_time_mean_s: f64,
    /// Longest such time (s).
    pub crossing_time_max_s: f64,
    /// Steps × vehicles inside A_S without a permission ever granted (IC Protocol (ii)).
    pub unpermitted_entries: u64,
    /// Vehicles still in the world at the end.
    pub in_system: usize,
}

/// What a run produced.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Scenario name.
    pub scenario: String,
    /// Vehicles (at the start and entered since).
    pub vehicles: usize,
    /// Simulated time (s).
    pub sim_seconds: f64,
    /// Collision findings (vehicle pairs × steps).
    pub collisions: u64,
    /// Invariant violations (pairs × steps).
    pub invariant_violations: u64,
    /// Speed, acceleration or heading limit violations (vehicles × steps).
    pub limit_violations: u64,
    /// Steps × vehicles past a road end.
    pub road_end_overruns: u64,
    /// Steps × vehicles with their rectangle off the road.
    pub off_road: u64,
    /// Smallest bumper-to-bumper gap between consecutive vehicles of a lane (m).
    pub min_gap_m: f64,
    /// Planner steps that applied the certified fallback (solver, verification or
    /// invariant).
    pub fallback_steps: u64,
    /// Of those, steps whose view overflowed within the relevance radius (a vehicle that
    /// may matter could not be held): 0 in any world, whatever its size.
    pub blind_steps: u64,
    /// Planner steps standing still with no room (forced, not a failure).
    pub waiting_steps: u64,
    /// Planner steps braking under the Yield Protocol (not a failure).
    pub yield_steps: u64,
    /// Lane changes.
    pub lane_changes: LaneChangeStats,
    /// Lateral-QP iterations over the run.
    pub lateral_iterations_total: u64,
    /// Planner steps.
    pub planner_steps: u64,
    /// Mean interior-point iterations of the planner steps that solved.
    pub solver_iterations_mean: f64,
    /// Planner steps that applied a certified previous plan without a solve (only with
    /// plan reuse on).
    pub reused_steps: u64,
    /// Every goal met: every goal x reached by the deadline, every planner-driven vehicle
    /// in its target lane, every vehicle through its junctions (when the world has any
    /// and no arrivals), and no deadlock.
    pub completed: bool,
    /// Planner-driven vehicles: each has goals (its target lane; a goal x, or junctions to
    /// cross and an exit to reach, where the world gives them). Always `goals_met +
    /// unfinished + under_way`.
    pub goals: usize,
    /// Of those, vehicles whose goals are all met at the end (gone through an exit
    /// counts as met).
    pub goals_met: usize,
    /// Of those, vehicles still under way in an open world that are not yet due to have
    /// met their goals (they arrived less than their free-flow time plus
    /// [`OPEN_GRACE_S`] before the end): neither met nor failed.
    pub under_way: usize,
    /// Vehicles with a goal x (the Fig. 6 worlds).
    pub goal_x: usize,
    /// Of those, goal x reached by the deadline.
    pub goal_x_reached: usize,
    /// Latest time a goal x was reached (s), if any.
    pub last_goal_time_s: Option<f64>,
    /// Messages the vehicles broadcast.
    pub messages_sent: u64,
    /// Messages a vehicle's view rejected (stale, invalid, implausible).
    pub messages_rejected: u64,
    /// Of those, states and crossing reports refused as physically implausible
    /// (`world::plausible`: a jump, a speed, a speed change or a lane beyond the bounds).
    pub messages_implausible: u64,
    /// A liar's states and reports (`[faults.liar]` runs only): heard by planners, and
    /// of those taken into a view (0 when every lie is refused).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lies: Option<Lies>,
    /// What the bus's injected faults did.
    pub bus_faults: FaultStats,
    /// Solver used by the multi-lane planners.
    pub solver: SolverChoice,
    /// Seed used.
    pub seed: u64,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
    /// Junction crossings, when the world has junctions.
    #[serde(flatten)]
    pub crossing: Option<CrossingStats>,
    /// Planner-driven vehicles with a goal still unmet at the end that were due to have
    /// met it (every such vehicle in a closed world).
    pub unfinished: usize,
    /// Of the unfinished vehicles, those held up by a silent vehicle (a run with
    /// `[faults.silent]` that no deadlock ended): each waits, at the end, on the vehicle
    /// whose transmitter is silent — ahead of it, or in the lane it must change into.
    pub held_by_silent: usize,
    /// The deadlock that ended the run, if one did.
    pub deadlock: Option<Deadlock>,
    /// How each vehicle computer in the loop ended (`run --firmware`; else empty, and
    /// not in the JSON).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub firmware: Vec<crate::firmware::FirmwareReport>,
}

impl Summary {
    /// Junctions crossed (0 without junctions).
    pub fn crossed(&self) -> u64 {
        self.crossing.as_ref().map_or(0, |c| c.crossed)
    }
    /// Mean crossing time (s; 0 without junctions).
    pub fn crossing_time_mean_s(&self) -> f64 {
        self.crossing
            .as_ref()
            .map_or(0.0, |c| c.crossing_time_mean_s)
    }
    /// Longest crossing time (s; 0 without junctions).
    pub fn crossing_time_max_s(&self) -> f64 {
        self.crossing
            .as_ref()
            .map_or(0.0, |c| c.crossing_time_max_s)
    }
    /// Entries into A_S without a permission (0 without junctions).
    pub fn unpermitted_entries(&self) -> u64 {
        self.crossing.as_ref().map_or(0, |c| c.unpermitted_entries)
    }
    /// Collisions, invariant and limit violations, road-end overruns and unpermitted
    /// entries: every safety finding.
    pub fn unsafe_events(&self) -> u64 {
        self.safety().events()
    }

    /// Its findings, by kind.
    pub fn safety(&self) -> Safety {
        Safety {
            road_end_overruns: self.road_end_overruns,
            ..Safety::of(
                self.collisions,
                self.invariant_violations,
                self.limit_violations,
                self.unpermitted_entries(),
            )
        }
    }
}

/// Lane-change statistics of `vehicles`.
pub fn lane_changes<'a, const N: usize>(
    vehicles: impl Iterator<Item = &'a Vehicle<N>> + Clone,
) -> LaneChangeStats {
    let wanted: Vec<&Vehicle<N>> = vehicles.filter(|v| v.is_planner()).collect();
    let done: Vec<f64> = wanted.iter().filter_map(|v| v.log.in_target_at).collect();
    LaneChangeStats {
        vehicles: wanted.len(),
        in_target_lane: done.len(),
        changes: wanted.iter().map(|v| v.log.changes.len()).sum(),
        all_done_at_s: (done.len() == wanted.len())
            .then(|| done.iter().copied().fold(0.0, f64::max)),
        max_distance_m: wanted
            .iter()
            .flat_map(|v| v.log.changes.iter().map(|c| c.0))
            .fold(0.0, f64::max),
    }
}

/// What a run produced besides its vehicles.
pub struct Outcome<'a> {
    /// The world that ran.
    pub spec: &'a WorldSpec,
    /// Vehicles in the world at the end.
    pub in_world: usize,
    /// Of those, planner-driven vehicles with a goal still unmet that were due to have
    /// met it.
    pub unfinished: usize,
    /// Of those, planner-driven vehicles with a goal still unmet, not yet due.
    pub under_way: usize,
    /// Of the unfinished, those held up by a silent vehicle.
    pub held_by_silent: usize,
    /// The monitor's findings.
    pub findings: &'a Findings,
    /// The planners' counters.
    pub counters: &'a Counters,
    /// The deadlock that ended the run, if one did.
    pub deadlock: Option<&'a Deadlock>,
    /// Simulated time (s).
    pub t: f64,
    /// Messages the vehicles broadcast.
    pub messages_sent: u64,
    /// What injected faults did.
    pub bus_faults: FaultStats,
    /// The multi-lane planners' solver.
    pub solver: SolverChoice,
    /// Seed.
    pub seed: u64,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// In an open world, how long after its free-flow time a vehicle may still be under way
/// at the end without counting as unfinished (s).
pub const OPEN_GRACE_S: f64 = 120.0;

/// The summary of a run whose vehicles (in the world and gone) are `all`.
pub fn summarize<'v, const N: usize>(
    all: impl Iterator<Item = &'v Vehicle<N>> + Clone,
    o: &Outcome<'_>,
) -> Summary {
    let f = o.findings;
    let c = o.counters;
    let deadline = o.spec.deadline_s;
    let with_goal: Vec<&Vehicle<N>> = all.clone().filter(|v| v.trip.goal_x.is_some()).collect();
    let reached: Vec<f64> = with_goal
        .iter()
        .filter_map(|v| v.log.reached_at)
        .filter(|&t| t <= deadline + 1e-9)
        .collect();
    let lc = lane_changes(all.clone());
    let net = &o.spec.network;
    let crossing = (!net.junctions.is_empty()).then(|| {
        let times: Vec<f64> = all
            .clone()
            .flat_map(|v| v.log.crossings.iter().copied())
            .collect();
        CrossingStats {
            algorithm: net.junctions.first().map_or("", |j| j.algorithm.name()),
            crossed: times.len() as u64,
            crossing_time_mean_s: times.iter().sum::<f64>() / times.len().max(1) as f64,
            crossing_time_max_s: times.iter().copied().fold(0.0, f64::max),
            unpermitted_entries: f.unpermitted_entries,
            in_system: o.in_world,
        }
    });
    let through = crossing
        .as_ref()
        .is_none_or(|x| x.in_system == 0 || o.spec.arrivals != Arrivals::None);
    Summary {
        scenario: o.spec.name.clone(),
        vehicles: all.clone().count(),
        sim_seconds: o.t,
        collisions: f.collisions,
        invariant_violations: f.invariant_violations,
        limit_violations: f.limit_violations,
        road_end_overruns: f.road_end_overruns,
        off_road: f.off_road,
        min_gap_m: f.min_gap_m,
        fallback_steps: c.fallback_steps,
        blind_steps: c.blind_steps,
        waiting_steps: c.waiting_steps,
        yield_steps: c.yield_steps,
        lane_changes: lc,
        lateral_iterations_total: c.lateral_iterations,
        planner_steps: c.planner_steps,
        solver_iterations_mean: c.solver_iterations as f64 / c.solved_steps.max(1) as f64,
        reused_steps: c.reused_steps,
        // An open world is never empty of vehicles under way: there, every vehicle that
        // is due (see `World::due`) must have met its goals.
        completed: reached.len() == with_goal.len()
            && match o.spec.arrivals {
                Arrivals::Poisson(_) => o.unfinished == 0,
                _ => lc.in_target_lane == lc.vehicles && through,
            }
            && o.deadlock.is_none(),
        goals: lc.vehicles,
        goals_met: lc.vehicles.saturating_sub(o.unfinished + o.under_way),
        under_way: o.under_way,
        goal_x: with_goal.len(),
        goal_x_reached: reached.len(),
        last_goal_time_s: reached.iter().copied().reduce(f64::max),
        messages_sent: o.messages_sent,
        messages_rejected: c.rejected,
        messages_implausible: c.implausible,
        lies: o.spec.faults.liar.map(|_| Lies {
            heard: c.lies_heard,
            taken: c.lies_taken,
        }),
        bus_faults: o.bus_faults,
        solver: o.solver,
        seed: o.seed,
        wall_seconds: o.wall_seconds,
        crossing,
        unfinished: o.unfinished,
        held_by_silent: o.held_by_silent,
        deadlock: o.deadlock.cloned(),
        firmware: Vec::new(),
    }
}

impl<const N: usize, B: Bus> World<N, B> {
    /// Every vehicle that has been in the world: those in it now, then those gone.
    pub fn all_vehicles(&self) -> impl Iterator<Item = &Vehicle<N>> + Clone {
        self.vehicles.iter().chain(self.gone.iter())
    }

    /// The findings so far.
    pub fn findings(&self) -> &Findings {
        &self.watch.monitor.findings
    }

    /// The counters so far.
    pub fn counters(&self) -> &Counters {
        &self.tally.counters
    }

    /// Measures what each planner step costs in wall-clock time from now on.
    pub fn measure_step_costs(&mut self) {
        self.tally.costs.get_or_insert_with(Box::default);
    }

    /// What its planner steps cost in wall-clock time, if measured.
    pub fn step_costs(&self) -> Option<&super::cost::StepCosts> {
        self.tally.costs.as_deref()
    }

    /// `true` if vehicle `v` should have met its goals by now: always in a world whose
    /// vehicles are all there from the start; in an open world only if it arrived at
    /// least its trip's free-flow time plus [`OPEN_GRACE_S`] ago (one that just arrived
    /// has not failed).
    pub(super) fn due<const M: usize>(&self, v: &crate::world::vehicle::Vehicle<M>) -> bool {
        !matches!(self.spec.arrivals, crate::world::Arrivals::Poisson(_))
            || v.log.entered_at + v.log.free_flow_s.unwrap_or(0.0) + OPEN_GRACE_S <= self.time.t
    }

    /// The summary so far.
    pub fn summary(&self, wall_seconds: f64) -> Summary {
        summarize(
            self.all_vehicles(),
            &Outcome {
                spec: &self.spec,
                in_world: self.vehicles.len(),
                unfinished: self
                    .vehicles
                    .iter()
                    .filter(|v| v.unmet(&self.net) && self.due(v))
                    .count(),
                under_way: self
                    .vehicles
                    .iter()
                    .filter(|v| v.unmet(&self.net) && !self.due(v))
                    .count(),
                held_by_silent: self.held_by_silent(),
                findings: &self.watch.monitor.findings,
                counters: &self.tally.counters,
                deadlock: self.watch.deadlock.as_ref(),
                t: self.time.t,
                messages_sent: self.tally.messages_sent,
                bus_faults: self.bus.fault_stats(),
                solver: self.solver,
                seed: self.seed,
                wall_seconds,
            },
        )
    }
}

impl Judged for Summary {
    /// Its findings; live when every vehicle met its goals.
    fn verdict(&self) -> Verdict {
        Verdict::new(self.safety(), self.completed)
    }
}
