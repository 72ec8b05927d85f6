//! Who drives a vehicle — its own planners ([`Brain`]), a script, or random admissible
//! accelerations — and, in one value, where it is and who drives it ([`Role`]): scripted
//! and random drivers keep to roads, so a junction is only ever held by a planner and a
//! pair the world could not run cannot be written.

use super::at::At;
use super::heard::{View, VIEW_CAP};
use super::precision::{params32, sensing32, CrossingF32, LaneF32, Precision, CROSS_HORIZON};
use super::{AnySolver, Body, Fleet, Phase, SolverChoice};
use crate::reference::ClarabelSolver;
use planner_core::crossing::{CrossingPlanner, CrossingReport, PathVehicle};
use planner_core::intersection::Layout;
use planner_core::{
    Command, CostWeights, InputError, Instant, IpmSolver, LaneCommand, LaneInputError,
    LaneObservation, LanePlanner, Other, Params, ParamsSpec, Planner, ReusePolicy, Sensing,
    Settings,
};
use rand_chacha::ChaCha8Rng;

/// Table I with vmax replaced by `v_max` (a segment's or a junction's speed limit), and
/// the length and braking limit of `body`.
pub fn params(v_max: f64, body: Body) -> Params<f64> {
    let spec = ParamsSpec {
        v_max,
        length: body.length,
        a_min: -body.brake,
        ..ParamsSpec::table_i()
    };
    // Limits at or below Table I's keep every Table I relation; loaders check the range.
    Params::new(spec).unwrap_or_else(|_| Params::table_i())
}

/// Cost of the crossing planners: the default, plus a small pull toward the target of
/// Sec. VII-B (x^f), so that the target switching is part of J.
pub fn crossing_weights() -> CostWeights<f64> {
    CostWeights {
        target_position: 1e-3,
        ..CostWeights::default()
    }
}

/// How every planner of a run is set up.
#[derive(Debug, Clone, Copy)]
pub struct PlannerSetup {
    /// The speed solver of the multi-lane planners.
    pub solver: SolverChoice,
    /// The bus's notification bound (s).
    pub notify: f64,
    /// Steps to which the bus rounds positions and speeds (0: exact).
    pub resolution: (f64, f64),
    /// Onboard sensors, if any.
    pub sensing: Option<Sensing<f64>>,
    /// Certified plan reuse in the multi-lane planners, if any (`None`: solve every step).
    pub reuse: Option<ReusePolicy<f64>>,
    /// The planners' precision (`f32` as on the MCU: ours alone, no reuse).
    pub precision: Precision,
    /// Beyond this distance (m) no vehicle can matter to a plan
    /// ([`super::heard::relevance_radius`]).
    pub relevant_m: f64,
    /// The invariant kept toward the vehicle ahead.
    pub invariant: planner_core::Invariant,
    /// What the planners assume of vehicles that do not say (the longest, the weakest
    /// braking).
    pub fleet: Fleet,
}

/// A vehicle's multi-lane planner, in the setup's precision.
pub enum LaneBrain<const N: usize> {
    /// In `f64`, with the chosen solver.
    F64(Box<LanePlanner<f64, N, AnySolver<N>>>),
    /// In `f32`, with planner-core's solver, as on the MCU.
    F32(Box<LaneF32<N>>),
}

impl<const N: usize> LaneBrain<N> {
    pub(super) fn step(
        &mut self,
        obs: &LaneObservation<'_, f64>,
    ) -> Result<LaneCommand<f64>, LaneInputError> {
        match self {
            Self::F64(p) => p.step(obs),
            Self::F32(p) => p.step(obs),
        }
    }

    pub(super) fn braking_command(&self, theta: f64, v_prev: f64) -> (f64, f64) {
        match self {
            Self::F64(p) => p.braking_command(theta, v_prev),
            Self::F32(p) => p.braking_command(theta, v_prev),
        }
    }
}

/// A vehicle's crossing planner, in the setup's precision.
pub enum CrossingBrain {
    /// In `f64`.
    F64(Box<CrossingPlanner<f64, CROSS_HORIZON, VIEW_CAP>>),
    /// In `f32`, on its junction's layout in `f32`.
    F32(Box<CrossingF32>),
}

impl CrossingBrain {
    pub(super) fn clear_reports(&mut self) {
        match self {
            Self::F64(c) => c.clear_reports(),
            Self::F32(c) => c.clear_reports(),
        }
    }

    pub(super) fn hear_report(&mut self, r: &CrossingReport<f64>, stamp: Instant) {
        // An overflow makes the planner take its path as blocked.
        let _ = match self {
            Self::F64(c) => c.hear_report(r, stamp),
            Self::F32(c) => c.hear_report(r, stamp),
        };
    }

    pub(super) fn hear_paths(&mut self, sensed: &[PathVehicle<f64>], mapped: &[PathVehicle<f64>]) {
        // Past the view's capacity the planner takes its path as blocked.
        let _ = match self {
            Self::F64(c) => c.hear_sensed(sensed).and(c.hear_mapped(mapped)),
            Self::F32(c) => c.hear_sensed(sensed).and(c.hear_mapped(mapped)),
        };
    }

    pub(super) fn hear_grant(&mut self, id: u16, until: Instant) {
        match self {
            Self::F64(c) => c.hear_grant(id, until),
            Self::F32(c) => c.hear_grant(id, until),
        }
    }

    pub(super) fn permitted(&self, layout: &Layout<f64>, s: f64, now: Instant) -> bool {
        match self {
            Self::F64(c) => c.permitted(layout, s, now),
            Self::F32(c) => c.permitted(s, now),
        }
    }

    pub(super) fn step(
        &mut self,
        layout: &Layout<f64>,
        (s, v_prev): (f64, f64),
        now: Instant,
    ) -> Result<Command<f64>, InputError> {
        match self {
            Self::F64(c) => c.step(layout, s, v_prev, now),
            Self::F32(c) => c.step(s, v_prev, now),
        }
    }
}

/// The planners of a planner-driven vehicle and what it heard.
pub struct Brain<const N: usize> {
    /// Its multi-lane planner, built on its first step on a segment.
    pub(super) lane: Option<LaneBrain<N>>,
    /// Its crossing planner, built on its first step in a junction.
    pub(super) crossing: Option<CrossingBrain>,
    /// What it heard.
    pub(super) view: View,
    /// The vehicles its planner is told of this step (heard and sensed).
    pub(super) others: Box<heapless::Vec<Other<f64>, VIEW_CAP>>,
    /// How its planners are set up.
    pub(super) setup: PlannerSetup,
    /// Its vehicle's body (its planners' length and braking limit).
    pub(super) body: Body,
    /// Its computer is a firmware image in the loop: it plans on a road instead of the
    /// multi-lane planner, from what the vehicle heard ([`crate::firmware`]).
    pub(super) computer: Option<Box<crate::firmware::Computer>>,
}

/// How a vehicle is driven.
pub enum Driver<const N: usize> {
    /// Its own planners.
    Planner(Box<Brain<N>>),
    /// A fixed acceleration script (an adversarial but admissible driver that ignores
    /// intentions, and brakes for what is physically in its lane ahead).
    Script(Vec<Phase>),
    /// Random admissible accelerations (same physical response).
    Random {
        /// Its own random numbers.
        rng: Box<ChaCha8Rng>,
        /// Current acceleration.
        accel: f64,
        /// Until when.
        until: f64,
    },
}

impl<const N: usize> Brain<N> {
    /// A brain for vehicle `id` of `body` with `setup`.
    pub fn new(id: u16, setup: PlannerSetup, body: Body) -> Self {
        Self {
            lane: None,
            crossing: None,
            view: View::new(id, setup.relevant_m).for_fleet(setup.fleet),
            others: Box::new(heapless::Vec::new()),
            setup,
            body,
            computer: None,
        }
    }

    /// A new setup for the planners built from now on.
    pub fn set_setup(&mut self, setup: PlannerSetup) {
        self.setup = setup;
    }

    /// A multi-lane planner in `lane` of a segment with speed limit `v_max`.
    pub(super) fn lane_planner(&self, lane: u8, v_max: f64) -> LaneBrain<N> {
        if self.setup.precision == Precision::F32 {
            return LaneBrain::F32(Box::new(self.lane_planner32(lane, v_max)));
        }
        let s = match self.setup.solver {
            SolverChoice::Ours => AnySolver::Ours(IpmSolver::default()),
            SolverChoice::OursInteriorPoint => {
                AnySolver::Ours(IpmSolver::new(Settings::interior_point_only()))
            }
            SolverChoice::Clarabel => AnySolver::Clarabel(ClarabelSolver {
                accept_almost_solved: true,
                ..ClarabelSolver::default()
            }),
        };
        let mut p =
            LanePlanner::with_solver(params(v_max, self.body), CostWeights::default(), s, lane)
                .unwrap_or_else(|_| unreachable!("default cost weights are valid"));
        // The setup was validated where it was made (finite bound, resolution, sensing).
        let _ = p.set_notify_latency(self.setup.notify);
        let (pos, speed) = self.setup.resolution;
        let _ = p.set_bus_resolution(pos, speed);
        let _ = p.set_sensing(self.setup.sensing);
        let _ = p.set_reuse(self.setup.reuse);
        p.set_invariant(self.setup.invariant);
        let _ = p.set_weakest_brake(self.setup.fleet.weakest_brake);
        LaneBrain::F64(Box::new(p))
    }

    /// The multi-lane planner in `f32`: planner-core's solver, the setup rounded.
    fn lane_planner32(&self, lane: u8, v_max: f64) -> LaneF32<N> {
        let mut p = LanePlanner::new(params32(v_max, self.body), CostWeights::default(), lane)
            .unwrap_or_else(|_| unreachable!("default cost weights are valid"));
        let _ = p.set_notify_latency(self.setup.notify as f32);
        let (pos, speed) = self.setup.resolution;
        let _ = p.set_bus_resolution(pos as f32, speed as f32);
        let _ = p.set_sensing(self.setup.sensing.map(sensing32));
        p.set_invariant(self.setup.invariant);
        let _ = p.set_weakest_brake(self.setup.fleet.weakest_brake as f32);
        LaneF32::new(p)
    }

    /// A crossing planner for vehicle `id` on `route` of `layout`.
    /// Its speed limit is `v_limit` ([`Network::route_limit`]).
    pub(super) fn crossing_planner(
        &self,
        (id, route): (u16, u8),
        layout: &Layout<f64>,
        v_limit: f64,
    ) -> CrossingBrain {
        if self.setup.precision == Precision::F32 {
            let w = CostWeights {
                target_position: 1e-3,
                ..CostWeights::default()
            };
            let planner = Planner::new(params32(v_limit, self.body), w)
                .unwrap_or_else(|_| unreachable!("the weights are valid"));
            let mut c = CrossingPlanner::new(planner, id, route, self.body.length as f32);
            let _ = c.set_notify_latency(self.setup.notify as f32);
            let (pos, speed) = self.setup.resolution;
            let _ = c.set_bus_resolution(pos as f32, speed as f32);
            let _ = c.set_sensing(self.setup.sensing.map(sensing32));
            c.set_invariant(self.setup.invariant);
            return CrossingBrain::F32(Box::new(CrossingF32::new(c, layout)));
        }
        let planner = Planner::new(params(v_limit, self.body), crossing_weights())
            .unwrap_or_else(|_| unreachable!("the weights are valid"));
        let mut c = CrossingPlanner::new(planner, id, route, self.body.length);
        let _ = c.set_notify_latency(self.setup.notify);
        let (pos, speed) = self.setup.resolution;
        let _ = c.set_bus_resolution(pos, speed);
        let _ = c.set_sensing(self.setup.sensing);
        c.set_invariant(self.setup.invariant);
        CrossingBrain::F64(Box::new(c))
    }
}

/// Where a vehicle is and who drives it, in one value: on a road any driver (its pose in
/// the segment's frame, its lane-change state ℓ, α, β); in a junction only its own
/// planners (its route and distance along the route's path). A scripted or random
/// driver in a junction cannot be written, so no step has to guess what it would do.
pub enum Role<const N: usize> {
    /// On a segment, in its frame.
    Road {
        /// Segment index.
        seg: usize,
        /// x (m).
        x: f64,
        /// y (m).
        y: f64,
        /// Heading relative to the segment (rad).
        theta: f64,
        /// ℓ.
        lane: u8,
        /// α.
        alpha: Option<u8>,
        /// β.
        beta: Option<u8>,
        /// Who drives it.
        driver: Driver<N>,
    },
    /// In a junction, along a route's path, driven by its planners.
    Junction {
        /// Junction index.
        junction: usize,
        /// Route.
        route: u8,
        /// Centre's distance along the route's path (m).
        s: f64,
        /// Its planners.
        brain: Box<Brain<N>>,
    },
}

impl<const N: usize> Role<N> {
    /// Its planners at `at` (planners drive anywhere).
    pub fn planner(at: At, brain: Box<Brain<N>>) -> Self {
        match Self::new(at, Driver::Planner(brain)) {
            Some(r) => r,
            // `new` refuses only drivers other than planners in a junction.
            None => unreachable!("a planner may be in a junction"),
        }
    }

    /// `driver` at `at`, or `None` for a driver other than its planners in a junction.
    pub fn new(at: At, driver: Driver<N>) -> Option<Self> {
        Some(match (at, driver) {
            (
                At::Lane {
                    seg,
                    x,
                    y,
                    theta,
                    lane,
                    alpha,
                    beta,
                },
                driver,
            ) => Role::Road {
                seg,
                x,
                y,
                theta,
                lane,
                alpha,
                beta,
                driver,
            },
            (At::Crossing { junction, route, s }, Driver::Planner(brain)) => Role::Junction {
                junction,
                route,
                s,
                brain,
            },
            (At::Crossing { .. }, _) => return None,
        })
    }

    /// Its lane-change state after a multi-lane step (ℓ, α, β); nothing in a junction.
    pub fn set_lane_state(&mut self, l: u8, a: Option<u8>, b: Option<u8>) {
        if let Role::Road {
            lane, alpha, beta, ..
        } = self
        {
            (*lane, *alpha, *beta) = (l, a, b);
        }
    }

    /// Where it is (a copy, for monitors, sensors and messages).
    pub fn at(&self) -> At {
        match *self {
            Role::Road {
                seg,
                x,
                y,
                theta,
                lane,
                alpha,
                beta,
                ..
            } => At::Lane {
                seg,
                x,
                y,
                theta,
                lane,
                alpha,
                beta,
            },
            Role::Junction {
                junction, route, s, ..
            } => At::Crossing { junction, route, s },
        }
    }

    /// Its planners, if it has any.
    pub fn brain(&self) -> Option<&Brain<N>> {
        match self {
            Role::Road {
                driver: Driver::Planner(b),
                ..
            }
            | Role::Junction { brain: b, .. } => Some(b),
            Role::Road { .. } => None,
        }
    }

    /// Its planners, if it has any, to step or to rebuild.
    pub fn brain_mut(&mut self) -> Option<&mut Brain<N>> {
        match self {
            Role::Road {
                driver: Driver::Planner(b),
                ..
            }
            | Role::Junction { brain: b, .. } => Some(b),
            Role::Road { .. } => None,
        }
    }

    /// Nothing: a script with no phases, at the origin of segment 0, which holds the place
    /// while a driver moves between variants (no allocation).
    fn parked() -> Self {
        Role::Road {
            seg: 0,
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            lane: 0,
            alpha: None,
            beta: None,
            driver: Driver::Script(Vec::new()),
        }
    }

    /// Into junction `junction` on `route` at `s`, its planners with it; `false` (and
    /// nothing changed) unless it is a planner on a road.
    pub fn enter_junction(&mut self, junction: usize, route: u8, s: f64) -> bool {
        match core::mem::replace(self, Self::parked()) {
            Role::Road {
                driver: Driver::Planner(brain),
                ..
            } => {
                *self = Role::Junction {
                    junction,
                    route,
                    s,
                    brain,
                };
                true
            }
            other => {
                *self = other;
                false
            }
        }
    }

    /// Onto segment `seg` at `(x, y)` in `lane`, straight, its driver with it.
    pub fn enter_segment(&mut self, seg: usize, (x, y): (f64, f64), lane: u8) {
        let driver = match core::mem::replace(self, Self::parked()) {
            Role::Road { driver, .. } => driver,
            Role::Junction { brain, .. } => Driver::Planner(brain),
        };
        *self = Role::Road {
            seg,
            x,
            y,
            theta: 0.0,
            lane,
            alpha: None,
            beta: None,
            driver,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup() -> PlannerSetup {
        PlannerSetup {
            solver: SolverChoice::Ours,
            notify: 0.1,
            resolution: (0.0, 0.0),
            sensing: None,
            reuse: None,
            precision: Precision::F64,
            relevant_m: 200.0,
            invariant: planner_core::Invariant::Paper,
            fleet: Fleet::default(),
        }
    }

    const ROAD: At = At::Lane {
        seg: 2,
        x: 10.0,
        y: 5.4,
        theta: 0.01,
        lane: 1,
        alpha: Some(0),
        beta: None,
    };
    const JUNCTION: At = At::Crossing {
        junction: 1,
        route: 3,
        s: 4.0,
    };

    #[test]
    fn only_planners_are_in_junctions() {
        let brain = || Box::new(Brain::<20>::new(7, setup(), Body::CAR));
        assert!(Role::new(JUNCTION, Driver::<20>::Script(Vec::new())).is_none());
        assert!(Role::new(JUNCTION, Driver::Planner(brain())).is_some());
        for at in [ROAD, JUNCTION] {
            assert_eq!(Role::planner(at, brain()).at(), at);
        }
        let script = Role::new(ROAD, Driver::<20>::Script(Vec::new()));
        let mut script = script.expect("any driver drives on a road");
        assert!(script.brain().is_none());
        assert!(!script.enter_junction(1, 3, 4.0), "a script never crosses");
        assert_eq!(script.at(), ROAD, "and a refused hand-over moves nothing");
    }

    #[test]
    fn the_brain_goes_where_the_vehicle_goes() {
        let mut r = Role::planner(ROAD, Box::new(Brain::<20>::new(7, setup(), Body::CAR)));
        assert!(r.enter_junction(1, 3, 4.0));
        assert_eq!(r.at(), JUNCTION);
        assert!(r.brain().is_some());
        r.enter_segment(5, (2.0, 1.8), 0);
        assert!(r.brain().is_some(), "its planners came back onto the road");
        let At::Lane {
            seg,
            x,
            lane,
            alpha,
            ..
        } = r.at()
        else {
            panic!("on a road")
        };
        assert_eq!((seg, x, lane, alpha), (5, 2.0, 0, None));
        r.set_lane_state(1, Some(0), Some(1));
        assert!(matches!(
            r.at(),
            At::Lane {
                lane: 1,
                alpha: Some(0),
                beta: Some(1),
                ..
            }
        ));
    }
}
