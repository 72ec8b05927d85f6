//! A world as a fleet on a CAN medium: every vehicle's planners run in a task of their own
//! (a thread with its own CAN node), and so does every junction's manager (its node at its
//! own source address, 0xF1 + its index); they hear each other only through can-gateway
//! frames on that medium — a SocketCAN interface such as `vcan0`, or the in-process
//! frame [`Hub`]. It differs from the in-process world only in the medium: the vehicles,
//! managers, monitors and summary are the world's own.
//!
//! Time is kept by a time master on the bus, in the manner of CANopen SYNC. Per period k
//! (time kh):
//!
//! 1. every vehicle publishes its message for kh (its state on a segment, its crossing
//!    request at a junction; and, for a while after leaving a junction, its exit), then
//!    reports its true state to the harness, which runs the monitors — ground truth never
//!    reaches a planner;
//! 2. with junctions, the master sends SYNC(2k): each manager takes what preceded it,
//!    decides, publishes its grants and tells the harness;
//! 3. the harness hands each vehicle its sensor returns (computed from ground truth, as
//!    in the in-process world), and the master sends SYNC(2k + 1) (without junctions,
//!    SYNC(k)): each vehicle takes what preceded it, plans, and moves one period.
//!
//! The run is lock-step and as repeatable as the in-process one (each period's messages
//! are taken in the in-process bus's order, whatever order the tasks' frames interleaved
//! in); what differs is that every message went through the codec (0.01 m, 0.02 m/s),
//! which the planners and managers allow for, and the kernel's CAN stack. The kernel's
//! receive time stamps measure the latency from publication to reception.

pub mod can;
pub mod intruder;
pub mod ledger;
pub mod throughput;

use crate::bus::{Clock, Faults, Message, Received};
use crate::monitor::liveness::DeadlockDetector;
use crate::monitor::Limits;
use crate::world::handover::Moved;
use crate::world::junction::ManagerNode;
use crate::world::network::Network;
use crate::world::sensor::{sense_each, Seen, Sensed};
use crate::world::summary::{summarize, Outcome, Summary};
use crate::world::vehicle::build_vehicle;
use crate::world::vehicle::{Counters, PlannerSetup, StepCtx, Vehicle, VehicleTruth};
use crate::world::watch::WorldMonitor;
use crate::world::{SolverChoice, TraceRow, WorldSpec};
use can::{CanError, CanNode, CanPort, CanStats, Hub, Keys, Polled, SocketCanPort, WireMap};
use can_gateway::wire::{self, CLOCK_ADDRESS};
use intruder::{Attack, Intruder, INTRUDER_ADDRESS};
use ledger::Ledger;
use serde::Serialize;
use std::fmt;
use std::io;
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

/// How long a task waits for the next SYNC, and the master for a report, before the run
/// fails: far above a period's work even under full-system emulation.
pub const TIMEOUT: Duration = Duration::from_secs(60);

/// Where the fleet's frames travel.
#[derive(Debug, Clone)]
pub enum Medium {
    /// A SocketCAN interface (e.g. `vcan0`).
    SocketCan(String),
    /// The in-process frame hub.
    Hub,
}

impl fmt::Display for Medium {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::SocketCan(i) => write!(f, "socketcan:{i}"),
            Self::Hub => write!(f, "can-hub"),
        }
    }
}

/// A node of the fleet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Node {
    /// The time master.
    Clock,
    /// Vehicle id.
    Vehicle(u16),
    /// Junction (index)'s manager.
    Manager(usize),
    /// The attack experiment's intruder ([`intruder`]).
    Intruder,
}

/// Latency percentiles (µs) from publication to reception, by receive time stamps.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Latency {
    /// Messages measured.
    pub count: u64,
    /// Median (µs).
    pub p50_us: f64,
    /// 99th percentile (µs).
    pub p99_us: f64,
    /// Largest (µs).
    pub max_us: f64,
}

impl Latency {
    /// Percentiles of `v` (µs).
    pub fn of(mut v: Vec<f64>) -> Self {
        if v.is_empty() {
            return Self::default();
        }
        v.sort_by(f64::total_cmp);
        let at = |q: f64| {
            let i = ((v.len() - 1) as f64 * q).round() as usize;
            v.get(i).copied().unwrap_or(0.0)
        };
        Self {
            count: v.len() as u64,
            p50_us: at(0.5),
            p99_us: at(0.99),
            max_us: v.last().copied().unwrap_or(0.0),
        }
    }
}

/// Messages of a fleet run, by kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Messages {
    /// Vehicles' states.
    pub states: u64,
    /// Vehicles' crossing requests.
    pub requests: u64,
    /// Managers' grants.
    pub grants: u64,
    /// Vehicles' exits.
    pub exits: u64,
}

/// What a fleet run produced (the `--json` summary of `run --bus`).
#[derive(Debug, Clone, Serialize)]
pub struct FleetSummary {
    /// The run, as the in-process world reports it.
    #[serde(flatten)]
    pub run: Summary,
    /// The medium (`socketcan:vcan0`, `can-hub`).
    pub medium: String,
    /// Tasks: one per vehicle and per junction manager.
    pub tasks: usize,
    /// Junction managers (each its own node, at 0xF1 + its index).
    pub managers: usize,
    /// Periods run (0 to the last, inclusive).
    pub periods: u64,
    /// SYNC ticks sent.
    pub sync_ticks: u64,
    /// Messages the vehicles and managers sent.
    pub messages: Messages,
    /// Every node's CAN traffic, summed.
    pub can: CanStats,
    /// Every message carried a SecOC-style authenticator, and every node accepted only
    /// those that verified.
    pub authenticated: bool,
    /// Every message went as one CAN FD frame (its authenticator inside).
    pub can_fd: bool,
    /// States: publication (before the first frame is written) to the receiving socket's
    /// time stamp of the last frame.
    pub state_latency: Latency,
    /// Crossing requests, likewise (at managers and vehicles).
    pub request_latency: Latency,
    /// Grants, likewise.
    pub grant_latency: Latency,
    /// SYNC: written by the master to received by the node that acts on it.
    pub sync_latency: Latency,
    /// The intruder's attack and what of it was accepted (attack runs only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub intrusion: Option<Intrusion>,
    /// Grants the managers sent while `[faults.manager_down]` had theirs down (runs with
    /// an outage only; 0 is the only right answer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grants_while_down: Option<u64>,
}

/// An intruder's attack on a fleet run, and what of it the receivers accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Intrusion {
    /// The attack.
    pub attack: Attack,
    /// Messages it wrote (frames, for a flood).
    pub attempts: u64,
    /// Messages receivers accepted that no genuine node sent — forgeries, and copies
    /// beyond the genuine ones (replays) — summed over receivers ([`ledger::Ledger`]).
    pub accepted: u64,
}

impl FleetSummary {
    /// One line for a terminal.
    pub fn line(&self) -> String {
        format!(
            "{}: {} tasks, {} periods ({} SYNC ticks); {} states, {} requests, {} grants, {} exits; \
             frames sent {}, received {}, rejected {}; state latency p50 {:.0} µs, p99 {:.0} µs; \
             request latency p50 {:.0} µs, p99 {:.0} µs",
            self.medium,
            self.tasks,
            self.periods,
            self.sync_ticks,
            self.messages.states,
            self.messages.requests,
            self.messages.grants,
            self.messages.exits,
            self.can.frames_sent,
            self.can.frames_received,
            self.can.rejected_total(),
            self.state_latency.p50_us,
            self.state_latency.p99_us,
            self.request_latency.p50_us,
            self.request_latency.p99_us,
        )
    }
}

/// Why a fleet run failed.
#[derive(Debug)]
pub enum FleetError {
    /// Opening a node's port, or the master's traffic.
    Can(CanError),
    /// A vehicle task failed.
    Vehicle {
        /// The vehicle.
        id: u16,
        /// What failed.
        error: String,
    },
    /// The tasks broke the period protocol (a report out of turn, a panicked task).
    Harness(String),
    /// A task did not report within [`TIMEOUT`].
    Timeout {
        /// The period waited for.
        period: u64,
    },
    /// The world cannot run as a fleet (see `host-sim run --bus`).
    Unsupported(String),
}

impl fmt::Display for FleetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Can(e) => write!(f, "{e}"),
            Self::Vehicle { id, error } => write!(f, "vehicle {id}: {error}"),
            Self::Harness(e) => write!(f, "{e}"),
            Self::Timeout { period } => write!(
                f,
                "no report from every task for period {period} within {} s",
                TIMEOUT.as_secs()
            ),
            Self::Unsupported(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for FleetError {}

impl From<CanError> for FleetError {
    fn from(e: CanError) -> Self {
        Self::Can(e)
    }
}

/// Why `spec` cannot run as a fleet, if it cannot: the bus carries frames as they are
/// (no loss, delay, duplicates or reordering injected — a silent vehicle, a liar and a
/// manager's outage are the nodes' own faults, and run); no vehicle enters during the
/// run (every node's socket is open before anyone transmits); every vehicle id a CAN
/// source address; at most as many junctions as manager addresses.
pub fn unsupported(spec: &WorldSpec) -> Option<String> {
    let nodes_only = Faults {
        silent: None,
        liar: None,
        manager_down: None,
        ..spec.faults
    };
    if !nodes_only.is_none() {
        return Some(
            "[faults] loss, delay, jitter, duplicates and reordering are injected by the \
             in-process bus; a fleet carries frames as they are"
                .into(),
        );
    }
    if spec.arrivals != crate::world::Arrivals::None {
        return Some("vehicles that enter while the run goes on need the in-process bus".into());
    }
    if let Some(e) = spec
        .vehicles
        .iter()
        .find_map(|v| can::vehicle_address(v.id).err())
    {
        return Some(e.to_string());
    }
    (0..spec.network.junctions.len())
        .find(|&j| wire::manager_address(j).is_none())
        .map(|_| "more junctions than CAN manager addresses (13)".into())
}

/// A task's report to the harness.
enum Report {
    /// A vehicle published what it had to for `period`.
    Vehicle {
        index: usize,
        period: u64,
        /// Its true state at the period's start; `None` once it has left the world.
        truth: Option<VehicleTruth>,
        /// The row of the decision that led here (none at period 0).
        row: Option<TraceRow>,
        /// When its message for `period` was published, and of which kind.
        published: Option<(SystemTime, Kind)>,
        /// Messages heard in the previous period: (kind, sender id, receive stamp).
        heard: Vec<(Kind, u16, SystemTime)>,
        /// Receive stamp of the SYNC it planned on.
        sync_rx: Option<SystemTime>,
        /// It published an exit this period.
        exit: bool,
    },
    /// Junction `junction`'s manager granted `granted` for `period`.
    Manager {
        junction: usize,
        period: u64,
        granted: Vec<u16>,
        holders: Vec<(u16, u8)>,
        published: SystemTime,
        heard: Vec<(Kind, u16, SystemTime)>,
        sync_rx: SystemTime,
    },
    Failed {
        id: u16,
        error: String,
    },
}

/// A message's kind, for the latencies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    State,
    Request,
    Grant,
    Other,
}

fn kind_of(m: &Message) -> Kind {
    match m {
        Message::State { .. } => Kind::State,
        Message::Crossing { .. } => Kind::Request,
        Message::Grant { .. } => Kind::Grant,
        Message::Left { .. } | Message::Gone { .. } => Kind::Other,
    }
}

/// What the harness tells a vehicle task before its planning tick.
struct Go {
    sensed: Sensed,
}

/// What a vehicle task hands back.
type VehicleResult<const N: usize> = (Vehicle<N>, Counters, CanStats, Messages);

/// Where a fleet's nodes get their CAN ports.
pub enum Ports {
    /// Every node on a medium: a SocketCAN interface, or the in-process hub.
    Medium(Medium),
    /// Every node's port from `open` (a test's, e.g. one that drops or forges frames);
    /// `name` names the medium in the summary.
    Custom {
        /// The medium's name in the summary.
        name: String,
        /// Opens one node's port.
        open: Box<dyn FnMut(Node) -> io::Result<Box<dyn CanPort>>>,
    },
}

impl Ports {
    /// Ports from `open`, named `name` in the summary.
    pub fn custom<P: CanPort + 'static>(
        name: &str,
        mut open: impl FnMut(Node) -> io::Result<P> + 'static,
    ) -> Self {
        Self::Custom {
            name: name.to_string(),
            open: Box::new(move |n| open(n).map(|p| Box::new(p) as Box<dyn CanPort>)),
        }
    }
}

impl From<Medium> for Ports {
    fn from(m: Medium) -> Self {
        Self::Medium(m)
    }
}

/// A fleet: built with [`Fleet::new`] and the settings that differ from the defaults,
/// then [`Fleet::run`] on its ports. Every node is a task that talks to the others only
/// in CAN frames.
///
/// ```no_run
/// # use host_sim::fleet::{Fleet, Medium};
/// # fn f(spec: host_sim::world::WorldSpec) -> Result<(), host_sim::fleet::FleetError> {
/// let summary = Fleet::new().fd(true).run(spec, Medium::Hub, &mut |_| {})?;
/// # Ok(()) }
/// ```
#[derive(Clone)]
pub struct Fleet {
    solver: SolverChoice,
    seed: Option<u64>,
    keys: Option<Arc<Keys>>,
    fd: bool,
    attack: Option<Attack>,
}

impl Default for Fleet {
    fn default() -> Self {
        Self::new()
    }
}

/// When the intruder starts (s): the fleet has settled into its traffic by then.
pub const ATTACK_FROM_S: f64 = 1.0;

impl Fleet {
    /// Our solver, the scenario's seed, no keys, classic frames, no intruder.
    pub fn new() -> Self {
        Self {
            solver: SolverChoice::Ours,
            seed: None,
            keys: None,
            fd: false,
            attack: None,
        }
    }

    /// The planners' solver.
    pub fn solver(self, solver: SolverChoice) -> Self {
        Self { solver, ..self }
    }

    /// Overrides the scenario's seed (`None`: the scenario's).
    pub fn seed(self, seed: Option<u64>) -> Self {
        Self { seed, ..self }
    }

    /// With keys, every node authenticates what it sends and verifies what it accepts.
    pub fn keys(self, keys: Option<Arc<Keys>>) -> Self {
        Self { keys, ..self }
    }

    /// Every message goes as one CAN FD frame (an interface must carry CAN FD: MTU 72).
    pub fn fd(self, fd: bool) -> Self {
        Self { fd, ..self }
    }

    /// An intruder carries out `attack` from [`ATTACK_FROM_S`] on.
    pub fn attack(self, attack: Option<Attack>) -> Self {
        Self { attack, ..self }
    }

    /// Runs `spec` on `ports`; `trace` sees a row per vehicle and period.
    pub fn run(
        self,
        spec: WorldSpec,
        ports: impl Into<Ports>,
        trace: &mut dyn FnMut(&TraceRow),
    ) -> Result<FleetSummary, FleetError> {
        if let Some(why) = unsupported(&spec) {
            return Err(FleetError::Unsupported(why));
        }
        if self.attack.is_some()
            && spec
                .vehicles
                .iter()
                .any(|v| v.id == u16::from(INTRUDER_ADDRESS))
        {
            return Err(FleetError::Unsupported(format!(
                "vehicle {INTRUDER_ADDRESS} holds the intruder's address"
            )));
        }
        match ports.into() {
            Ports::Medium(m) => self.on_medium(spec, &m, trace),
            Ports::Custom { name, open } => self.start(spec, &name, open, trace),
        }
    }

    fn on_medium(
        self,
        spec: WorldSpec,
        medium: &Medium,
        trace: &mut dyn FnMut(&TraceRow),
    ) -> Result<FleetSummary, FleetError> {
        let name = medium.to_string();
        let fd = self.fd;
        match medium {
            Medium::SocketCan(iface) => {
                if let Some(w) = can::order_warning(iface) {
                    eprintln!("warning: {w}");
                }
                let iface = iface.clone();
                let open = move |n: Node| match n {
                    Node::Clock => SocketCanPort::open_transmit_only(&iface, fd),
                    _ if fd => SocketCanPort::open_fd(&iface),
                    _ => SocketCanPort::open(&iface),
                };
                self.start(spec, &name, open, trace)
            }
            Medium::Hub => {
                let hub = Hub::new();
                self.start(spec, &name, move |_| Ok(hub.port()), trace)
            }
        }
    }

    fn start<P: CanPort + 'static>(
        self,
        spec: WorldSpec,
        medium: &str,
        open: impl FnMut(Node) -> io::Result<P>,
        trace: &mut dyn FnMut(&TraceRow),
    ) -> Result<FleetSummary, FleetError> {
        match spec.horizon {
            50 => Harness::<50>::new(spec, self).run(medium, open, trace),
            _ => Harness::<20>::new(spec, self).run(medium, open, trace),
        }
    }
}

/// The fleet's harness: the time master, the monitors, the summary.
struct Harness<const N: usize> {
    spec: WorldSpec,
    solver: SolverChoice,
    seed: u64,
    lim: Limits,
    keys: Option<Arc<Keys>>,
    fd: bool,
    attack: Option<Attack>,
}

/// The latencies and counts the harness gathers.
#[derive(Default)]
struct Tally {
    state: Vec<f64>,
    request: Vec<f64>,
    grant: Vec<f64>,
    sync: Vec<f64>,
    grants: u64,
    exits: u64,
    ticks: u64,
    /// Grants managers sent while down (`[faults.manager_down]`).
    grants_while_down: u64,
}

impl Tally {
    fn heard(
        &mut self,
        heard: Vec<(Kind, u16, SystemTime)>,
        sent: &[(u16, SystemTime, Kind)],
        grants_at: Option<SystemTime>,
    ) {
        for (k, sender, at) in heard {
            match k {
                Kind::Grant => {
                    if let Some(g) = grants_at {
                        self.grant.push(micros(g, at));
                    }
                }
                Kind::State | Kind::Request => {
                    if let Some((_, s, _)) =
                        sent.iter().find(|(id, _, kk)| *id == sender && *kk == k)
                    {
                        let v = if k == Kind::State {
                            &mut self.state
                        } else {
                            &mut self.request
                        };
                        v.push(micros(*s, at));
                    }
                }
                Kind::Other => {}
            }
        }
    }
}

impl<const N: usize> Harness<N> {
    fn new(spec: WorldSpec, fleet: Fleet) -> Self {
        Self {
            seed: fleet.seed.unwrap_or(spec.seed),
            spec,
            solver: fleet.solver,
            lim: Limits::table_i(),
            keys: fleet.keys,
            fd: fleet.fd,
            attack: fleet.attack,
        }
    }

    fn setup(&self) -> PlannerSetup {
        PlannerSetup {
            solver: self.solver,
            // Lock-step: every message of period k is heard in period k.
            notify: self.lim.h,
            resolution: can::RESOLUTION,
            sensing: self.spec.sensing,
            reuse: None,
            precision: self.spec.precision,
            relevant_m: crate::world::heard::relevance_radius(&self.spec.network, self.lim.v_max),
            invariant: self.spec.invariant,
        }
    }

    /// Opens every node, runs the tasks and the time master to the end, and sums up.
    fn run<P: CanPort + 'static>(
        self,
        medium: &str,
        mut open: impl FnMut(Node) -> io::Result<P>,
        trace: &mut dyn FnMut(&TraceRow),
    ) -> Result<FleetSummary, FleetError> {
        let t0 = Instant::now();
        let net = self.spec.network.clone();
        let map = WireMap::new(&net);
        let vehicles: Vec<Vehicle<N>> = self
            .spec
            .vehicles
            .iter()
            .map(|v| build_vehicle::<N>(v, self.setup(), self.seed, &net))
            .collect();
        let managers = self.managers(&net)?;
        let mut nodes = Nodes::open(&mut open, &vehicles, &managers, &map)?;
        if let Some(keys) = &self.keys {
            nodes = nodes.with_keys(keys);
        }
        if self.fd {
            nodes = nodes.with_fd();
        }
        nodes = nodes.with_precision(self.spec.precision);
        let ledger = self.attack.map(|_| Arc::new(Ledger::new()));
        if let Some(l) = &ledger {
            nodes = nodes.with_ledger(l);
        }
        let intruder = match self.attack {
            Some(a) => Some(self.intruder(a, open(Node::Intruder).map_err(CanError::Io)?)),
            None => None,
        };
        let order: Vec<u16> = vehicles.iter().map(|v| v.id).collect();
        let ctx = TaskCtx {
            net: &net,
            map: &map,
            order: &order,
            total: (self.spec.duration_s / self.lim.h).round() as u64,
            with_managers: !managers.is_empty(),
            lim: self.lim,
            faults: self.spec.faults,
            clock: Clock::new(self.spec.clock_start, self.lim.h),
        };
        let (n, m) = (vehicles.len(), managers.len());
        let (ran, master) = std::thread::scope(|sc| {
            let (tx, rx) = mpsc::channel::<Report>();
            let Nodes {
                clock,
                vehicles: vnodes,
                managers: mnodes,
            } = nodes;
            let mut master = Master::new(&self, &ctx, clock, rx);
            master.intruder = intruder;
            let spawned = Tasks::spawn(
                sc,
                &mut master.clock,
                &ctx,
                &tx,
                (vehicles, vnodes),
                (managers, mnodes),
            );
            drop(tx);
            let mut tasks = match spawned {
                Ok(t) => t,
                Err(e) => return (Err(e), master.into_parts()),
            };
            // The master releases the vehicles each period; the channels stay open until
            // every task has ended.
            master.go = std::mem::take(&mut tasks.go);
            master.readings = std::mem::take(&mut tasks.readings);
            let mut result = master.periods(trace);
            if result.is_err() {
                let _ = end(&mut master.clock, master.tally.ticks as u32);
            }
            let ran = tasks.join(&mut result);
            (result.map(|()| ran), master.into_parts())
        });
        let ran = ran?;
        let mut summary = self.summary(medium, (n, m), ran, master, &net, t0);
        if let (Some(i), Some(l)) = (&mut summary.intrusion, &ledger) {
            i.accepted = l.forged_accepted();
        }
        Ok(summary)
    }

    /// The intruder of `attack` on `port`, with its own address's key if the fleet
    /// authenticates.
    fn intruder<P: CanPort>(&self, attack: Attack, port: P) -> Intruder<P> {
        let key = self
            .keys
            .as_ref()
            .and_then(|k| k.get(INTRUDER_ADDRESS).copied());
        let from = (ATTACK_FROM_S / self.lim.h).round() as u64;
        Intruder::new(attack, port, key, self.fd, from)
    }

    /// Every junction's manager, at the bus's position resolution.
    fn managers(&self, net: &Network) -> Result<Vec<ManagerNode>, FleetError> {
        let mut managers: Vec<ManagerNode> = net
            .junctions
            .iter()
            .enumerate()
            .map(|(j, jn)| {
                let setup = self.setup();
                let lease = crate::world::junction::lease(setup.notify, self.lim.h);
                let mut m = ManagerNode::new(j, jn, (lease, setup.precision));
                let _ = m.set_roadside(self.spec.sensing.map(|s| s.position_error_m));
                m
            })
            .collect();
        for m in &mut managers {
            m.set_resolution(can::RESOLUTION)
                .map_err(|e| FleetError::Harness(format!("bus resolution: {e:?}")))?;
        }
        Ok(managers)
    }

    /// The fleet's summary: the world's summary of the vehicles the tasks handed back,
    /// and the bus's figures.
    fn summary(
        &self,
        medium: &str,
        (n, m): (usize, usize),
        ran: Ran<N>,
        master: MasterParts,
        net: &Network,
        t0: Instant,
    ) -> FleetSummary {
        let Ran {
            cars,
            counters,
            can,
            mut msgs,
        } = ran;
        let MasterParts {
            tally,
            findings,
            deadlock,
            periods,
            intrusion,
        } = master;
        msgs.grants = tally.grants;
        msgs.exits = tally.exits;
        let in_world = cars.iter().filter(|v| v.log.left_at.is_none()).count();
        let unfinished = cars
            .iter()
            .filter(|v| v.log.left_at.is_none() && v.unmet(net))
            .count();
        let run = summarize(
            cars.iter(),
            &Outcome {
                spec: &self.spec,
                in_world,
                unfinished,
                // The fleet runs closed worlds: every vehicle is due from the start.
                under_way: 0,
                findings: &findings,
                counters: &counters,
                deadlock: deadlock.as_ref(),
                t: periods.saturating_sub(1) as f64 * self.lim.h,
                messages_sent: msgs.states + msgs.requests,
                bus_faults: Default::default(),
                solver: self.solver,
                seed: self.seed,
                wall_seconds: t0.elapsed().as_secs_f64(),
            },
        );
        FleetSummary {
            run,
            medium: medium.to_string(),
            tasks: n + m,
            managers: m,
            periods,
            sync_ticks: tally.ticks,
            messages: msgs,
            can,
            authenticated: self.keys.is_some(),
            can_fd: self.fd,
            state_latency: Latency::of(tally.state),
            request_latency: Latency::of(tally.request),
            grant_latency: Latency::of(tally.grant),
            sync_latency: Latency::of(tally.sync),
            intrusion,
            grants_while_down: self
                .spec
                .faults
                .manager_down
                .map(|_| tally.grants_while_down),
        }
    }
}

/// Every node's CAN port, opened before anyone transmits so that no node misses a frame.
struct Nodes<P: CanPort> {
    clock: CanNode<P>,
    vehicles: Vec<CanNode<P>>,
    managers: Vec<CanNode<P>>,
}

impl<P: CanPort> Nodes<P> {
    fn open<const N: usize>(
        open: &mut impl FnMut(Node) -> io::Result<P>,
        vehicles: &[Vehicle<N>],
        managers: &[ManagerNode],
        map: &WireMap<'_>,
    ) -> Result<Self, FleetError> {
        let clock = CanNode::new(CLOCK_ADDRESS, open(Node::Clock).map_err(CanError::Io)?);
        let mut vnodes = Vec::with_capacity(vehicles.len());
        for v in vehicles {
            let port = open(Node::Vehicle(v.id)).map_err(CanError::Io)?;
            vnodes.push(CanNode::vehicle(v.id, port)?);
        }
        let mut mnodes = Vec::with_capacity(managers.len());
        for m in managers {
            let port = open(Node::Manager(m.junction)).map_err(CanError::Io)?;
            mnodes.push(CanNode::new(map.manager_address(m.junction)?, port));
        }
        Ok(Self {
            clock,
            vehicles: vnodes,
            managers: mnodes,
        })
    }
}

impl<P: CanPort> Nodes<P> {
    /// Every node sending CAN FD frames.
    fn with_fd(self) -> Self {
        let fd = |v: Vec<CanNode<P>>| v.into_iter().map(CanNode::with_fd).collect();
        Self {
            clock: self.clock.with_fd(),
            vehicles: fd(self.vehicles),
            managers: fd(self.managers),
        }
    }

    /// Every node coding in `precision`.
    fn with_precision(self, precision: crate::world::precision::Precision) -> Self {
        let coded =
            |v: Vec<CanNode<P>>| v.into_iter().map(|n| n.with_precision(precision)).collect();
        Self {
            clock: self.clock.with_precision(precision),
            vehicles: coded(self.vehicles),
            managers: coded(self.managers),
        }
    }

    /// Every node telling `ledger` what it sends and accepts.
    fn with_ledger(self, ledger: &Arc<Ledger>) -> Self {
        let told = |v: Vec<CanNode<P>>| {
            v.into_iter()
                .map(|n| n.with_ledger(ledger.clone()))
                .collect()
        };
        Self {
            clock: self.clock.with_ledger(ledger.clone()),
            vehicles: told(self.vehicles),
            managers: told(self.managers),
        }
    }

    /// Every node authenticating with `keys`.
    fn with_keys(self, keys: &Arc<Keys>) -> Self {
        let keyed = |v: Vec<CanNode<P>>| v.into_iter().map(|n| n.with_keys(keys.clone())).collect();
        Self {
            clock: self.clock.with_keys(keys.clone()),
            vehicles: keyed(self.vehicles),
            managers: keyed(self.managers),
        }
    }
}

/// What the vehicle tasks handed back at the end.
#[derive(Default)]
struct Ran<const N: usize> {
    cars: Vec<Vehicle<N>>,
    counters: Counters,
    can: CanStats,
    msgs: Messages,
}

/// The running tasks: one per vehicle (with the channel that releases it each period)
/// and one per manager.
struct Tasks<'scope, const N: usize> {
    vehicles: Vec<std::thread::ScopedJoinHandle<'scope, Result<VehicleResult<N>, FleetError>>>,
    go: Vec<mpsc::Sender<Go>>,
    managers: Vec<std::thread::ScopedJoinHandle<'scope, Result<CanStats, FleetError>>>,
    /// Per manager, its roadside sensor's readings of each period (when it has one).
    readings: Vec<mpsc::Sender<Readings>>,
}

/// A roadside sensor's readings of one period: (vehicle, position along its route).
type Readings = Vec<(u16, f64)>;

impl<'scope, const N: usize> Tasks<'scope, N> {
    fn spawn<'env, P: CanPort + 'static>(
        sc: &'scope std::thread::Scope<'scope, 'env>,
        clock: &mut CanNode<P>,
        ctx: &'scope TaskCtx<'scope>,
        tx: &mpsc::Sender<Report>,
        (cars, vnodes): (Vec<Vehicle<N>>, Vec<CanNode<P>>),
        (mgrs, mnodes): (Vec<ManagerNode>, Vec<CanNode<P>>),
    ) -> Result<Self, FleetError> {
        let mut tasks = Self {
            vehicles: Vec::with_capacity(cars.len()),
            go: Vec::with_capacity(cars.len()),
            managers: Vec::with_capacity(mgrs.len()),
            readings: Vec::with_capacity(mgrs.len()),
        };
        for (index, (car, node)) in cars.into_iter().zip(vnodes).enumerate() {
            let (task_tx, (gtx, grx)) = (tx.clone(), mpsc::channel::<Go>());
            tasks.go.push(gtx);
            let name = format!("vehicle-{}", car.id);
            tasks.vehicles.push(spawn(sc, clock, &name, move || {
                vehicle_task(index, car, node, ctx, &task_tx, &grx)
            })?);
        }
        for (mgr, node) in mgrs.into_iter().zip(mnodes) {
            let (task_tx, (rtx, rrx)) = (tx.clone(), mpsc::channel::<Readings>());
            tasks.readings.push(rtx);
            let name = format!("manager-{}", mgr.junction);
            tasks.managers.push(spawn(sc, clock, &name, move || {
                manager_task(mgr, node, ctx, &task_tx, &rrx)
            })?);
        }
        Ok(tasks)
    }

    /// Waits for every task; the first failure (if `result` has none yet) goes there.
    fn join(self, result: &mut Result<(), FleetError>) -> Ran<N> {
        let mut ran = Ran::default();
        for (car, c, s, mm) in join(self.vehicles, result) {
            ran.counters.add(&c);
            ran.can.add(&s);
            ran.msgs.states += mm.states;
            ran.msgs.requests += mm.requests;
            ran.cars.push(car);
        }
        for s in join(self.managers, result) {
            ran.can.add(&s);
        }
        ran
    }
}

/// The time master and the harness's view of one run: it collects every task's report
/// for a period, runs the monitors on ground truth, ticks SYNC and hands out sensor
/// returns.
struct Master<'a, P: CanPort, const N: usize> {
    harness: &'a Harness<N>,
    ctx: &'a TaskCtx<'a>,
    clock: CanNode<P>,
    rx: mpsc::Receiver<Report>,
    go: Vec<mpsc::Sender<Go>>,
    /// Per manager, where its roadside sensor's readings go.
    readings: Vec<mpsc::Sender<Readings>>,
    /// The roadside sensors' noise, drawn as the in-process world draws it.
    roadside_rng: Box<rand_chacha::ChaCha8Rng>,
    tally: Tally,
    monitor: WorldMonitor,
    detector: DeadlockDetector,
    deadlock: Option<crate::monitor::liveness::Deadlock>,
    periods: u64,
    /// Who published what when in the previous period (for the latencies).
    sent: Vec<(u16, SystemTime, Kind)>,
    grants_at: Option<SystemTime>,
    last_tick: Option<SystemTime>,
    /// Per junction, the permissions its manager holds (for the wait-for relation).
    holders: Vec<Vec<(u16, u8)>>,
    /// The attack experiment's intruder, acting before each planning tick.
    intruder: Option<Intruder<P>>,
}

/// What the master hands back for the summary.
struct MasterParts {
    tally: Tally,
    findings: crate::monitor::Findings,
    deadlock: Option<crate::monitor::liveness::Deadlock>,
    periods: u64,
    intrusion: Option<Intrusion>,
}

/// One period's vehicle reports, in vehicle order.
struct Truths {
    truths: Vec<Option<VehicleTruth>>,
    rows: Vec<Option<TraceRow>>,
}

impl<'a, P: CanPort, const N: usize> Master<'a, P, N> {
    fn new(
        harness: &'a Harness<N>,
        ctx: &'a TaskCtx<'a>,
        clock: CanNode<P>,
        rx: mpsc::Receiver<Report>,
    ) -> Self {
        Self {
            harness,
            ctx,
            clock,
            rx,
            go: Vec::new(),
            readings: Vec::new(),
            roadside_rng: Box::new(crate::reference::instances::rng(
                harness.seed ^ crate::world::sensor::ROADSIDE_SEED,
            )),
            tally: Tally::default(),
            monitor: WorldMonitor::new(ctx.net),
            detector: DeadlockDetector::new(harness.spec.deadlock_window_s),
            deadlock: None,
            periods: 0,
            sent: Vec::new(),
            grants_at: None,
            last_tick: None,
            holders: vec![Vec::new(); ctx.net.junctions.len()],
            intruder: None,
        }
    }

    fn into_parts(self) -> MasterParts {
        MasterParts {
            tally: self.tally,
            findings: self.monitor.findings,
            deadlock: self.deadlock,
            periods: self.periods,
            intrusion: self.intruder.map(|i| Intrusion {
                attack: i.attack(),
                attempts: i.attempts(),
                accepted: 0,
            }),
        }
    }

    /// Runs every period to the last.
    fn periods(&mut self, trace: &mut dyn FnMut(&TraceRow)) -> Result<(), FleetError> {
        for k in 0..=self.ctx.total {
            if self.period(k, trace)? {
                break;
            }
        }
        Ok(())
    }

    /// Period k: the vehicles' reports, the monitors, the managers' turn, the sensor
    /// returns and the planning tick. `Ok(true)` when the run is over.
    fn period(&mut self, k: u64, trace: &mut dyn FnMut(&TraceRow)) -> Result<bool, FleetError> {
        self.clock.set_time(self.ctx.clock.at_step(k));
        let Truths { truths, rows } = self.vehicle_reports(k)?;
        let present: Vec<VehicleTruth> = truths.iter().flatten().copied().collect();
        if k > 0 {
            rows.iter().flatten().for_each(&mut *trace);
            self.observe(k, &present);
        }
        self.periods = k + 1;
        let gone = present.is_empty() && !self.ctx.net.junctions.is_empty();
        let last = k == self.ctx.total || self.deadlock.is_some() || gone;
        let with_managers = self.ctx.with_managers;
        if with_managers {
            if !last {
                self.roadside(k, &present);
            }
            let at = tick(&mut self.clock, 2 * k, last)?;
            self.tally.ticks += 1;
            if last {
                return Ok(true);
            }
            self.manager_reports(k, at)?;
        }
        if let Some(i) = &mut self.intruder {
            let (ctx, h) = (self.ctx, self.ctx.lim.h);
            let junctions = ctx.net.junctions.len();
            i.act((k, ctx.clock.at_step(k), h), &present, ctx.map, junctions)?;
        }
        // Sensor returns from ground truth at kh, as in the in-process world.
        let h = self.harness;
        let seen = sense_all(
            self.ctx.net,
            &present,
            &truths,
            h.spec.sensing.as_ref(),
            (h.seed, k),
        );
        for (g, s) in self.go.iter().zip(seen) {
            let _ = g.send(Go { sensed: s });
        }
        let plan = if with_managers { 2 * k + 1 } else { k };
        self.last_tick = Some(tick(&mut self.clock, plan, !with_managers && last)?);
        self.tally.ticks += 1;
        Ok(!with_managers && last)
    }

    /// Each manager's roadside readings of period k (when the world has sensors; none
    /// while it is down), drawn in junction order as the in-process world draws them.
    fn roadside(&mut self, k: u64, present: &[VehicleTruth]) {
        let Some(error) = self.harness.spec.sensing.map(|s| s.position_error_m) else {
            return;
        };
        let seen: Vec<Seen> = present.iter().map(VehicleTruth::seen).collect();
        let t = k as f64 * self.ctx.lim.h;
        for (j, out) in self.readings.iter().enumerate() {
            let id = self.harness.spec.network.junctions.get(j).map(|jn| jn.id);
            if id.is_some_and(|id| self.ctx.faults.manager_down_at(id, t)) {
                let _ = out.send(Vec::new());
                continue;
            }
            let r = crate::world::sensor::roadside(
                self.ctx.net,
                j,
                &seen,
                error,
                &mut self.roadside_rng,
            );
            let _ = out.send(r);
        }
    }

    /// The monitors and the deadlock detector on the ground truth of period k.
    fn observe(&mut self, k: u64, present: &[VehicleTruth]) {
        let (lim, net) = (&self.ctx.lim, self.ctx.net);
        self.monitor.check(lim, net, present);
        let holders = &self.holders;
        let held = |j: usize| holders.get(j).cloned().unwrap_or_default();
        let t = k as f64 * lim.h;
        let watched =
            crate::world::wait::watch(&mut self.detector, t, present, false, net, &held, lim);
        if let Some(d) = watched {
            self.deadlock = Some(d);
        }
    }

    /// Every vehicle task's report for period k.
    fn vehicle_reports(&mut self, k: u64) -> Result<Truths, FleetError> {
        let n = self.ctx.order.len();
        let mut out = Truths {
            truths: vec![None; n],
            rows: vec![None; n],
        };
        let mut next_sent = Vec::with_capacity(n);
        for _ in 0..n {
            match self.rx.recv_timeout(TIMEOUT) {
                Ok(Report::Vehicle {
                    index,
                    period,
                    truth,
                    row,
                    published,
                    heard,
                    sync_rx,
                    exit,
                }) if period == k => {
                    if let (Some(slot), Some(r)) =
                        (out.truths.get_mut(index), out.rows.get_mut(index))
                    {
                        (*slot, *r) = (truth, row);
                    }
                    if let (Some((at, kind)), Some(id)) = (published, self.ctx.order.get(index)) {
                        next_sent.push((*id, at, kind));
                    }
                    self.tally.heard(heard, &self.sent, self.grants_at);
                    self.tally.exits += u64::from(exit);
                    if let (Some(s), Some(r)) = (self.last_tick, sync_rx) {
                        self.tally.sync.push(micros(s, r));
                    }
                }
                Ok(Report::Failed { id, error }) => return Err(FleetError::Vehicle { id, error }),
                Ok(_) => {
                    return Err(FleetError::Harness(format!(
                        "a report out of turn in period {k}"
                    )))
                }
                Err(_) => return Err(FleetError::Timeout { period: k }),
            }
        }
        self.sent = next_sent;
        Ok(out)
    }

    /// Every manager's report for period k (after SYNC(2k) at `at`).
    fn manager_reports(&mut self, k: u64, at: SystemTime) -> Result<(), FleetError> {
        self.grants_at = None;
        for _ in 0..self.holders.len() {
            match self.rx.recv_timeout(TIMEOUT) {
                Ok(Report::Manager {
                    junction,
                    period,
                    granted,
                    holders,
                    published,
                    heard,
                    sync_rx,
                }) if period == k => {
                    self.monitor.granted(junction, &granted);
                    self.tally.grants += granted.len() as u64;
                    let t = k as f64 * self.ctx.lim.h;
                    let id = self
                        .harness
                        .spec
                        .network
                        .junctions
                        .get(junction)
                        .map(|jn| jn.id);
                    if id.is_some_and(|id| self.ctx.faults.manager_down_at(id, t)) {
                        self.tally.grants_while_down += granted.len() as u64;
                    }
                    if !granted.is_empty() {
                        self.grants_at = Some(published);
                    }
                    if let Some(slot) = self.holders.get_mut(junction) {
                        *slot = holders;
                    }
                    self.tally.heard(heard, &self.sent, None);
                    self.tally.sync.push(micros(at, sync_rx));
                }
                Ok(Report::Failed { id, error }) => {
                    return Err(FleetError::Harness(format!("manager {id}: {error}")))
                }
                Ok(_) => {
                    return Err(FleetError::Harness(format!(
                        "a report out of turn while waiting for the managers' period {k}"
                    )))
                }
                Err(_) => return Err(FleetError::Timeout { period: k }),
            }
        }
        Ok(())
    }
}

/// Sensor returns for every vehicle task (in index order) from the truths at period k;
/// a vehicle gone gets none. The noise is drawn per period from the seed, so the run is
/// repeatable.
fn sense_all(
    net: &Network,
    present: &[VehicleTruth],
    truths: &[Option<VehicleTruth>],
    sensing: Option<&planner_core::Sensing<f64>>,
    (seed, k): (u64, u64),
) -> Vec<Sensed> {
    let all: Vec<Seen> = present.iter().map(VehicleTruth::seen).collect();
    let mut rng = crate::reference::instances::rng(seed ^ 0x5e15 ^ k.wrapping_mul(0x9E37_79B9));
    let each = truths.iter().map(|t| t.map(|v| (v.seen(), v.planner)));
    sense_each(net, &all, each, sensing, &mut rng)
}

/// What every task knows of the run.
struct TaskCtx<'a> {
    net: &'a Network,
    map: &'a WireMap<'a>,
    order: &'a [u16],
    total: u64,
    with_managers: bool,
    lim: Limits,
    /// The nodes' own faults: a silent vehicle, a liar, a manager's outage.
    faults: Faults,
    /// Every node's clock.
    clock: Clock,
}

/// One vehicle: publish, report, wait for SYNC, plan, move — until the last SYNC.
fn vehicle_task<const N: usize, P: CanPort>(
    index: usize,
    mut car: Vehicle<N>,
    mut node: CanNode<P>,
    ctx: &TaskCtx<'_>,
    tx: &mpsc::Sender<Report>,
    go: &mpsc::Receiver<Go>,
) -> Result<VehicleResult<N>, FleetError> {
    let id = car.id;
    let fail = |error: String| {
        let _ = tx.send(Report::Failed {
            id,
            error: error.clone(),
        });
        FleetError::Vehicle { id, error }
    };
    let h = ctx.lim.h;
    let mut counters = Counters::default();
    let mut msgs = Messages::default();
    let mut inbox: Vec<(Received, u8)> = Vec::new();
    let mut row = None;
    let mut heard = Vec::new();
    let mut sync_rx = None;
    let mut departing: Option<(Option<usize>, f64)> = None;
    for k in 0..=ctx.total {
        let t = k as f64 * h;
        let now = ctx.clock.at_step(k);
        node.set_time(now);
        let published = SystemTime::now();
        let mut exit = false;
        if let Some((j, at)) =
            departing.filter(|&(_, at)| t < at + crate::world::junction::LEFT_REPEAT_S)
        {
            let at = ctx.clock.at_secs(at);
            node.send(&Message::departure(id, at, j), ctx.map, at)
                .map_err(|e| fail(e.to_string()))?;
            exit = true;
        }
        let in_world = car.log.left_at.is_none();
        let kind = if in_world {
            publish(&car, &mut node, ctx, k, &mut msgs).map_err(|e| fail(e.to_string()))?
        } else {
            None
        };
        let report = Report::Vehicle {
            index,
            period: k,
            truth: in_world.then(|| car.truth(ctx.net)),
            row: row.take(),
            published: kind.map(|k| (published, k)),
            heard: std::mem::take(&mut heard),
            sync_rx: sync_rx.take(),
            exit,
        };
        if tx.send(report).is_err() {
            return Err(fail("the harness is gone".into()));
        }
        let plan = if ctx.with_managers { 2 * k + 1 } else { k };
        inbox.clear();
        let Some(at) =
            await_tick(&mut node, plan, ctx.map, (t, now), &mut inbox, &mut heard).map_err(fail)?
        else {
            break;
        };
        sync_rx = Some(at);
        let Ok(Go { sensed }) = go.recv_timeout(TIMEOUT) else {
            return Err(fail(format!("no sensor returns for period {k}")));
        };
        if k == ctx.total || !in_world {
            continue;
        }
        let received = in_order(&mut inbox, ctx.order, t);
        let step = StepCtx {
            t,
            now,
            clock: ctx.clock,
            steps_done: k,
            net: ctx.net,
            lim: ctx.lim,
            silent: ctx.faults.silent,
            liar: ctx.faults.liar,
            returns: &sensed,
        };
        let (r, moved) = car.period(&step, &received, &mut counters);
        let now = (k + 1) as f64 * h;
        match moved {
            Moved::LeftJunction(j) => departing = Some((Some(j), now)),
            Moved::LeftWorld => departing = Some((None, now)),
            Moved::Stays => {}
        }
        row = Some(r);
    }
    Ok((car, counters, node.stats().clone(), msgs))
}

/// Vehicle `car`'s message for period `k` — unless its transmitter is silent, and as a
/// liar tells it — counted in `msgs`; its kind, if sent.
fn publish<const N: usize, P: CanPort>(
    car: &Vehicle<N>,
    node: &mut CanNode<P>,
    ctx: &TaskCtx<'_>,
    k: u64,
    msgs: &mut Messages,
) -> Result<Option<Kind>, CanError> {
    let id = car.id;
    let (t, now) = (k as f64 * ctx.lim.h, ctx.clock.at_step(k));
    if ctx
        .faults
        .silent
        .is_some_and(|s| s.id == id && t >= s.from_s)
    {
        return Ok(None);
    }
    let m = ctx.faults.told(id, car.message(now), t);
    let arrival = car.log.arrived_at.map_or(now, |a| ctx.clock.at_secs(a));
    node.send(&m, ctx.map, arrival)?;
    let kind = kind_of(&m);
    match kind {
        Kind::State => msgs.states += 1,
        _ => msgs.requests += 1,
    }
    Ok(Some(kind))
}

/// A junction's manager: wait for SYNC(2k), decide on what preceded it, grant — until the
/// last SYNC.
fn manager_task<P: CanPort>(
    mut mgr: ManagerNode,
    mut node: CanNode<P>,
    ctx: &TaskCtx<'_>,
    tx: &mpsc::Sender<Report>,
    readings: &mpsc::Receiver<Readings>,
) -> Result<CanStats, FleetError> {
    let j = mgr.junction;
    let fail = |error: String| {
        let _ = tx.send(Report::Failed {
            id: j as u16,
            error: error.clone(),
        });
        FleetError::Harness(format!("manager of junction {j}: {error}"))
    };
    let mut inbox: Vec<(Received, u8)> = Vec::new();
    let mut heard = Vec::new();
    for k in 0..=ctx.total {
        let t = k as f64 * ctx.lim.h;
        let now = ctx.clock.at_step(k);
        node.set_time(now);
        inbox.clear();
        let Some(sync_rx) = await_tick(&mut node, 2 * k, ctx.map, (t, now), &mut inbox, &mut heard)
            .map_err(fail)?
        else {
            break;
        };
        let received = in_order(&mut inbox, ctx.order, t);
        let seen = if mgr.has_roadside() {
            readings.recv_timeout(TIMEOUT).unwrap_or_default()
        } else {
            Vec::new()
        };
        let granted = if mgr.is_up(&ctx.faults, t) {
            mgr.manage(&received, &seen, now)
        } else {
            Vec::new()
        };
        let published = SystemTime::now();
        for &id in &granted {
            let g = mgr.grant(id, now);
            node.send(&g, ctx.map, now)
                .map_err(|e| fail(e.to_string()))?;
        }
        let holders = crate::world::wait::holders(std::slice::from_ref(&mgr), j);
        let report = Report::Manager {
            junction: j,
            period: k,
            granted,
            holders,
            published,
            heard: std::mem::take(&mut heard),
            sync_rx,
        };
        if tx.send(report).is_err() {
            return Err(fail("the harness is gone".into()));
        }
    }
    Ok(node.stats().clone())
}

/// Reads frames until SYNC(`tick`), keeping every message before it (sent in the period
/// that began at world time `t`, node time `now`, with its sender's address) and what
/// was heard when; `None` on the last SYNC.
fn await_tick<P: CanPort>(
    node: &mut CanNode<P>,
    tick: u64,
    map: &WireMap<'_>,
    (t, now): (f64, planner_core::Instant),
    inbox: &mut Vec<(Received, u8)>,
    heard: &mut Vec<(Kind, u16, SystemTime)>,
) -> Result<Option<SystemTime>, String> {
    let deadline = Instant::now() + TIMEOUT;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(format!("no SYNC {tick} within {TIMEOUT:?}"));
        }
        match node.poll(left).map_err(|e| e.to_string())? {
            Polled::Nothing | Polled::Frame => {}
            Polled::Message(wire::Message::Sync { period, last }, at, _) => {
                if last {
                    return Ok(None);
                }
                // Every node hears every tick: the managers' and the vehicles' alternate.
                match u64::from(period).cmp(&tick) {
                    std::cmp::Ordering::Less => {}
                    std::cmp::Ordering::Equal => return Ok(Some(at)),
                    std::cmp::Ordering::Greater => {
                        return Err(format!("SYNC {period} while waiting for {tick}"))
                    }
                }
            }
            Polled::Message(m, at, sa) => {
                if let Some(msg) = map.heard(&m, sa, now) {
                    heard.push((kind_of(&msg), msg.sender(), at));
                    inbox.push((Received { msg, at: t }, sa));
                }
            }
        }
    }
}

/// A period's messages in the in-process bus's order, whatever order the tasks' frames
/// interleaved in: exits first, then states and requests by sender in the world's order,
/// then grants by junction; received at `t`.
fn in_order(inbox: &mut [(Received, u8)], order: &[u16], t: f64) -> Vec<Received> {
    let rank = |r: &Received| -> (u8, usize) {
        let pos = |id: u16| order.iter().position(|&o| o == id).unwrap_or(usize::MAX);
        match r.msg {
            Message::Left { id, .. } | Message::Gone { id, .. } => (0, pos(id)),
            Message::State { .. } | Message::Crossing { .. } => (1, pos(r.msg.subject().0)),
            Message::Grant { junction, id, .. } => (2, junction * 65536 + pos(id).min(65535)),
        }
    };
    inbox.sort_by_key(|(r, _)| rank(r));
    inbox
        .iter()
        .map(|(r, _)| Received { msg: r.msg, at: t })
        .collect()
}

/// Starts a task named `name` in `scope`; if the system refuses a thread, tells the tasks
/// already started to stop (a last SYNC) and answers the error.
fn spawn<'scope, T: Send + 'scope, P: CanPort>(
    scope: &'scope std::thread::Scope<'scope, '_>,
    clock: &mut CanNode<P>,
    name: &str,
    task: impl FnOnce() -> T + Send + 'scope,
) -> Result<std::thread::ScopedJoinHandle<'scope, T>, FleetError> {
    std::thread::Builder::new()
        .name(name.to_string())
        .spawn_scoped(scope, task)
        .map_err(|e| {
            let _ = end(clock, 0);
            FleetError::Harness(format!("{name}: cannot start its task: {e}"))
        })
}

/// Waits for every task; their results, and the first failure in `result` (unless it
/// already holds one).
fn join<T>(
    handles: Vec<std::thread::ScopedJoinHandle<'_, Result<T, FleetError>>>,
    result: &mut Result<(), FleetError>,
) -> Vec<T> {
    let mut done = Vec::with_capacity(handles.len());
    for h in handles {
        let failure = match h.join() {
            Ok(Ok(r)) => {
                done.push(r);
                continue;
            }
            Ok(Err(e)) => e,
            Err(_) => FleetError::Harness("a task panicked".into()),
        };
        if result.is_ok() {
            *result = Err(failure);
        }
    }
    done
}

/// The time master's tick `period` (`last`: the run ends); when it was written.
fn tick<P: CanPort>(
    clock: &mut CanNode<P>,
    period: u64,
    last: bool,
) -> Result<SystemTime, FleetError> {
    // The master's own port hears the fleet on a hub; nothing else reads it (a failed
    // read only leaves frames queued there).
    let _ = clock.drain(|_, _| {});
    let at = SystemTime::now();
    let m = wire::Message::Sync {
        period: period as u32,
        last,
    };
    clock.send_wire(&m).map_err(FleetError::Can)?;
    Ok(at)
}

/// Tells every task to stop (a last SYNC after `period`).
fn end<P: CanPort>(clock: &mut CanNode<P>, period: u32) -> Result<(), CanError> {
    clock.send_wire(&wire::Message::Sync {
        period: period.saturating_add(1),
        last: true,
    })
}

/// Microseconds from `from` to `to` (0 if `to` is earlier).
pub fn micros(from: SystemTime, to: SystemTime) -> f64 {
    to.duration_since(from)
        .map_or(0.0, |d| d.as_secs_f64() * 1e6)
}
