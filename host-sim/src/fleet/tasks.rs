//! The tasks: each vehicle and each junction manager a thread of its own with its own
//! CAN node, what they report to the harness, and the clock ticks they wait for.

use super::can::{CanError, CanNode, CanPort, CanStats, Polled, WireMap};
use crate::bus::{Clock, Faults, Message, Received};
use crate::monitor::Limits;
use crate::world::handover::Moved;
use crate::world::junction::ManagerNode;
use crate::world::network::Network;
use crate::world::sensor::{sense_each, Seen, Sensed};
use crate::world::vehicle::{Counters, StepCtx, Vehicle, VehicleTruth};
use crate::world::TraceRow;
use can_gateway::wire::{self};
use std::sync::mpsc;
use std::time::{Instant, SystemTime};

use super::summary::{FleetError, Messages};
use super::TIMEOUT;

/// A task's report to the harness.
pub(super) enum Report {
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
pub(super) enum Kind {
    State,
    Request,
    Grant,
    Other,
}

pub(super) fn kind_of(m: &Message) -> Kind {
    match m {
        Message::State { .. } => Kind::State,
        Message::Crossing { .. } => Kind::Request,
        Message::Grant { .. } => Kind::Grant,
        Message::Left { .. } | Message::Gone { .. } => Kind::Other,
    }
}

/// What the harness tells a vehicle task before its planning tick.
pub(super) struct Go {
    pub(super) sensed: Sensed,
}

/// What a vehicle task hands back.
pub(super) type VehicleResult<const N: usize> = (Vehicle<N>, Counters, CanStats, Messages);

/// What the vehicle tasks handed back at the end.
#[derive(Default)]
pub(super) struct Ran<const N: usize> {
    pub(super) cars: Vec<Vehicle<N>>,
    pub(super) counters: Counters,
    pub(super) can: CanStats,
    pub(super) msgs: Messages,
}

/// The running tasks: one per vehicle (with the channel that releases it each period)
/// and one per manager.
pub(super) struct Tasks<'scope, const N: usize> {
    pub(super) vehicles:
        Vec<std::thread::ScopedJoinHandle<'scope, Result<VehicleResult<N>, FleetError>>>,
    pub(super) go: Vec<mpsc::Sender<Go>>,
    pub(super) managers: Vec<std::thread::ScopedJoinHandle<'scope, Result<CanStats, FleetError>>>,
    /// Per manager, its roadside sensor's readings of each period (when it has one).
    pub(super) readings: Vec<mpsc::Sender<Readings>>,
}

/// A roadside sensor's readings of one period: (vehicle, position along its route).
pub(super) type Readings = Vec<(u16, f64)>;

impl<'scope, const N: usize> Tasks<'scope, N> {
    pub(super) fn spawn<'env, P: CanPort + 'static>(
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
    pub(super) fn join(self, result: &mut Result<(), FleetError>) -> Ran<N> {
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

/// Sensor returns for every vehicle task (in index order) from the truths at period k;
/// a vehicle gone gets none. The noise is drawn per period from the seed, so the run is
/// repeatable.
pub(super) fn sense_all(
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
pub(super) struct TaskCtx<'a> {
    pub(super) net: &'a Network,
    pub(super) map: &'a WireMap<'a>,
    pub(super) order: &'a [u16],
    pub(super) total: u64,
    pub(super) with_managers: bool,
    pub(super) lim: Limits,
    /// The nodes' own faults: a silent vehicle, a liar, a manager's outage.
    pub(super) faults: Faults,
    /// Every node's clock.
    pub(super) clock: Clock,
}

/// One vehicle: publish, report, wait for SYNC, plan, move — until the last SYNC.
pub(super) fn vehicle_task<const N: usize, P: CanPort>(
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
        let repeat = crate::world::junction::left_repeat_s(car.log.left_at.is_some());
        if let Some((j, at)) = departing.filter(|&(_, at)| t < at + repeat) {
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
        if moved != Moved::Stays && car.log.left_at.is_some() {
            // Gone from the world (past an exit, or off a junction with no outlet road),
            // it plans nothing more: only SYNC paces it from here on.
            node.hear_only_clock().map_err(|e| fail(e.to_string()))?;
        }
        row = Some(r);
    }
    Ok((car, counters, node.stats().clone(), msgs))
}

/// Vehicle `car`'s message for period `k` — unless its transmitter is silent, and as a
/// liar tells it — counted in `msgs`; its kind, if sent.
pub(super) fn publish<const N: usize, P: CanPort>(
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
pub(super) fn manager_task<P: CanPort>(
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
pub(super) fn await_tick<P: CanPort>(
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
pub(super) fn in_order(inbox: &mut [(Received, u8)], order: &[u16], t: f64) -> Vec<Received> {
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
pub(super) fn spawn<'scope, T: Send + 'scope, P: CanPort>(
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
pub(super) fn join<T>(
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
pub(super) fn tick<P: CanPort>(
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
pub(super) fn end<P: CanPort>(clock: &mut CanNode<P>, period: u32) -> Result<(), CanError> {
    clock.send_wire(&wire::Message::Sync {
        period: period.saturating_add(1),
        last: true,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use planner_core::Instant;

    fn got(msg: Message) -> (Received, u8) {
        (Received { msg, at: 0.0 }, 0)
    }

    /// Whatever order the frames came in, a period's messages are taken as the in-process
    /// bus delivers them: exits first, then by sender in the world's order, grants last
    /// by junction — so a fleet's run repeats the in-process world's.
    #[test]
    fn a_periods_messages_are_taken_in_the_worlds_order() {
        let at = Instant::from_micros(0);
        let grant = |junction, id| Message::Grant {
            junction,
            id,
            until: at,
        };
        let mut inbox = vec![
            got(grant(1, 7)),
            got(grant(0, 9)),
            got(Message::departure(9, at, None)),
            got(grant(0, 7)),
            got(Message::departure(7, at, Some(0))),
        ];
        let order = [7, 9];
        let taken = in_order(&mut inbox, &order, 2.5);
        let want = [
            Message::departure(7, at, Some(0)),
            Message::departure(9, at, None),
            grant(0, 7),
            grant(0, 9),
            grant(1, 7),
        ];
        assert_eq!(taken.iter().map(|r| r.msg).collect::<Vec<_>>(), want);
        assert!(
            taken.iter().all(|r| r.at == 2.5),
            "received at the period's time"
        );
        let kinds: Vec<Kind> = want.iter().map(kind_of).collect();
        assert_eq!(
            kinds,
            [
                Kind::Other,
                Kind::Other,
                Kind::Grant,
                Kind::Grant,
                Kind::Grant
            ]
        );
    }
}
