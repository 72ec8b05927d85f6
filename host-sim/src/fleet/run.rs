//! A fleet's run from start to end: its nodes opened, its tasks spawned, the time master
//! pacing them period by period, and the summary once every task is back.

use super::can::{CanError, CanPort, WireMap};
use super::harness::Harness;
use super::ledger::Ledger;
use super::master::{Master, MasterParts, Nodes};
use super::summary::{FleetError, FleetSummary, Latency};
use super::tasks::{end, Ran, Report, TaskCtx, Tasks};
use super::Node;
use crate::bus::Clock;
use crate::world::network::Network;
use crate::world::summary::{summarize, Outcome};
use crate::world::vehicle::build_vehicle;
use crate::world::vehicle::Vehicle;
use crate::world::TraceRow;
use std::io;
use std::sync::mpsc;
use std::sync::Arc;
use std::time::Instant;

impl<const N: usize> Harness<N> {
    /// Opens every node, runs the tasks and the time master to the end, and sums up.
    pub(super) fn run<P: CanPort + 'static>(
        self,
        medium: &str,
        mut open: impl FnMut(Node) -> io::Result<P>,
        trace: &mut dyn FnMut(&TraceRow),
    ) -> Result<FleetSummary, FleetError> {
        let t0 = Instant::now();
        let net = self.spec.network.clone();
        let map = WireMap::new(&net).for_fleet(self.setup().fleet);
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

    /// The fleet's summary: the world's summary of the vehicles the tasks handed back,
    /// and the bus's figures.
    pub(super) fn summary(
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
                // Not classified on a fleet (a silent node's neighbours left waiting count
                // as unfinished, with no reason given): the in-process world gives it.
                held_by_silent: 0,
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
