//! The world's period, its phases in order (the module docs of [`super`] list them):
//! broadcast, manage, sense, each vehicle's period (`super::period`), departures
//! (`super::handover`), arrivals (`super::spawn`), the monitors (`super::watch`) and the
//! liveness watch. Each phase is a function here or in the file named; this one only
//! runs them.

use super::junction::ManagerNode;
use super::sensor::{roadside, sense_each, Seen, Sensed};
use super::vehicle::{StepCtx, Vehicle, VehicleTruth};
use super::{TraceRow, World};
use crate::bus::{Bus, BusError, Message, Received};
use crate::monitor::liveness::{Deadlock, WaitsOn};

impl<const N: usize, B: Bus> World<N, B> {
    /// Simulates one period h; `trace` sees a row per vehicle.
    pub fn step(&mut self, trace: &mut dyn FnMut(&TraceRow)) -> Result<(), BusError> {
        let t = self.time.t;
        let h = self.lim.h;
        self.broadcast(t)?;
        self.manage(t)?;
        let sensed = self.sense_all();
        let mut moves = Vec::with_capacity(self.vehicles.len());
        let mut early = self.tick_computers(t)?;
        let mut inbox: Vec<Received> = Vec::new();
        for (i, v) in self.vehicles.iter_mut().enumerate() {
            inbox.clear();
            match early.get_mut(i) {
                Some(e) => std::mem::swap(&mut inbox, e),
                None => self.bus.receive(v.id, t, &mut inbox)?,
            }
            let empty = Sensed::default();
            let ctx = StepCtx {
                t,
                now: self.time.clock.at_step(self.time.steps_done),
                clock: self.time.clock,
                steps_done: self.time.steps_done,
                net: &self.net,
                lim: self.lim,
                silent: self.spec.faults.silent,
                liar: self.spec.faults.liar,
                returns: sensed.get(i).unwrap_or(&empty),
            };
            let t0 = self.tally.costs.is_some().then(std::time::Instant::now);
            let (row, moved) = v.period(&ctx, &inbox, &mut self.tally.counters);
            if let (Some(c), Some(t0), true) = (&mut self.tally.costs, t0, v.is_planner()) {
                c.add(t0.elapsed().as_nanos() as u64);
            }
            moves.push(moved);
            trace(&row);
        }
        self.time.steps_done += 1;
        self.time.t = self.time.steps_done as f64 * h;
        self.hand_over(&moves)?;
        self.arrive()?;
        let truths: Vec<VehicleTruth> = self.vehicles.iter().map(|v| v.truth(&self.net)).collect();
        self.watch.monitor.check(&self.lim, &self.net, &truths);
        self.watch_liveness(&truths);
        Ok(())
    }

    /// Phase 1: the vehicles that left a junction or the network repeat it; every vehicle
    /// broadcasts.
    fn broadcast(&mut self, t: f64) -> Result<(), BusError> {
        let bus = &mut self.bus;
        let live = &self.vehicles;
        self.insertion.departing.retain(|&(id, _, _, until)| {
            let keep = t < until;
            // Its last word said, a vehicle gone from the world leaves the bus too.
            if !keep && !live.iter().any(|v| v.id == id) {
                bus.detach(id);
            }
            keep
        });
        for &(id, from, at, _) in &self.insertion.departing {
            let at = self.time.clock.at_secs(at);
            self.bus.send(id, &Message::departure(id, at, from), t)?;
        }
        let now = self.time.clock.at_step(self.time.steps_done);
        for v in &self.vehicles {
            let (x, y) = v.position(&self.net);
            self.bus.locate(v.id, x, y);
        }
        // Every computer in the loop told first, so that their images work at once.
        for v in &mut self.vehicles {
            v.tell_computer(now, &self.net);
        }
        for v in &mut self.vehicles {
            let msg = v.broadcast(now);
            let msg = self.spec.faults.told(v.id, msg, t);
            self.bus.send(v.id, &msg, t)?;
        }
        self.tally.messages_sent += self.vehicles.len() as u64;
        Ok(())
    }

    /// Phase 4's first half where computers are in the loop: every vehicle's deliveries
    /// taken now, and each computer given its own and the tick, so that their images plan
    /// at once; the deliveries, in the vehicles' order (empty when no computer is in the
    /// loop: each vehicle then takes its own in turn).
    fn tick_computers(&mut self, t: f64) -> Result<Vec<Vec<Received>>, BusError> {
        if !self.vehicles.iter().any(Vehicle::in_the_loop) {
            return Ok(Vec::new());
        }
        let mut all = Vec::with_capacity(self.vehicles.len());
        for v in &mut self.vehicles {
            let mut inbox = Vec::new();
            self.bus.receive(v.id, t, &mut inbox)?;
            v.tick_computer(&inbox);
            all.push(inbox);
        }
        Ok(all)
    }

    /// Phase 2: every manager hears its junction's reports, decides, and grants leases.
    fn manage(&mut self, t: f64) -> Result<(), BusError> {
        let mut inbox = Vec::new();
        let now = self.time.clock.at_step(self.time.steps_done);
        let seen: Vec<Seen> = if self.managers.iter().any(ManagerNode::has_roadside) {
            self.vehicles.iter().map(Vehicle::seen).collect()
        } else {
            Vec::new()
        };
        let error = self.spec.sensing.map_or(0.0, |s| s.position_error_m);
        for m in &mut self.managers {
            inbox.clear();
            self.bus.receive(m.node(), t, &mut inbox)?;
            if !m.is_up(&self.spec.faults, t) {
                continue;
            }
            let readings = if m.has_roadside() {
                roadside(
                    &self.net,
                    m.junction,
                    &seen,
                    error,
                    &mut self.draws.roadside,
                )
            } else {
                Vec::new()
            };
            let granted = m.manage(&inbox, &readings, now);
            self.watch.monitor.granted(m.junction, &granted);
            for id in granted {
                let g = m.grant(id, now);
                self.bus.send(m.node(), &g, t)?;
            }
        }
        Ok(())
    }

    /// Phase 3: every vehicle's sensor returns (planners only with sensors; scripted and
    /// random drivers always see what is in their lane ahead).
    fn sense_all(&mut self) -> Vec<Sensed> {
        let any_script = self.vehicles.iter().any(|v| !v.is_planner());
        if self.spec.sensing.is_none() && !any_script {
            return Vec::new();
        }
        let all: Vec<Seen> = self.vehicles.iter().map(Vehicle::seen).collect();
        let each = all
            .iter()
            .zip(&self.vehicles)
            .map(|(me, v)| Some((*me, v.is_planner())));
        let sensing = self.spec.sensing.as_ref();
        sense_each(&self.net, &all, each, sensing, &mut self.draws.rng)
    }

    /// Phase 6, liveness: the deadlock detector on the period's `truths` (the monitors'
    /// own), and its report when it fires.
    fn watch_liveness(&mut self, truths: &[VehicleTruth]) {
        let waiting = self.insertion.streams.iter().any(|s| !s.queue.is_empty())
            || !self.insertion.pending.is_empty();
        let holders = |j: usize| super::wait::holders(&self.managers, j);
        if let Some(d) = super::wait::watch(
            &mut self.watch.detector,
            self.time.t,
            truths,
            waiting,
            &self.net,
            &holders,
            &self.lim,
        ) {
            self.watch.deadlock = Some(self.own_silence(d));
        }
    }

    /// Of the vehicles unfinished now (and due), those held up by a silent vehicle when
    /// no deadlock ended the run: what each waits on (as the deadlock report would say it,
    /// from ground truth) names the vehicle whose transmitter is silent — the vehicle
    /// ahead, or one in the lane it must change into, which it knows only by its sensors
    /// and so takes at the wall and, its body unknown, at the fleet's weakest braking
    /// limit (a gap enough for the car it is may not be for the truck it could be).
    pub(super) fn held_by_silent(&self) -> usize {
        let t = self.time.t;
        let silent = self.spec.faults.silent.filter(|s| t >= s.from_s);
        let (Some(s), None) = (silent, &self.watch.deadlock) else {
            return 0;
        };
        let truths: Vec<VehicleTruth> = self.vehicles.iter().map(|v| v.truth(&self.net)).collect();
        let holders = |j: usize| super::wait::holders(&self.managers, j);
        let names = |w: &WaitsOn| match w {
            WaitsOn::Vehicle { id } => *id == s.id,
            WaitsOn::LaneChange { ids } => ids.contains(&s.id),
            _ => false,
        };
        self.vehicles
            .iter()
            .zip(&truths)
            .filter(|(v, _)| v.id != s.id && v.unmet(&self.net) && self.due(v))
            .filter(|(_, truth)| {
                super::wait::waits_on(truth, &truths, &self.net, &holders, &self.lim)
                    .iter()
                    .any(names)
            })
            .count()
    }

    /// `d` with the grant a silent vehicle waits on named for what it is: one it cannot
    /// ask for (its transmitter is silent, a fault the world knows of and the wait-for
    /// relation, built from ground truth and the managers' records, does not).
    fn own_silence(&self, mut d: Deadlock) -> Deadlock {
        let t = self.time.t;
        let Some(s) = self.spec.faults.silent.filter(|s| t >= s.from_s) else {
            return d;
        };
        for w in d.waits.iter_mut().filter(|w| w.id == s.id) {
            for on in &mut w.waits_on {
                if let WaitsOn::Grant { junction, .. } = *on {
                    *on = WaitsOn::OwnSilence { junction };
                }
            }
        }
        d
    }
}
