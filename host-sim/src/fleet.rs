//! A fleet on a CAN medium: every vehicle's planner runs in its own task (a thread with
//! its own CAN socket) and hears the others only through can-gateway frames on that
//! medium — a SocketCAN interface such as `vcan0`, or the in-process frame [`Hub`].
//!
//! Time is kept by a time master on the bus, in the manner of CANopen SYNC: one
//! [`wire::Message::Sync`] frame per period. Per period k a vehicle task
//!
//! 1. reads frames until SYNC(k): the states every other vehicle published for time kh
//!    precede it on the bus (one interface delivers in send order);
//! 2. plans with what it heard (the world view, message ages by time stamp), applies the
//!    command for one period h to its own exact vehicle model (1);
//! 3. publishes its state at (k+1)h as CAN frames, then reports its true state to the
//!    harness, which runs the independent monitor — ground truth never reaches a planner.
//!
//! The master sends SYNC(k+1) once every vehicle has reported. The run is lock-step and
//! as deterministic as the in-process simulator; what differs is that every state went
//! through the codec (J2735 resolutions, E2E checks) and the kernel's CAN stack. The
//! kernel's receive time stamps measure the latency from publication to reception.

use crate::bus::{Message, Received};
use crate::can::{CanError, CanNode, CanPort, CanStats, Hub, Polled, SocketCanPort};
use crate::monitor::{Findings, Limits, Truth};
use crate::scenario::Scenario;
use crate::sim::{
    build_agents, road_of, set_bus_resolution, summarize, Agent, Counters, Outcome, RunSummary,
    SolverChoice, StepCtx, TraceRow,
};
use can_gateway::wire::{self, CLOCK_ADDRESS};
use serde::Serialize;
use std::collections::HashMap;
use std::fmt;
use std::io;
use std::sync::mpsc;
use std::time::{Duration, Instant, SystemTime};

/// How long a task waits for the next SYNC, and the master for a vehicle's report, before
/// the run fails: far above a period's work even under full-system emulation.
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
    pub(crate) fn of(mut v: Vec<f64>) -> Self {
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

/// What a fleet run produced (the `--json` summary of `run --bus`).
#[derive(Debug, Clone, Serialize)]
pub struct FleetSummary {
    /// The run, as the in-process simulator reports it.
    #[serde(flatten)]
    pub run: RunSummary,
    /// The medium (`socketcan:vcan0`, `can-hub`).
    pub medium: String,
    /// Tasks (one per vehicle).
    pub tasks: usize,
    /// SYNC ticks sent.
    pub periods: u64,
    /// Every vehicle node's CAN traffic, summed.
    pub can: CanStats,
    /// State messages: publication (just before the first frame is written) to the
    /// receiving socket's time stamp of the last frame.
    pub state_latency: Latency,
    /// SYNC: written by the master to received by each vehicle.
    pub sync_latency: Latency,
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
    /// A vehicle did not report within [`TIMEOUT`].
    Timeout {
        /// The period waited for.
        period: u64,
    },
}

impl fmt::Display for FleetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Can(e) => write!(f, "{e}"),
            Self::Vehicle { id, error } => write!(f, "vehicle {id}: {error}"),
            Self::Harness(e) => write!(f, "{e}"),
            Self::Timeout { period } => write!(
                f,
                "no report from every vehicle for period {period} within {} s",
                TIMEOUT.as_secs()
            ),
        }
    }
}

impl std::error::Error for FleetError {}

impl From<CanError> for FleetError {
    fn from(e: CanError) -> Self {
        Self::Can(e)
    }
}

/// A vehicle task's report to the harness after publishing its state for `period`.
enum Report {
    Ready {
        index: usize,
        id: u16,
        period: u64,
        truth: Truth,
        /// The row of the decision that led here (none at period 0).
        row: Option<TraceRow>,
        /// When its state for `period` was published.
        published: SystemTime,
        /// States heard while waiting for the SYNC that ended the previous period:
        /// (sender, receive stamp).
        heard: Vec<(u16, SystemTime)>,
        /// Receive stamp of that SYNC.
        sync_rx: Option<SystemTime>,
    },
    Failed {
        id: u16,
        error: String,
    },
}

/// Opens the port of a node (`Some(id)`: a vehicle, or an intersection manager's node
/// id) or of the time master (`None`).
pub(crate) type OpenPort = dyn FnMut(Option<u16>) -> io::Result<Box<dyn CanPort>>;

/// What a task hands back at the end.
type TaskResult<const N: usize> = (Agent<N>, Counters, CanStats);

/// Runs `scenario` as a fleet on `medium`, dispatching on its horizon; `trace` sees a row
/// per vehicle and period (in scenario order), `progress` (period, periods).
pub fn run(
    scenario: Scenario,
    solver: SolverChoice,
    seed: Option<u64>,
    medium: &Medium,
    trace: &mut dyn FnMut(&TraceRow),
    progress: &mut dyn FnMut(u64, u64),
) -> Result<FleetSummary, FleetError> {
    run_with_ports(
        scenario,
        solver,
        seed,
        &medium.to_string(),
        opener(medium),
        trace,
        progress,
    )
}

/// The ports of `medium`: a socket per node (the master's transmit-only), or a port on
/// one new hub.
pub(crate) fn opener(medium: &Medium) -> Box<OpenPort> {
    // One port type for both media: a frame's dynamic call is nothing next to a plan.
    match medium {
        Medium::SocketCan(iface) => {
            let iface = iface.clone();
            Box::new(move |id| {
                let port = match id {
                    Some(_) => SocketCanPort::open(&iface)?,
                    None => SocketCanPort::open_transmit_only(&iface)?,
                };
                Ok(Box::new(port) as Box<dyn CanPort>)
            })
        }
        Medium::Hub => {
            let hub = Hub::new();
            Box::new(move |_| Ok(Box::new(hub.port()) as Box<dyn CanPort>))
        }
    }
}

/// [`run`] on ports from `open`: `open(Some(id))` for vehicle `id`'s node, `open(None)`
/// for the time master's; `medium` names them in the summary.
pub fn run_with_ports<P: CanPort + 'static>(
    scenario: Scenario,
    solver: SolverChoice,
    seed: Option<u64>,
    medium: &str,
    open: impl FnMut(Option<u16>) -> io::Result<P>,
    trace: &mut dyn FnMut(&TraceRow),
    progress: &mut dyn FnMut(u64, u64),
) -> Result<FleetSummary, FleetError> {
    match scenario.horizon {
        50 => run_n::<50, P>(scenario, solver, seed, medium, open, trace, progress),
        _ => run_n::<20, P>(scenario, solver, seed, medium, open, trace, progress),
    }
}

#[allow(clippy::too_many_arguments)]
fn run_n<const N: usize, P: CanPort + 'static>(
    scenario: Scenario,
    solver: SolverChoice,
    seed: Option<u64>,
    medium: &str,
    mut open: impl FnMut(Option<u16>) -> io::Result<P>,
    trace: &mut dyn FnMut(&TraceRow),
    progress: &mut dyn FnMut(u64, u64),
) -> Result<FleetSummary, FleetError> {
    let t0 = Instant::now();
    let lim = Limits::table_i();
    let h = lim.h;
    let seed = seed.unwrap_or(scenario.seed);
    // Lock-step: every state of period k is heard in period k, as on the perfect bus.
    let mut agents = build_agents::<N>(&scenario, solver, seed, h);
    set_bus_resolution(&mut agents, crate::can::RESOLUTION)
        .map_err(|e| FleetError::Harness(format!("bus resolution: {e:?}")))?;
    // Every socket is open before anyone transmits, so that no node misses a frame.
    let mut clock = CanNode::new(CLOCK_ADDRESS, open(None).map_err(CanError::Io)?);
    let mut nodes = Vec::with_capacity(agents.len());
    for a in &agents {
        let port = open(Some(a.id())).map_err(CanError::Io)?;
        nodes.push(CanNode::vehicle(a.id(), port)?);
    }
    let total = (scenario.duration_s / h).round() as u64;
    let n = agents.len();
    let (tx, rx) = mpsc::channel::<Report>();
    let scenario_ref = &scenario;
    let mut findings = Findings::new();
    let mut sync_lat = Vec::new();
    let mut state_lat = Vec::new();
    let mut periods = 0u64;
    let outcome = std::thread::scope(|sc| {
        let mut handles = Vec::with_capacity(n);
        for (index, (agent, node)) in agents.into_iter().zip(nodes).enumerate() {
            let task_tx = tx.clone();
            let id = agent.id();
            handles.push(start(sc, &mut clock, Task::Vehicle(id), move || {
                vehicle_task(index, agent, node, scenario_ref, total, &task_tx)
            })?);
        }
        drop(tx);
        let mut published: HashMap<u16, SystemTime> = HashMap::new();
        let mut last_sync_tx: Option<SystemTime> = None;
        let mut truths: Vec<Option<Truth>> = vec![None; n];
        let mut rows: Vec<Option<TraceRow>> = vec![None; n];
        let mut result = Ok(());
        'periods: for k in 0..=total {
            let mut next_published = HashMap::with_capacity(n);
            for _ in 0..n {
                match rx.recv_timeout(TIMEOUT) {
                    Ok(Report::Ready {
                        index,
                        id,
                        period,
                        truth,
                        row,
                        published: at,
                        heard,
                        sync_rx,
                    }) if period == k => {
                        if let Some(slot) = truths.get_mut(index) {
                            *slot = Some(truth);
                        }
                        if let Some(slot) = rows.get_mut(index) {
                            *slot = row;
                        }
                        for (sender, rx_at) in heard {
                            if let Some(sent) = published.get(&sender) {
                                state_lat.push(micros(*sent, rx_at));
                            }
                        }
                        if let (Some(s), Some(r)) = (last_sync_tx, sync_rx) {
                            sync_lat.push(micros(s, r));
                        }
                        next_published.insert(id, at);
                    }
                    Ok(Report::Ready { id, period, .. }) => {
                        result = Err(FleetError::Vehicle {
                            id,
                            error: format!("reported period {period} in period {k}"),
                        });
                        break 'periods;
                    }
                    Ok(Report::Failed { id, error }) => {
                        result = Err(FleetError::Vehicle { id, error });
                        break 'periods;
                    }
                    Err(_) => {
                        result = Err(FleetError::Timeout { period: k });
                        break 'periods;
                    }
                }
            }
            published = next_published;
            if k > 0 {
                for r in rows.iter().flatten() {
                    trace(r);
                }
                let t: Vec<Truth> = truths.iter().flatten().copied().collect();
                findings.check(&lim, &t, scenario_ref.road.end_x, scenario_ref.road.lanes);
            }
            progress(k, total);
            match sync(&mut clock, k, k == total) {
                Ok(at) => last_sync_tx = Some(at),
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
            periods += 1;
        }
        if result.is_err() {
            let _ = end(&mut clock, periods as u32);
        }
        let done = join(handles, &mut result);
        result.map(|()| done)
    })?;
    let mut counters = Counters::default();
    let mut can = CanStats::default();
    let mut agents = Vec::with_capacity(outcome.len());
    for (a, c, s) in outcome {
        counters.add(&c);
        can.add(&s);
        agents.push(a);
    }
    let run = summarize(
        &scenario,
        &agents,
        &Outcome {
            findings: &findings,
            counters: &counters,
            t: total as f64 * h,
            steps_done: total,
            bus_faults: Default::default(),
            solver,
            seed,
            wall_seconds: t0.elapsed().as_secs_f64(),
        },
    );
    Ok(FleetSummary {
        run,
        medium: medium.to_string(),
        tasks: agents.len(),
        periods,
        can,
        state_latency: Latency::of(state_lat),
        sync_latency: Latency::of(sync_lat),
    })
}

pub(crate) fn micros(from: SystemTime, to: SystemTime) -> f64 {
    to.duration_since(from)
        .map_or(0.0, |d| d.as_secs_f64() * 1e6)
}

/// Whose task a thread runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Task {
    /// Vehicle `id`'s.
    Vehicle(u16),
    /// The intersection manager's.
    Manager,
}

/// Starts `who`'s task in `scope`; if the system refuses a thread, tells the tasks
/// already started to stop (a last SYNC) and answers the error.
pub(crate) fn start<'scope, T: Send + 'scope, P: CanPort>(
    scope: &'scope std::thread::Scope<'scope, '_>,
    clock: &mut CanNode<P>,
    who: Task,
    task: impl FnOnce() -> T + Send + 'scope,
) -> Result<std::thread::ScopedJoinHandle<'scope, T>, FleetError> {
    let name = match who {
        Task::Vehicle(id) => format!("vehicle-{id}"),
        Task::Manager => "manager".to_string(),
    };
    std::thread::Builder::new()
        .name(name)
        .spawn_scoped(scope, task)
        .map_err(|e| {
            let _ = end(clock, 0);
            let error = format!("cannot start its task: {e}");
            match who {
                Task::Vehicle(id) => FleetError::Vehicle { id, error },
                Task::Manager => FleetError::Harness(format!("the manager: {error}")),
            }
        })
}

/// Waits for every task; their results, and the first failure in `result` (unless it
/// already holds one).
pub(crate) fn join<T>(
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
pub(crate) fn sync<P: CanPort>(
    clock: &mut CanNode<P>,
    period: u64,
    last: bool,
) -> Result<SystemTime, FleetError> {
    // The master's own port hears the fleet on a hub; nothing else reads it (a failed
    // read only leaves frames queued there).
    let _ = clock.drain(|_| {});
    let at = SystemTime::now();
    let tick = wire::Message::Sync {
        period: period as u32,
        last,
    };
    clock.send_wire(&tick).map_err(FleetError::Can)?;
    Ok(at)
}

/// Tells every task to stop (a last SYNC after `period`).
pub(crate) fn end<P: CanPort>(clock: &mut CanNode<P>, period: u32) -> Result<(), CanError> {
    clock.send_wire(&wire::Message::Sync {
        period: period.saturating_add(1),
        last: true,
    })
}

/// One vehicle: publish, wait for SYNC, plan, move, publish, report — until the last SYNC.
fn vehicle_task<const N: usize, P: CanPort>(
    index: usize,
    mut agent: Agent<N>,
    mut node: CanNode<P>,
    scenario: &Scenario,
    total: u64,
    tx: &mpsc::Sender<Report>,
) -> Result<TaskResult<N>, FleetError> {
    let id = agent.id();
    let fail = |error: String| {
        let _ = tx.send(Report::Failed {
            id,
            error: error.clone(),
        });
        FleetError::Vehicle { id, error }
    };
    let lim = Limits::table_i();
    let h = lim.h;
    let road = road_of(scenario);
    let mut counters = Counters::default();
    let mut inbox: Vec<Received> = Vec::new();
    let mut row = None;
    let mut heard = Vec::new();
    let mut sync_rx = None;
    // Each vehicle's place in the scenario, for taking a period's messages in that order.
    let order: HashMap<u16, usize> = scenario
        .vehicles
        .iter()
        .enumerate()
        .map(|(i, v)| (v.id, i))
        .collect();
    for k in 0..=total {
        // Publish the state at kh, then report it (truth for the monitor).
        let t = k as f64 * h;
        let published = SystemTime::now();
        node.send(&Message::State(agent.state(t)))
            .map_err(|e| fail(e.to_string()))?;
        let report = Report::Ready {
            index,
            id,
            period: k,
            truth: agent.truth(),
            row: row.take(),
            published,
            heard: std::mem::take(&mut heard),
            sync_rx: sync_rx.take(),
        };
        if tx.send(report).is_err() {
            return Err(fail("the harness is gone".into()));
        }
        // Everything before SYNC(k) is what the others published for kh.
        inbox.clear();
        let deadline = Instant::now() + TIMEOUT;
        let last = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(fail(format!("no SYNC for period {k} within {TIMEOUT:?}")));
            }
            match node.poll(left).map_err(|e| fail(e.to_string()))? {
                Polled::Nothing | Polled::Frame => {}
                Polled::Message(wire::Message::Sync { period, last }, at) => {
                    if last {
                        break true;
                    }
                    if u64::from(period) != k {
                        return Err(fail(format!("SYNC {period} in period {k}")));
                    }
                    sync_rx = Some(at);
                    break false;
                }
                Polled::Message(m, at) => {
                    if let wire::Message::State(s) = m {
                        heard.push((s.id, at));
                    }
                    if let Some(msg) = crate::can::from_wire(&m) {
                        inbox.push(Received { msg, at: t });
                    }
                }
            }
        };
        if last || k == total {
            break;
        }
        // Take the period's messages in scenario order, as the in-process bus delivers
        // them, whatever order the tasks' frames interleaved in: the run is then
        // independent of thread timing.
        inbox.sort_by_key(|r| order.get(&r.msg.subject().0).copied().unwrap_or(usize::MAX));
        let ctx = StepCtx {
            t,
            steps_done: k,
            road,
            lim,
            silent: None,
        };
        let ((v, w), r) = agent.decide(&ctx, &inbox, &mut counters);
        agent.advance(v, w, h);
        agent.check_goal((k + 1) as f64 * h);
        row = Some(r);
    }
    let stats = node.stats().clone();
    Ok((agent, counters, stats))
}
