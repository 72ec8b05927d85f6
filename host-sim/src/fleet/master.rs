//! The time master: the SYNC frames that pace every node, period by period, and the
//! CAN nodes it and the harness hold.

use super::can::{CanError, CanNode, CanPort, Keys, WireMap};
use super::intruder::Intruder;
use super::ledger::Ledger;
use crate::monitor::liveness::DeadlockDetector;
use crate::world::junction::ManagerNode;
use crate::world::sensor::Seen;
use crate::world::vehicle::{Vehicle, VehicleTruth};
use crate::world::watch::WorldMonitor;
use crate::world::TraceRow;
use can_gateway::wire::CLOCK_ADDRESS;
use std::io;
use std::sync::mpsc;
use std::sync::Arc;
use std::time::SystemTime;

use super::harness::{Harness, Tally};
use super::summary::{FleetError, Intrusion};
use super::tasks::{sense_all, tick, Go, Kind, Readings, Report, TaskCtx};
use super::TIMEOUT;
use super::{micros, Node};

/// Every node's CAN port, opened before anyone transmits so that no node misses a frame.
pub(super) struct Nodes<P: CanPort> {
    pub(super) clock: CanNode<P>,
    pub(super) vehicles: Vec<CanNode<P>>,
    pub(super) managers: Vec<CanNode<P>>,
}

impl<P: CanPort> Nodes<P> {
    pub(super) fn open<const N: usize>(
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
    pub(super) fn with_fd(self) -> Self {
        let fd = |v: Vec<CanNode<P>>| v.into_iter().map(CanNode::with_fd).collect();
        Self {
            clock: self.clock.with_fd(),
            vehicles: fd(self.vehicles),
            managers: fd(self.managers),
        }
    }

    /// Every node coding in `precision`.
    pub(super) fn with_precision(self, precision: crate::world::precision::Precision) -> Self {
        let coded =
            |v: Vec<CanNode<P>>| v.into_iter().map(|n| n.with_precision(precision)).collect();
        Self {
            clock: self.clock.with_precision(precision),
            vehicles: coded(self.vehicles),
            managers: coded(self.managers),
        }
    }

    /// Every node telling `ledger` what it sends and accepts.
    pub(super) fn with_ledger(self, ledger: &Arc<Ledger>) -> Self {
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
    pub(super) fn with_keys(self, keys: &Arc<Keys>) -> Self {
        let keyed = |v: Vec<CanNode<P>>| v.into_iter().map(|n| n.with_keys(keys.clone())).collect();
        Self {
            clock: self.clock.with_keys(keys.clone()),
            vehicles: keyed(self.vehicles),
            managers: keyed(self.managers),
        }
    }
}

/// The time master and the harness's view of one run: it collects every task's report
/// for a period, runs the monitors on ground truth, ticks SYNC and hands out sensor
/// returns.
pub(super) struct Master<'a, P: CanPort, const N: usize> {
    pub(super) harness: &'a Harness<N>,
    pub(super) ctx: &'a TaskCtx<'a>,
    pub(super) clock: CanNode<P>,
    pub(super) rx: mpsc::Receiver<Report>,
    pub(super) go: Vec<mpsc::Sender<Go>>,
    /// Per manager, where its roadside sensor's readings go.
    pub(super) readings: Vec<mpsc::Sender<Readings>>,
    /// The roadside sensors' noise, drawn as the in-process world draws it.
    pub(super) roadside_rng: Box<rand_chacha::ChaCha8Rng>,
    pub(super) tally: Tally,
    pub(super) monitor: WorldMonitor,
    pub(super) detector: DeadlockDetector,
    pub(super) deadlock: Option<crate::monitor::liveness::Deadlock>,
    pub(super) periods: u64,
    /// Who published what when in the previous period (for the latencies).
    pub(super) sent: Vec<(u16, SystemTime, Kind)>,
    pub(super) grants_at: Option<SystemTime>,
    pub(super) last_tick: Option<SystemTime>,
    /// Per junction, the permissions its manager holds (for the wait-for relation).
    pub(super) holders: Vec<Vec<(u16, u8)>>,
    /// The attack experiment's intruder, acting before each planning tick.
    pub(super) intruder: Option<Intruder<P>>,
}

/// What the master hands back for the summary.
pub(super) struct MasterParts {
    pub(super) tally: Tally,
    pub(super) findings: crate::monitor::Findings,
    pub(super) deadlock: Option<crate::monitor::liveness::Deadlock>,
    pub(super) periods: u64,
    pub(super) intrusion: Option<Intrusion>,
}

/// One period's vehicle reports, in vehicle order.
pub(super) struct Truths {
    pub(super) truths: Vec<Option<VehicleTruth>>,
    pub(super) rows: Vec<Option<TraceRow>>,
}

impl<'a, P: CanPort, const N: usize> Master<'a, P, N> {
    pub(super) fn new(
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

    pub(super) fn into_parts(self) -> MasterParts {
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
    pub(super) fn periods(&mut self, trace: &mut dyn FnMut(&TraceRow)) -> Result<(), FleetError> {
        for k in 0..=self.ctx.total {
            if self.period(k, trace)? {
                break;
            }
        }
        Ok(())
    }

    /// Period k: the vehicles' reports, the monitors, the managers' turn, the sensor
    /// returns and the planning tick. `Ok(true)` when the run is over.
    pub(super) fn period(
        &mut self,
        k: u64,
        trace: &mut dyn FnMut(&TraceRow),
    ) -> Result<bool, FleetError> {
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
    pub(super) fn roadside(&mut self, k: u64, present: &[VehicleTruth]) {
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
    pub(super) fn observe(&mut self, k: u64, present: &[VehicleTruth]) {
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
    pub(super) fn vehicle_reports(&mut self, k: u64) -> Result<Truths, FleetError> {
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
    pub(super) fn manager_reports(&mut self, k: u64, at: SystemTime) -> Result<(), FleetError> {
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
