//! One world of roads and intersections (SPEC §10): the network, its vehicles, and its
//! junctions' managers, stepped by one loop. A straight road is a network of one
//! segment; the Fig. 8 intersection is one junction with its own inlet and outlet
//! tracks; a corridor or a grid joins junctions by segments. Every vehicle is its own
//! planner-core instance that knows the others only from what the bus delivers.
//!
//! One period h at time t, data flowing one way:
//!
//! ```text
//! 1. every vehicle broadcasts (a state on a segment, a crossing report at a junction;
//!    a vehicle that has left a junction repeats Left for a while)
//! 2. every junction's manager hears the reports, decides, and broadcasts its leases
//! 3. every vehicle's sensors return what they see (when the world has sensors)
//! 4. every vehicle's period (`Vehicle::period`, which a fleet's tasks run too): it
//!    hears what the bus delivered → its view → its planner → command; it moves (the
//!    exact unicycle (1) on a segment, along the path at a junction); it takes its place
//!    after the move (hand-overs between segments and junctions)
//! 5. departures are said and the departed leave; arrivals enter
//! 6. the monitors judge the ground truth: safety, then liveness
//! ```

pub mod at;
pub mod cost;
pub mod driver;
pub mod handover;
pub mod heard;
pub mod junction;
pub mod network;
pub mod period;
pub mod plausible;
pub mod precision;
pub mod reroute;
pub mod sensor;
pub mod spawn;
pub mod step;
pub mod summary;
pub mod vehicle;
pub mod wait;
pub mod watch;

use crate::bus::{Bus, Faults, InProcessBus};
use crate::monitor::liveness::{Deadlock, DeadlockDetector};
use crate::monitor::Limits;
use crate::reference::ClarabelSolver;
use junction::ManagerNode;
use network::{Network, Place};
use planner_core::reuse::Duals;
use planner_core::{
    IpmSolver, MpcSolver, ReusePolicy, Sensing, SingleLaneProblem, Solution, SolveError,
};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use spawn::Stream;
use vehicle::{Counters, PlannerSetup, Vehicle};

/// How a vehicle is driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum DriverKind {
    /// Its own planner-core instance.
    #[default]
    Planner,
    /// A fixed acceleration script (an adversarial but admissible driver).
    Script,
    /// Random admissible accelerations, seeded from the scenario seed and the id.
    Random,
}

/// One phase of a scripted driver: hold `accel` until `until_s`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Phase {
    /// End of the phase (s).
    pub until_s: f64,
    /// Acceleration (m/s²), within [amin, amax].
    pub accel: f64,
}

/// Vehicle length L (Table I).
pub const LENGTH_M: f64 = 4.5;
/// Vehicle width W (Table I).
pub const WIDTH_M: f64 = 1.7;
/// Lane width Wl (Table I).
pub const LANE_WIDTH_M: f64 = 3.6;
/// Extra room scenario starts need over the invariant: the f32 planner margin (2 cm)
/// plus 1 cm, so that planners of either precision start with (10) feasible.
pub const START_MARGIN_M: f64 = 0.03;

/// What a vehicle is doing (the trace's `mode` column).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Driving on its verified plan (or its script).
    Cruise,
    /// Changing lanes.
    LaneChange,
    /// Yielding to a vehicle that wants its lane.
    Yield,
    /// The certified max-braking fallback (solver failure, failed verification, or the
    /// invariant not holding).
    Fallback,
    /// Stopped with no room to move (behind a stopped vehicle, at a road end or a line).
    Waiting,
    /// Crossing a junction on its verified plan.
    Crossing,
    /// Its liveness goal is reached.
    Done,
}

impl Mode {
    /// Driving on a verified plan: changing lanes or not.
    pub fn moving(changing: bool) -> Self {
        if changing {
            Self::LaneChange
        } else {
            Self::Cruise
        }
    }

    /// The name used in traces.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Cruise => "cruise",
            Self::LaneChange => "lane_change",
            Self::Yield => "yield",
            Self::Fallback => "fallback",
            Self::Waiting => "waiting",
            Self::Crossing => "crossing",
            Self::Done => "done",
        }
    }
}

/// Which solver the multi-lane planners use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SolverChoice {
    /// planner-core's solver with its defaults: the active-set step on warm starts, the
    /// interior-point method behind it.
    Ours,
    /// planner-core's solver as it was before its active-set step: the interior-point method alone
    /// ([`planner_core::Settings::interior_point_only`]), for side-by-side benchmarks.
    OursInteriorPoint,
    /// Clarabel (the reference), for comparing plans.
    Clarabel,
}

/// Either solver behind one type, so that a planner can be built with either.
#[derive(Debug, Clone)]
pub enum AnySolver<const N: usize> {
    /// Ours.
    Ours(IpmSolver<f64, N>),
    /// Clarabel.
    Clarabel(ClarabelSolver),
}

impl<const N: usize> MpcSolver<f64, N> for AnySolver<N> {
    fn solve(
        &mut self,
        problem: &SingleLaneProblem<f64, N>,
        warm: Option<&[f64; N]>,
    ) -> Result<Solution<f64, N>, SolveError> {
        match self {
            Self::Ours(s) => s.solve(problem, warm),
            Self::Clarabel(s) => MpcSolver::<f64, N>::solve(s, problem, warm),
        }
    }

    fn duals(&self) -> Option<Duals<f64, N>> {
        match self {
            Self::Ours(s) => s.duals(),
            // Clarabel's duals are not kept: its planners solve every step.
            Self::Clarabel(_) => None,
        }
    }

    fn advance(&mut self) {
        if let Self::Ours(s) = self {
            s.advance();
        }
    }
}

/// The invariant a scenario file that names none, and every command without
/// `--invariant`, keeps toward the vehicle ahead: the leader-aware one (docs/spec.md §11),
/// made the default once every sweep was clean with it (docs/capacity.md). The paper's
/// stays selectable (`invariant = "paper"`, `--invariant paper`), and reproduces every
/// figure of the paper. planner-core's own default stays the paper's: a planner linked
/// alone keeps the invariant that needs nothing of its leader.
pub const DEFAULT_INVARIANT: planner_core::Invariant = planner_core::Invariant::LeaderAware;

/// [`DEFAULT_INVARIANT`]'s name, as the command line's flags default to it.
pub const DEFAULT_INVARIANT_NAME: &str = "leader-aware";

/// The name of an invariant in scenario files, reports, traces and on the command line.
pub fn invariant_name(i: planner_core::Invariant) -> &'static str {
    match i {
        planner_core::Invariant::LeaderAware => "leader-aware",
        _ => "paper",
    }
}

/// The invariant named `name` ("paper" or "leader-aware").
pub fn invariant_named(name: &str) -> Result<planner_core::Invariant, String> {
    match name {
        "paper" => Ok(planner_core::Invariant::Paper),
        "leader-aware" => Ok(planner_core::Invariant::LeaderAware),
        _ => Err(format!(
            "invariant must be \"paper\" or \"leader-aware\", got {name:?}"
        )),
    }
}

/// An invariant in JSON, by its name (`#[serde(with = "crate::world::invariant_serde")]`);
/// settings written before it existed read as the paper's (`#[serde(default)]` on a
/// field of type [`planner_core::Invariant`], whose default is the paper's).
pub mod invariant_serde {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Writes the invariant's name.
    pub fn serialize<S: Serializer>(i: &planner_core::Invariant, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(super::invariant_name(*i))
    }

    /// Reads an invariant's name.
    pub fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<planner_core::Invariant, D::Error> {
        let name = String::deserialize(d)?;
        super::invariant_named(&name).map_err(serde::de::Error::custom)
    }
}

/// One row of the trace: the state at `t` and the command for [t, t+h).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceRow {
    /// Time (s).
    pub t: f64,
    /// Vehicle id.
    pub id: u16,
    /// Centre x in the world (m).
    pub x: f64,
    /// Centre y in the world (m).
    pub y: f64,
    /// Heading in the world (rad; 0 = east, counter-clockwise).
    pub theta: f64,
    /// Speed commanded for [t, t+h) (m/s).
    pub v: f64,
    /// Yaw rate commanded for [t, t+h) (rad/s).
    pub omega: f64,
    /// Lane (on a segment: 0 = rightmost; at a junction: its inlet lane, 0 = inner).
    pub lane: u8,
    /// Target lane.
    pub target_lane: u8,
    /// Mode.
    pub mode: Mode,
    /// Where it is.
    pub place: Place,
    /// At a junction: whether it holds its manager's permission (the trace file leaves
    /// this out; the viewer shows it).
    pub granted: Option<bool>,
    /// Its length (m).
    pub length: f64,
    /// Its width (m).
    pub width: f64,
    /// Its braking limit |amin| (m/s²).
    pub brake: f64,
    /// The invariant it keeps toward a cooperating vehicle ahead; `None` for a driver
    /// that keeps none (scripted or random: its followers never credit it, and nothing
    /// judges its own gaps).
    pub invariant: Option<planner_core::Invariant>,
}

/// Everything a world is made of, validated (a scenario file loads into one).
#[derive(Debug, Clone)]
pub struct WorldSpec {
    /// Name.
    pub name: String,
    /// Simulated time (s).
    pub duration_s: f64,
    /// Seed (random drivers, faults, sensor noise, spawns).
    pub seed: u64,
    /// MPC horizon N of the multi-lane planners (20 or 50).
    pub horizon: usize,
    /// Goals on roads must be reached by this time (s).
    pub deadline_s: f64,
    /// The network.
    pub network: Network,
    /// The vehicles at t = 0.
    pub vehicles: Vec<VehicleSpec>,
    /// Faults the bus injects.
    pub faults: Faults,
    /// Onboard sensors of every planner-driven vehicle (none: the paper's V2V world).
    pub sensing: Option<Sensing<f64>>,
    /// Arrivals while the world runs.
    pub arrivals: Arrivals,
    /// No vehicle moving for this long while some have goals is a deadlock (s).
    pub deadlock_window_s: f64,
    /// When the run ends before its duration.
    pub finish: Finish,
    /// What every node's clock reads when the run begins ([`crate::bus::Clock`]; `host-sim
    /// run --clock-start`): the epoch unless an uptime is to be tried.
    pub clock_start: planner_core::Instant,
    /// The precision of every planner, manager and codec ([`precision`]; `host-sim run
    /// --precision`).
    pub precision: precision::Precision,
    /// The invariant every planner keeps toward the vehicle ahead (scenario key
    /// `invariant`, `--invariant`): the paper's wall unless asked.
    pub invariant: planner_core::Invariant,
}

/// When a run ends before its duration (besides a deadlock, which always ends it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Finish {
    /// At its duration (or when a junction world is empty).
    Duration,
    /// As soon as every vehicle has met its goals and nothing moves (a sweep's case: every
    /// vehicle in its lane and stopped at the road end).
    GoalsMetAndStill,
}

/// A vehicle's body: what makes a truck other than a car to the planners, the monitors
/// and the bus. Its length and braking limit travel in its state messages
/// ([`planner_core::BodyLength`], [`planner_core::BrakeLimit`]); width, acceleration
/// and speed limits are Table I's for every vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    /// Length L (m).
    pub length: f64,
    /// Braking limit |amin| (m/s²).
    pub brake: f64,
}

impl Body {
    /// Table I's car: 4.5 m, 7.9 m/s².
    pub const CAR: Self = Self {
        length: LENGTH_M,
        brake: 7.9,
    };
    /// An articulated truck: 16.5 m (the EU's longest), 4.5 m/s².
    pub const TRUCK: Self = Self {
        length: 16.5,
        brake: 4.5,
    };
}

impl Default for Body {
    fn default() -> Self {
        Self::CAR
    }
}

/// What every planner of a world assumes of the vehicles it cannot measure: the longest
/// vehicle and the weakest braking limit among them (the paper's vehicles are all
/// alike: Table I's car). A vehicle that declares no length is taken at the longest;
/// a vehicle behind that declares no limit, at the weakest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fleet {
    /// The longest vehicle (m).
    pub longest_m: f64,
    /// The weakest braking limit (m/s²).
    pub weakest_brake: f64,
}

impl Fleet {
    /// The fleet of `bodies` (and of cars, which arrivals bring).
    pub fn of(bodies: impl IntoIterator<Item = Body>) -> Self {
        bodies.into_iter().fold(Self::default(), |f, b| Self {
            longest_m: f.longest_m.max(b.length),
            weakest_brake: f.weakest_brake.min(b.brake),
        })
    }

    /// The fleet of the vehicles at t = 0 (`bodies`) and of arrivals of which
    /// `trucks_percent` are trucks: a truck's body if any may arrive. The one rule
    /// [`WorldSpec::fleet`], the scenario loaders and the SUMO export share.
    pub fn with_arrivals(bodies: impl IntoIterator<Item = Body>, trucks_percent: u8) -> Self {
        Self::of(bodies.into_iter().chain(arriving_truck(trucks_percent)))
    }
}

/// The truck's body if arrivals of which `trucks_percent` are trucks may bring one.
pub fn arriving_truck(trucks_percent: u8) -> Option<Body> {
    (trucks_percent > 0).then_some(Body::TRUCK)
}

impl Default for Fleet {
    /// Cars alone.
    fn default() -> Self {
        Self {
            longest_m: Body::CAR.length,
            weakest_brake: Body::CAR.brake,
        }
    }
}

/// A vehicle at t = 0.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleSpec {
    /// Id.
    pub id: u16,
    /// Where it starts.
    pub at: at::At,
    /// Initial speed (m/s).
    pub v: f64,
    /// How it is driven: on a road, as this says; a vehicle that starts in a junction is
    /// driven by its own planners whatever this says (only planners cross junctions,
    /// [`driver::Role`]).
    pub driver: DriverKind,
    /// Its script, for a scripted driver.
    pub script: Vec<Phase>,
    /// Its trip.
    pub trip: vehicle::Trip,
    /// It says over V2V that it cooperates (keeps the protocols: yields, keeps its
    /// intentions). Others assume one that does not may accelerate at amax and never
    /// yield.
    pub cooperative: bool,
    /// Its body (a car unless the scenario says otherwise).
    pub body: Body,
}

/// Vehicles entering while the world runs.
#[derive(Debug, Clone, PartialEq)]
pub enum Arrivals {
    /// None.
    None,
    /// A closed system (Fig. 9): a vehicle leaving the world comes back at the start of a
    /// junction's inlet with a random route.
    Closed,
    /// Open: arrivals at each entry at its rate, each with a trip drawn at random.
    Poisson(Poisson),
}

/// Open arrivals: Poisson processes, one per entry.
#[derive(Debug, Clone, PartialEq)]
pub struct Poisson {
    /// Each entry and its rate (veh/h).
    pub entries: Vec<(spawn::Entry, f64)>,
    /// Percent of the arrivals that are trucks ([`Body::TRUCK`]), each drawn at random.
    pub trucks_percent: u8,
}

impl Poisson {
    /// Cars arriving at `entries`.
    pub fn cars(entries: Vec<(spawn::Entry, f64)>) -> Self {
        Self {
            entries,
            trucks_percent: 0,
        }
    }
}

impl WorldSpec {
    /// The fleet the world's planners expect: its vehicles' bodies, and a truck's if
    /// arrivals may bring one.
    pub fn fleet(&self) -> Fleet {
        Fleet::with_arrivals(self.vehicles.iter().map(|v| v.body), self.trucks_percent())
    }

    /// Percent of the arrivals that are trucks (0 without open arrivals).
    pub fn trucks_percent(&self) -> u8 {
        match &self.arrivals {
            Arrivals::Poisson(p) => p.trucks_percent,
            _ => 0,
        }
    }
}

/// A running world with multi-lane horizon `N` over bus `B`, in SUMO's parts: the
/// network, the vehicles, insertion, the junctions' managers, the bus, and the watch
/// (monitor and deadlock detector); [`World::step`] runs the phases over them in order.
pub struct World<const N: usize, B: Bus = InProcessBus> {
    spec: WorldSpec,
    net: Network,
    vehicles: Vec<Vehicle<N>>,
    /// Vehicles that left the world (their logs count in the summary).
    gone: Vec<Vehicle<N>>,
    managers: Vec<ManagerNode>,
    bus: B,
    lim: Limits,
    setup: PlannerSetup,
    solver: SolverChoice,
    seed: u64,
    time: Time,
    insertion: Insertion,
    watch: Watch,
    tally: Tally,
    draws: Draws,
}

/// Where a run is in time.
struct Time {
    /// Every node's clock.
    clock: crate::bus::Clock,
    /// Simulated time (s).
    t: f64,
    /// Periods done.
    steps_done: u64,
    /// Periods in the run's duration.
    total_steps: u64,
}

/// Vehicles coming and going: arrivals, a closed system's returns, departures still
/// announcing, and the ids new vehicles take.
struct Insertion {
    /// Vehicles that left a junction or the world and repeat `Left`: (id, junction,
    /// when, until when).
    departing: Vec<(u16, Option<usize>, f64, f64)>,
    /// Closed system: (id, route) waiting to come back.
    pending: Vec<(u16, u8)>,
    /// Open system: one arrival stream per entry.
    streams: Vec<Stream>,
    /// Ids for new vehicles.
    ids: spawn::Ids,
}

/// What watches the run from outside the vehicles: the independent monitor and the
/// deadlock detector.
struct Watch {
    monitor: watch::WorldMonitor,
    detector: DeadlockDetector,
    deadlock: Option<Deadlock>,
}

/// What the run counts.
struct Tally {
    counters: Counters,
    /// Wall-clock time of each planner step, when asked for (`host-sim scale`): the
    /// other runs do not read the clock in their steps.
    costs: Option<Box<cost::StepCosts>>,
    messages_sent: u64,
}

/// Mixed into a run's seed for the draws of which arrivals are trucks.
const BODIES_SEED: u64 = 0x07b0_d1e5;

/// The world's random streams, each its own so that one kind of draw does not move
/// another's.
struct Draws {
    /// Sensor noise, arrivals, trips, a closed system's routes.
    rng: Box<ChaCha8Rng>,
    /// The roadside sensors' noise.
    roadside: Box<ChaCha8Rng>,
    /// Which arrivals are trucks.
    bodies: Box<ChaCha8Rng>,
}

impl<const N: usize> World<N, InProcessBus> {
    /// A world of `spec` on the in-process bus (injecting the spec's faults).
    pub fn new(spec: WorldSpec, solver: SolverChoice, seed: Option<u64>) -> Self {
        let lim = Limits::table_i();
        let seed = seed.unwrap_or(spec.seed);
        let mut nodes: Vec<u16> = spec.vehicles.iter().map(|v| v.id).collect();
        nodes.extend((0..spec.network.junctions.len()).map(junction::manager_node));
        let mut bus = InProcessBus::with_faults(&nodes, spec.faults, seed, lim.h);
        // A radio that reaches every vehicle that can matter before a message from it
        // can arrive ([`InProcessBus::set_range`]).
        let relevant = heard::relevance_radius(&spec.network, lim.v_max, spec.fleet());
        let notify = spec.faults.notify_bound(lim.h);
        bus.set_range(Some(relevant + 2.0 * lim.v_max * (notify + lim.h)));
        Self::with_bus(spec, solver, Some(seed), bus)
    }
}

impl<const N: usize, B: Bus> World<N, B> {
    /// A world of `spec` over `bus` (every vehicle and manager node attached).
    pub fn with_bus(spec: WorldSpec, solver: SolverChoice, seed: Option<u64>, bus: B) -> Self {
        let lim = Limits::table_i();
        let seed = seed.unwrap_or(spec.seed);
        let fleet = spec.fleet();
        let setup = PlannerSetup {
            solver,
            notify: spec.faults.notify_bound(lim.h),
            resolution: (0.0, 0.0),
            sensing: spec.sensing,
            reuse: None,
            precision: spec.precision,
            relevant_m: heard::relevance_radius(&spec.network, lim.v_max, fleet),
            invariant: spec.invariant,
            fleet,
        };
        let net = spec.network.clone();
        let vehicles = spec
            .vehicles
            .iter()
            .map(|v| vehicle::build_vehicle::<N>(v, setup, seed, &net))
            .collect();
        let managers = net
            .junctions
            .iter()
            .enumerate()
            .map(|(j, jn)| {
                let lease = junction::lease(setup.notify, lim.h);
                let mut m = ManagerNode::new(j, jn, (lease, setup.precision));
                // A world with sensors has them at its junctions too.
                let _ = m.set_roadside(spec.sensing.map(|s| s.position_error_m));
                m
            })
            .collect();
        let mut bus = bus;
        for (j, jn) in net.junctions.iter().enumerate() {
            bus.locate(junction::manager_node(j), jn.centre.0, jn.centre.1);
        }
        let mut rng = Box::new(crate::reference::instances::rng(seed ^ 0x1c));
        let streams = match &spec.arrivals {
            Arrivals::Poisson(p) => p
                .entries
                .iter()
                .map(|&(e, rate)| Stream::new(e, (rate, p.trucks_percent), &mut rng))
                .collect(),
            _ => Vec::new(),
        };
        let ids = spawn::Ids::from(
            spec.vehicles
                .iter()
                .map(|v| v.id)
                .max()
                .unwrap_or(0)
                .wrapping_add(1),
        );
        let clock = crate::bus::Clock::new(spec.clock_start, lim.h);
        Self {
            time: Time {
                clock,
                t: 0.0,
                steps_done: 0,
                total_steps: (spec.duration_s / lim.h).round() as u64,
            },
            watch: Watch {
                monitor: watch::WorldMonitor::new(&net),
                detector: DeadlockDetector::new(spec.deadlock_window_s),
                deadlock: None,
            },
            insertion: Insertion {
                departing: Vec::new(),
                pending: Vec::new(),
                streams,
                ids,
            },
            draws: Draws {
                rng,
                roadside: Box::new(crate::reference::instances::rng(
                    seed ^ sensor::ROADSIDE_SEED,
                )),
                bodies: Box::new(crate::reference::instances::rng(seed ^ BODIES_SEED)),
            },
            tally: Tally {
                counters: Counters::default(),
                costs: None,
                messages_sent: 0,
            },
            spec,
            net,
            vehicles,
            gone: Vec::new(),
            managers,
            bus,
            lim,
            setup,
            solver,
            seed,
        }
    }

    /// Lets every multi-lane planner built from now on reuse its certified previous plan
    /// instead of solving (`None`: solve every step, the default).
    pub fn set_reuse(&mut self, policy: Option<ReusePolicy<f64>>) {
        self.setup.reuse = policy;
        self.give_setup();
    }

    /// Makes the firmware image of `spec` the computer of each of its vehicles (each in
    /// its own QEMU, its defmt log into `logs`): they plan on their roads from then on.
    /// Fails, changing nothing, if one cannot be started.
    pub fn attach_firmware(
        &mut self,
        spec: &crate::firmware::FirmwareSpec,
        logs: &std::path::Path,
    ) -> Result<(), crate::firmware::FirmwareError> {
        let mut started = Vec::new();
        for &id in &spec.vehicles {
            let log = logs.join(format!("firmware-{id}.defmt"));
            started.push((
                id,
                crate::firmware::Computer::start(&spec.elf, spec.board, id, &log)?,
            ));
        }
        for (id, c) in started {
            if let Some(v) = self.vehicles.iter_mut().find(|v| v.id == id) {
                v.set_computer(c);
            }
        }
        Ok(())
    }

    /// Ends every computer in the loop (a last period, the tick marked last) and reports
    /// how each ended.
    pub fn finish_firmware(&mut self) -> Vec<crate::firmware::FirmwareReport> {
        let now = self.time.clock.at_step(self.time.steps_done);
        let mut reports = Vec::new();
        for v in &mut self.vehicles {
            let ego = v.road_limits(&self.net).and_then(|r| v.ego(now, r));
            if let (Some(c), Some(ego)) = (v.take_computer(), ego) {
                reports.push(c.finish(&ego));
            }
        }
        reports
    }

    /// Gives every vehicle's brain the world's planner setup (for planners built from
    /// now on).
    fn give_setup(&mut self) {
        for v in &mut self.vehicles {
            vehicle::set_setup(v, self.setup);
        }
    }

    /// Tells the planners and managers the steps to which the bus rounds positions and
    /// speeds (a CAN bus: [`crate::fleet::can::RESOLUTION`]).
    pub fn set_bus_resolution(&mut self, resolution: (f64, f64)) -> Result<(), String> {
        let ok = |r: f64| r.is_finite() && (0.0..1.0).contains(&r);
        if !(ok(resolution.0) && ok(resolution.1)) {
            return Err(format!("bus resolution {resolution:?}"));
        }
        self.setup.resolution = resolution;
        self.give_setup();
        for m in &mut self.managers {
            m.set_resolution(resolution).map_err(|e| format!("{e:?}"))?;
        }
        Ok(())
    }

    /// The network.
    pub fn network(&self) -> &Network {
        &self.net
    }

    /// Current time (s).
    pub fn time(&self) -> f64 {
        self.time.t
    }

    /// Steps in the whole run.
    pub fn total_steps(&self) -> u64 {
        self.time.total_steps
    }

    /// Steps done.
    pub fn steps_done(&self) -> u64 {
        self.time.steps_done
    }

    /// The vehicles in the world now.
    pub fn vehicles(&self) -> &[Vehicle<N>] {
        &self.vehicles
    }

    /// `true` once the run is over: its duration simulated, a deadlock found, or — when
    /// asked to stop then — every goal met.
    pub fn finished(&self) -> bool {
        self.time.steps_done >= self.time.total_steps
            || self.watch.deadlock.is_some()
            || (self.spec.finish == Finish::GoalsMetAndStill
                && self.all_done()
                && self
                    .vehicles
                    .iter()
                    .all(|v| v.v <= crate::monitor::liveness::MOVING_MPS))
            || (self.vehicles.is_empty()
                && self.insertion.pending.is_empty()
                && self.insertion.streams.is_empty()
                && !self.net.junctions.is_empty())
    }

    /// The junctions' managers.
    pub fn managers(&self) -> &[ManagerNode] {
        &self.managers
    }

    /// The deadlock found, if any.
    pub fn deadlock(&self) -> Option<&Deadlock> {
        self.watch.deadlock.as_ref()
    }

    /// The longest queue waiting outside one entry so far, and the longest now.
    pub fn queues(&self) -> (usize, usize) {
        (
            self.insertion
                .streams
                .iter()
                .map(|s| s.max_queue)
                .max()
                .unwrap_or(0),
            self.insertion
                .streams
                .iter()
                .map(|s| s.queue.len())
                .max()
                .unwrap_or(0),
        )
    }

    /// When each open arrival still waiting outside arrived (s).
    pub fn waiting_since(&self) -> Vec<f64> {
        self.insertion
            .streams
            .iter()
            .flat_map(|s| s.queue.iter().map(|a| a.since))
            .collect()
    }

    /// Every (non-scripted) vehicle has met its goals.
    pub fn all_done(&self) -> bool {
        self.vehicles.iter().all(|v| !v.unmet(&self.net))
            && self.insertion.pending.is_empty()
            && self.insertion.streams.iter().all(|s| s.queue.is_empty())
    }
}
