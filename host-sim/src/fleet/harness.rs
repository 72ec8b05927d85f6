//! The harness: what runs beside the tasks and sees ground truth — the monitors, the
//! sensors, the trace and the tally of what the tasks reported.

use super::can::{CanPort, Keys};
use super::intruder::{Attack, Intruder, INTRUDER_ADDRESS};
use crate::monitor::Limits;
use crate::world::junction::ManagerNode;
use crate::world::network::Network;
use crate::world::vehicle::PlannerSetup;
use crate::world::{SolverChoice, WorldSpec};
use std::sync::Arc;
use std::time::SystemTime;

use super::summary::FleetError;
use super::tasks::Kind;
use super::{micros, Fleet, ATTACK_FROM_S};

/// The fleet's harness: the time master, the monitors, the summary.
pub(super) struct Harness<const N: usize> {
    pub(super) spec: WorldSpec,
    pub(super) solver: SolverChoice,
    pub(super) seed: u64,
    pub(super) lim: Limits,
    pub(super) keys: Option<Arc<Keys>>,
    pub(super) fd: bool,
    pub(super) attack: Option<Attack>,
}

/// The latencies and counts the harness gathers.
#[derive(Default)]
pub(super) struct Tally {
    pub(super) state: Vec<f64>,
    pub(super) request: Vec<f64>,
    pub(super) grant: Vec<f64>,
    pub(super) sync: Vec<f64>,
    pub(super) grants: u64,
    pub(super) exits: u64,
    pub(super) ticks: u64,
    /// Grants managers sent while down (`[faults.manager_down]`).
    pub(super) grants_while_down: u64,
}

impl Tally {
    pub(super) fn heard(
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
    pub(super) fn new(spec: WorldSpec, fleet: Fleet) -> Self {
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

    /// What its planners assume of vehicles that do not say.
    fn fleet(&self) -> crate::world::Fleet {
        self.spec.fleet()
    }

    pub(super) fn setup(&self) -> PlannerSetup {
        let fleet = self.fleet();
        PlannerSetup {
            solver: self.solver,
            // Lock-step: every message of period k is heard in period k.
            notify: self.lim.h,
            resolution: super::can::RESOLUTION,
            sensing: self.spec.sensing,
            reuse: None,
            precision: self.spec.precision,
            relevant_m: crate::world::heard::relevance_radius(
                &self.spec.network,
                self.lim.v_max,
                fleet,
            ),
            invariant: self.spec.invariant,
            fleet,
        }
    }

    /// The intruder of `attack` on `port`, with its own address's key if the fleet
    /// authenticates.
    pub(super) fn intruder<P: CanPort>(&self, attack: Attack, port: P) -> Intruder<P> {
        let key = self
            .keys
            .as_ref()
            .and_then(|k| k.get(INTRUDER_ADDRESS).copied());
        let from = (ATTACK_FROM_S / self.lim.h).round() as u64;
        Intruder::new(attack, port, key, self.fd, from)
    }

    /// Every junction's manager, at the bus's position resolution.
    pub(super) fn managers(&self, net: &Network) -> Result<Vec<ManagerNode>, FleetError> {
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
            m.set_resolution(super::can::RESOLUTION)
                .map_err(|e| FleetError::Harness(format!("bus resolution: {e:?}")))?;
        }
        Ok(managers)
    }
}
