//! An intersection scenario as a fleet on a CAN medium: every vehicle's crossing planner
//! runs in its own task with its own CAN node, and so does the intersection manager
//! (source address [`MANAGER_ADDRESS`]); they hear each other only through can-gateway
//! frames — vehicles broadcast `Request`s (route as inlet and outlet tracks, arrival,
//! position, speed) and, once gone, `Exit`s; the manager broadcasts `Grant` leases.
//!
//! The time master ticks twice per period k, so that each period holds the in-process
//! simulator's two exchanges (reports → manager → grants → plans):
//!
//! 1. every vehicle has published its `Request` for kh; the master sends SYNC(2k);
//! 2. the manager takes the requests that preceded SYNC(2k), decides, publishes its
//!    grants (lease until kh + [`LEASE_S`]) and tells the harness; the master sends
//!    SYNC(2k+1);
//! 3. every vehicle takes what preceded SYNC(2k+1) (the others' requests, the grants,
//!    exits), plans, drives one period along its path, publishes its `Request` for
//!    (k+1)h and reports its true state to the harness, whose independent monitor
//!    checks every period.
//!
//! As with road fleets the run is lock-step and repeatable; what differs from the
//! in-process run is that every report went through the codec (positions 0.01 m, speeds
//! 0.02 m/s), which the manager and the planners allow for
//! ([`Manager::set_position_resolution`], `CrossingPlanner::set_bus_resolution`).

use crate::bus::{Message, Received};
use crate::can::{report_from_wire, report_to_wire, CanError, CanNode, CanPort, CanStats, Polled};
use crate::fleet::{
    end, join, micros, opener, start, sync, FleetError, Latency, Medium, Task, TIMEOUT,
};
use crate::intersection::{
    manage, params, summarize, Car, CarTruth, CrossingMonitor, CrossingScenario, CrossingSummary,
    PoseSample, LEASE_S, LEFT_REPEAT_S, MANAGER_CAP, MANAGER_NODE,
};
use crate::monitor::Limits;
use can_gateway::wire::{self, CLOCK_ADDRESS, MANAGER_ADDRESS};
use planner_core::crossing::Manager;
use planner_core::intersection::Layout;
use planner_core::Params;
use serde::Serialize;
use std::collections::HashMap;
use std::io;
use std::sync::mpsc;
use std::time::{Instant, SystemTime};

/// What an intersection fleet run produced (the `--json` summary of `run --bus`).
#[derive(Debug, Clone, Serialize)]
pub struct CrossingFleetSummary {
    /// The run, as the in-process simulator reports it.
    #[serde(flatten)]
    pub run: CrossingSummary,
    /// The medium (`socketcan:vcan0`, `can-hub`).
    pub medium: String,
    /// Tasks: one per vehicle, plus the manager.
    pub tasks: usize,
    /// Periods run (each of two SYNC ticks).
    pub periods: u64,
    /// SYNC ticks sent.
    pub sync_ticks: u64,
    /// Messages the vehicles and the manager sent.
    pub messages: Messages,
    /// Every node's CAN traffic (vehicles and manager), summed.
    pub can: CanStats,
    /// Requests: publication (before the first frame is written) to the receiving
    /// socket's time stamp of the last frame, at the manager and at every vehicle.
    pub request_latency: Latency,
    /// Grants: publication by the manager to each vehicle's receive stamp.
    pub grant_latency: Latency,
    /// SYNC: written by the master to received by the node that acts on it.
    pub sync_latency: Latency,
}

/// Messages of an intersection fleet run, by kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Messages {
    /// Vehicles' `Request`s (2 frames each).
    pub requests: u64,
    /// The manager's `Grant`s (1 frame each).
    pub grants: u64,
    /// Vehicles' `Exit`s (1 frame each).
    pub exits: u64,
}

/// A task's report to the harness.
enum Report {
    /// A vehicle published what it had to for `period` (its request while in the
    /// system, its exit while repeating it).
    Vehicle {
        index: usize,
        period: u64,
        /// Its true state at the period's start; `None` once it has crossed.
        truth: Option<CarTruth>,
        /// It crossed in the previous period, after this long (s).
        crossed: Option<f64>,
        /// The previous decision applied the certified fallback.
        fallback: bool,
        /// It sent an `Exit` this period.
        exit: bool,
        /// When its request for `period` was published.
        published: Option<SystemTime>,
        /// Requests heard in the previous period: (sender, receive stamp).
        requests_rx: Vec<(u16, SystemTime)>,
        /// Receive stamps of the grants heard in the previous period.
        grants_rx: Vec<SystemTime>,
        /// Receive stamp of the SYNC(2k−1) it planned on.
        sync_rx: Option<SystemTime>,
    },
    /// The manager granted `granted` for `period`.
    Manager {
        period: u64,
        granted: Vec<u16>,
        published: SystemTime,
        requests_rx: Vec<(u16, SystemTime)>,
        sync_rx: SystemTime,
    },
    Failed {
        id: u16,
        error: String,
    },
}

/// Runs an intersection scenario (faults are not injected: the scenario's `[faults]`
/// must be empty, the caller checks) as a fleet on `medium`; `sample` sees every
/// vehicle's pose each period, `progress` (period, periods).
pub fn run(
    sc: &CrossingScenario,
    medium: &Medium,
    sample: &mut dyn FnMut(f64, &[PoseSample]),
    progress: &mut dyn FnMut(u64, u64),
) -> Result<CrossingFleetSummary, FleetError> {
    run_with_ports(sc, &medium.to_string(), opener(medium), sample, progress)
}

/// [`run`] on ports from `open`: `open(Some(id))` for vehicle `id`'s node,
/// `open(Some(MANAGER_NODE))` for the manager's, `open(None)` for the time master's.
pub fn run_with_ports<P: CanPort + 'static>(
    sc: &CrossingScenario,
    medium: &str,
    mut open: impl FnMut(Option<u16>) -> io::Result<P>,
    sample: &mut dyn FnMut(f64, &[PoseSample]),
    progress: &mut dyn FnMut(u64, u64),
) -> Result<CrossingFleetSummary, FleetError> {
    let params = params(sc.layout.spec.v_limit);
    let mut lim = Limits::table_i();
    lim.v_max = sc.layout.spec.v_limit;
    let h = lim.h;
    let (pos_res, _) = crate::can::RESOLUTION;
    let mut cars = Vec::with_capacity(sc.placements.len());
    for p in &sc.placements {
        let mut car = Car::new(&params, p, params.h());
        car.set_bus_resolution(pos_res)
            .map_err(|e| FleetError::Harness(format!("bus resolution: {e:?}")))?;
        cars.push(car);
    }
    let mut manager = Manager::<f64, MANAGER_CAP>::new(sc.layout.clone(), sc.algorithm);
    manager
        .set_position_resolution(pos_res)
        .map_err(|e| FleetError::Harness(format!("bus resolution: {e:?}")))?;
    // Every socket is open before anyone transmits, so that no node misses a frame.
    let mut clock = CanNode::new(CLOCK_ADDRESS, open(None).map_err(CanError::Io)?);
    let manager_node = CanNode::new(
        MANAGER_ADDRESS,
        open(Some(MANAGER_NODE)).map_err(CanError::Io)?,
    );
    let mut nodes = Vec::with_capacity(cars.len());
    for c in &cars {
        let port = open(Some(c.id)).map_err(CanError::Io)?;
        nodes.push(CanNode::vehicle(c.id, port)?);
    }
    // Messages of a period are taken in scenario order (the in-process bus's order),
    // whatever order the tasks' frames interleaved in.
    let order: HashMap<u16, usize> = sc
        .placements
        .iter()
        .enumerate()
        .map(|(i, p)| (p.id, i))
        .collect();
    let total = (sc.duration_s / h).round() as u64;
    let n = cars.len();
    let (tx, rx) = mpsc::channel::<Report>();
    let mut monitor = CrossingMonitor::default();
    let mut times = Vec::new();
    let mut fallback_steps = 0u64;
    let mut messages = Messages::default();
    let (mut req_lat, mut grant_lat, mut sync_lat) = (Vec::new(), Vec::new(), Vec::new());
    let (mut periods, mut ticks) = (0u64, 0u64);
    let mut in_system = n;
    let layout = &sc.layout;
    let params = &params;
    let order = &order;
    let outcome = std::thread::scope(|scope| {
        let mut handles = Vec::with_capacity(n + 1);
        let manager_tx = tx.clone();
        handles.push(start(scope, &mut clock, Task::Manager, move || {
            manager_task(manager, manager_node, order, total, &manager_tx)
        })?);
        for (index, (car, node)) in cars.into_iter().zip(nodes).enumerate() {
            let task_tx = tx.clone();
            handles.push(start(
                scope,
                &mut clock,
                Task::Vehicle(car.id),
                move || vehicle_task(index, car, node, layout, params, order, total, &task_tx),
            )?);
        }
        drop(tx);
        let mut request_sent: HashMap<u16, SystemTime> = HashMap::new();
        let mut grants_sent: Option<SystemTime> = None;
        let mut last_tick_tx: Option<SystemTime> = None;
        let mut result = Ok(());
        'periods: for k in 0..=total {
            let t = k as f64 * h;
            let mut truths: Vec<(usize, CarTruth)> = Vec::with_capacity(n);
            let mut next_sent = HashMap::with_capacity(n);
            for _ in 0..n {
                match rx.recv_timeout(TIMEOUT) {
                    Ok(Report::Vehicle {
                        index,
                        period,
                        truth,
                        crossed,
                        fallback,
                        exit,
                        published,
                        requests_rx,
                        grants_rx,
                        sync_rx,
                    }) if period == k => {
                        if let Some(tr) = truth {
                            truths.push((index, tr));
                            messages.requests += 1;
                        }
                        if let (Some(at), Some(tr)) = (published, truth) {
                            next_sent.insert(tr.id, at);
                        }
                        times.extend(crossed);
                        fallback_steps += u64::from(fallback);
                        messages.exits += u64::from(exit);
                        for (sender, at) in requests_rx {
                            if let Some(sent) = request_sent.get(&sender) {
                                req_lat.push(micros(*sent, at));
                            }
                        }
                        if let Some(sent) = grants_sent {
                            grant_lat.extend(grants_rx.into_iter().map(|at| micros(sent, at)));
                        }
                        if let (Some(s), Some(r)) = (last_tick_tx, sync_rx) {
                            sync_lat.push(micros(s, r));
                        }
                    }
                    Ok(Report::Vehicle { index, period, .. }) => {
                        result = Err(FleetError::Vehicle {
                            id: sc.placements.get(index).map_or(0, |p| p.id),
                            error: format!("reported period {period} in period {k}"),
                        });
                        break 'periods;
                    }
                    Ok(Report::Manager { period, .. }) => {
                        result = Err(FleetError::Harness(format!(
                            "the manager reported period {period} while the vehicles were \
                             reporting period {k}"
                        )));
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
            request_sent = next_sent;
            truths.sort_by_key(|(i, _)| *i);
            let truths: Vec<CarTruth> = truths.into_iter().map(|(_, c)| c).collect();
            in_system = truths.len();
            if k > 0 {
                monitor.check(layout, &lim, &truths);
            }
            let poses: Vec<PoseSample> = truths.iter().map(|c| pose(layout, c)).collect();
            sample(t, &poses);
            progress(k, total);
            let last = k == total || truths.is_empty();
            // Phase 1: the requests for kh are in; the manager decides.
            let sent_at = match sync(&mut clock, 2 * k, last) {
                Ok(at) => at,
                Err(e) => {
                    result = Err(e);
                    break;
                }
            };
            ticks += 1;
            periods = k;
            if last {
                break;
            }
            match rx.recv_timeout(TIMEOUT) {
                Ok(Report::Manager {
                    period,
                    granted,
                    published,
                    requests_rx,
                    sync_rx,
                }) if period == k => {
                    monitor.granted(&granted);
                    messages.grants += granted.len() as u64;
                    grants_sent = (!granted.is_empty()).then_some(published);
                    for (sender, at) in requests_rx {
                        if let Some(sent) = request_sent.get(&sender) {
                            req_lat.push(micros(*sent, at));
                        }
                    }
                    sync_lat.push(micros(sent_at, sync_rx));
                }
                Ok(Report::Failed { id, error }) => {
                    result = Err(if id == MANAGER_NODE {
                        FleetError::Harness(format!("the manager: {error}"))
                    } else {
                        FleetError::Vehicle { id, error }
                    });
                    break;
                }
                Ok(_) => {
                    result = Err(FleetError::Harness(format!(
                        "a report out of turn while waiting for the manager's period {k}"
                    )));
                    break;
                }
                Err(_) => {
                    result = Err(FleetError::Timeout { period: k });
                    break;
                }
            }
            // Phase 2: the grants are in; the vehicles plan.
            match sync(&mut clock, 2 * k + 1, false) {
                Ok(at) => last_tick_tx = Some(at),
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
            ticks += 1;
        }
        if result.is_err() {
            let _ = end(&mut clock, ticks as u32);
        }
        let mut can = CanStats::default();
        for stats in join(handles, &mut result) {
            can.add(&stats);
        }
        result.map(|()| can)
    })?;
    let run = summarize(
        sc.algorithm,
        periods as f64 * h,
        &times,
        fallback_steps,
        &monitor,
        in_system,
    );
    Ok(CrossingFleetSummary {
        run,
        medium: medium.to_string(),
        tasks: n + 1,
        periods,
        sync_ticks: ticks,
        messages,
        can: outcome,
        request_latency: Latency::of(req_lat),
        grant_latency: Latency::of(grant_lat),
        sync_latency: Latency::of(sync_lat),
    })
}

fn pose(layout: &Layout<f64>, c: &CarTruth) -> PoseSample {
    let path = layout
        .route(usize::from(c.route))
        .map_or(layout.routes[0].path, |r| r.path);
    let q = path.pose_at(c.s);
    (c.id, q.x, q.y, q.theta, c.v)
}

/// What a node heard in one phase, as the simulator's messages at the period's time:
/// requests (as crossing reports on the layout's routes), grants, exits; with the receive
/// stamps of requests and grants (for the latency figures).
#[derive(Debug, Default)]
struct Heard {
    inbox: Vec<Received>,
    requests_rx: Vec<(u16, SystemTime)>,
    grants_rx: Vec<SystemTime>,
}

impl Heard {
    fn take(&mut self, m: wire::Message<f64>, at: SystemTime, t: f64, layout: &Layout<f64>) {
        let msg = match m {
            wire::Message::Request(q) => {
                self.requests_rx.push((q.id, at));
                // A pair that is no route of this layout is not acted on.
                let Some(rep) = report_from_wire(&q, layout) else {
                    return;
                };
                Message::Crossing(rep, t)
            }
            wire::Message::Grant { id, until } => {
                self.grants_rx.push(at);
                Message::Grant { id, until }
            }
            wire::Message::Exit { id, at } => Message::Left { id, at },
            wire::Message::State(_) | wire::Message::Revoke { .. } | wire::Message::Sync { .. } => {
                return
            }
        };
        self.inbox.push(Received { msg, at: t });
    }

    /// The inbox in scenario order (the in-process bus's), whatever order the tasks'
    /// frames interleaved in.
    fn in_order(&mut self, order: &HashMap<u16, usize>) -> &[Received] {
        self.inbox
            .sort_by_key(|r| order.get(&r.msg.subject().0).copied().unwrap_or(usize::MAX));
        &self.inbox
    }
}

/// Reads frames until the SYNC tick `want` (skipping the other phase's tick `skip`),
/// taking every other verified message into `heard` as of time `t`. `Ok(None)` on the
/// last tick (the run ends), else the tick's receive stamp.
fn await_tick<P: CanPort>(
    node: &mut CanNode<P>,
    (want, skip): (u64, Option<u64>),
    heard: &mut Heard,
    t: f64,
    layout: &Layout<f64>,
) -> Result<Option<SystemTime>, String> {
    let deadline = Instant::now() + TIMEOUT;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(format!("no SYNC {want} within {TIMEOUT:?}"));
        }
        match node.poll(left).map_err(|e| e.to_string())? {
            Polled::Nothing | Polled::Frame => {}
            Polled::Message(wire::Message::Sync { period, last }, at) => {
                if last {
                    return Ok(None);
                }
                match u64::from(period) {
                    p if p == want => return Ok(Some(at)),
                    p if Some(p) == skip => {}
                    p => return Err(format!("SYNC {p} while waiting for SYNC {want}")),
                }
            }
            Polled::Message(m, at) => heard.take(m, at, t, layout),
        }
    }
}

/// The intersection manager's task: per period, the requests and exits that preceded
/// SYNC(2k), the decision, the grants.
fn manager_task<P: CanPort>(
    mut manager: Manager<f64, MANAGER_CAP>,
    mut node: CanNode<P>,
    order: &HashMap<u16, usize>,
    total: u64,
    tx: &mpsc::Sender<Report>,
) -> Result<CanStats, FleetError> {
    let fail = |error: String| {
        let _ = tx.send(Report::Failed {
            id: MANAGER_NODE,
            error: error.clone(),
        });
        FleetError::Harness(format!("the manager: {error}"))
    };
    let h = Limits::table_i().h;
    let layout = manager.layout().clone();
    for k in 0..=total {
        let t = k as f64 * h;
        let mut heard = Heard::default();
        // SYNC(2k): every vehicle's request for kh is in (SYNC(2k−1) ended phase 2).
        let tick = (2 * k, (2 * k).checked_sub(1));
        let Some(sync_rx) = await_tick(&mut node, tick, &mut heard, t, &layout).map_err(fail)?
        else {
            break;
        };
        let granted = manage(&mut manager, heard.in_order(order), t);
        let published = SystemTime::now();
        for &id in &granted {
            let lease = wire::Message::Grant {
                id,
                until: t + LEASE_S,
            };
            node.send_wire(&lease).map_err(|e| fail(e.to_string()))?;
        }
        let report = Report::Manager {
            period: k,
            granted,
            published,
            requests_rx: heard.requests_rx,
            sync_rx,
        };
        if tx.send(report).is_err() {
            return Err(fail("the harness is gone".into()));
        }
    }
    Ok(node.stats().clone())
}

/// One vehicle: publish its request (or exit), report, wait for SYNC(2k+1), hear, plan,
/// drive — until the last SYNC.
#[allow(clippy::too_many_arguments)]
fn vehicle_task<P: CanPort>(
    index: usize,
    mut car: Car,
    mut node: CanNode<P>,
    layout: &Layout<f64>,
    params: &Params<f64>,
    order: &HashMap<u16, usize>,
    total: u64,
    tx: &mpsc::Sender<Report>,
) -> Result<CanStats, FleetError> {
    let id = car.id;
    let fail = |error: String| {
        let _ = tx.send(Report::Failed {
            id,
            error: error.clone(),
        });
        FleetError::Vehicle { id, error }
    };
    let h = Limits::table_i().h;
    let mut gone_at: Option<f64> = None;
    let (mut crossed, mut fallback) = (None, false);
    let (mut heard, mut sync_rx) = (Heard::default(), None);
    for k in 0..=total {
        let t = k as f64 * h;
        // Publish: the request while in the system, then `Exit` for LEFT_REPEAT_S.
        let mut published = None;
        let mut exit = false;
        match gone_at {
            None => {
                published = Some(SystemTime::now());
                let req = report_to_wire(&car.report(), car.arrived_at().unwrap_or(t), layout)
                    .map_err(|e| fail(e.to_string()))?;
                node.send_wire(&req).map_err(|e| fail(e.to_string()))?;
            }
            Some(at) if t < at + LEFT_REPEAT_S => {
                exit = true;
                node.send_wire(&wire::Message::Exit { id, at })
                    .map_err(|e| fail(e.to_string()))?;
            }
            Some(_) => {}
        }
        let report = Report::Vehicle {
            index,
            period: k,
            truth: gone_at.is_none().then(|| car.truth()),
            crossed: crossed.take(),
            fallback: std::mem::take(&mut fallback),
            exit,
            published,
            requests_rx: std::mem::take(&mut heard.requests_rx),
            grants_rx: std::mem::take(&mut heard.grants_rx),
            sync_rx: sync_rx.take(),
        };
        if tx.send(report).is_err() {
            return Err(fail("the harness is gone".into()));
        }
        // Everything before SYNC(2k+1): the others' requests for kh, the grants, exits.
        heard.inbox.clear();
        let tick = (2 * k + 1, Some(2 * k));
        let Some(rx_at) = await_tick(&mut node, tick, &mut heard, t, layout).map_err(fail)? else {
            break;
        };
        sync_rx = Some(rx_at);
        if k == total || gone_at.is_some() {
            continue;
        }
        for r in heard.in_order(order) {
            car.hear(&r.msg);
        }
        let (v, fell_back) = car.decide(layout, params, t);
        fallback = fell_back;
        car.advance(v, h);
        crossed = car.crossed(layout, t + h);
        if crossed.is_some() {
            gone_at = Some(t + h);
        }
    }
    Ok(node.stats().clone())
}
