//! A junction's manager as a node of the bus (Sec. VI): it hears the vehicles' crossing
//! reports for its junction, decides by its algorithm, and answers every vehicle holding
//! a permission with a lease.

use super::precision::{AnyManager, Precision};
use crate::bus::{Faults, Message, Received};
use planner_core::crossing::Lease;
use planner_core::intersection::Layout;
use planner_core::{ConfigError, Duration, Instant};

/// Vehicles one manager can track.
pub const MANAGER_CAP: usize = 128;
/// Lease of a permission (s) beyond the bus's notification bound: renewed every period
/// while held; 0.1 s lets a few messages go missing before a vehicle that has not yet
/// entered A_S must stop. A lease must outlive its own delivery, hence the bound.
pub const LEASE_S: f64 = 0.1;

/// The leases of a manager on a bus whose notification bound is `notify` (s) over a
/// period `h` (s): valid [`LEASE_S`] past their delivery at the latest, so
/// `LEASE_S + notify − h` after they are sent (planner-core's [`Lease`]; its quiet time
/// at start-up follows from it).
pub fn lease(notify: f64, h: f64) -> Lease {
    let d = |s: f64| Duration::from_secs_real(s).unwrap_or(Duration::ZERO);
    Lease {
        length: d(LEASE_S + (notify - h).max(0.0)),
        notify: d(notify.max(h)),
    }
}
/// How long a vehicle that has left a junction repeats its `Left` message (s): 50
/// periods, so that even at 20 % loss every receiver has it (0.2^50) and drops its last
/// report.
pub const LEFT_REPEAT_S: f64 = 0.5;

/// How long a vehicle that has left the world at an exit repeats its `Left` message (s):
/// 1,000 periods. A vehicle that leaves a junction into a segment goes on broadcasting
/// its state, which replaces its last report in every view; one that leaves the world
/// says nothing else, so a receiver that misses every `Left` keeps its last report, a
/// vehicle it must take to be still there (it may have stopped there, silent), and a
/// follower waits behind it for ever. At 99 % loss 50 repeats miss a receiver with
/// probability 0.99^50 = 0.61 (the fault grid's intersections ended with vehicles
/// stopped on their outlet behind such a ghost); 1,000 miss it with 0.99^1000 < 5e-5.
/// Physically it is the vehicle still in radio range on the road beyond the exit: 10 s
/// at the SPEC's 13.9 m/s is 139 m.
pub const EXIT_REPEAT_S: f64 = 10.0;

/// How long a vehicle that left a junction (`left_world` false: into a segment) or the
/// world repeats its `Left` message (s).
pub fn left_repeat_s(left_world: bool) -> f64 {
    if left_world {
        EXIT_REPEAT_S
    } else {
        LEFT_REPEAT_S
    }
}

pub use crate::bus::manager_node;

/// One junction's manager on the bus.
#[derive(Debug, Clone)]
pub struct ManagerNode {
    /// The junction (index).
    pub junction: usize,
    /// The junction's id in the scenario (what `[faults.manager_down]` names).
    pub junction_id: u16,
    /// The manager.
    pub manager: AnyManager<MANAGER_CAP>,
    /// Its layout (a restart builds the new manager on it).
    layout: Layout<f64>,
    /// It has been restarted (after an outage).
    pub restarted: bool,
    /// The bus's position and speed resolutions it was given (m, m/s): a restart keeps
    /// them, the bus being the same.
    resolution: (f64, f64),
    /// Its roadside sensor's error (m), if it has one: a restart keeps it.
    roadside: Option<f64>,
}

impl ManagerNode {
    /// The manager of the network's junction `junction`, `jn`, running its algorithm in
    /// `precision`, granting leases on the terms `lease` (see [`lease`]).
    pub fn new(
        junction: usize,
        jn: &crate::world::network::Junction,
        (lease, precision): (Lease, Precision),
    ) -> Self {
        let layout = jn.layout.clone();
        let mut manager = AnyManager::new(&layout, jn.algorithm, precision);
        // A zero notification bound or length is refused: keep the defaults then.
        let _ = manager.set_lease(lease);
        Self {
            junction,
            junction_id: jn.id,
            manager,
            layout,
            restarted: false,
            resolution: (0.0, 0.0),
            roadside: None,
        }
    }

    /// Gives it a roadside sensor measuring every vehicle in A_C within ± `error` m (see
    /// planner-core's `Manager::set_roadside_sensor`); `None`: reports alone.
    pub fn set_roadside(&mut self, error: Option<f64>) -> Result<(), ConfigError> {
        self.manager.set_roadside_sensor(error)?;
        self.roadside = error;
        Ok(())
    }

    /// `true` if it has a roadside sensor.
    pub fn has_roadside(&self) -> bool {
        self.roadside.is_some()
    }

    /// Its roadside sensor's readings of this period: (id, centre along the route's path).
    pub fn measure(&mut self, readings: &[(u16, f64)]) {
        for &(id, s) in readings {
            // A suspect is flagged by it; the manager's record says so.
            let _ = self.manager.measure(id, s);
        }
    }

    /// Reports reach it with positions and speeds rounded to `resolution` (m, m/s): see
    /// planner-core's `Manager::set_position_resolution` and `set_speed_resolution`.
    pub fn set_resolution(&mut self, resolution: (f64, f64)) -> Result<(), ConfigError> {
        self.manager.set_resolution(resolution)?;
        self.resolution = resolution;
        Ok(())
    }

    /// A restart: a new manager of the same junction and algorithm, remembering nothing
    /// but its configuration. It rebuilds its state from the reports it hears (every
    /// vehicle repeats its report every period) and grants nothing until every lease its
    /// predecessor may have given has lapsed (planner-core's `Manager` quiet time); a
    /// vehicle heard inside A_S holds its zones as a permission would.
    pub fn restart(&mut self) {
        let lease = self.manager.lease();
        let (algorithm, precision) = (self.manager.algorithm(), self.manager.precision());
        self.manager = AnyManager::new(&self.layout, algorithm, precision);
        // Both were accepted when they were set: they cannot be refused now.
        let _ = self.manager.set_resolution(self.resolution);
        let _ = self.manager.set_lease(lease);
        let _ = self.manager.set_roadside_sensor(self.roadside);
        self.restarted = true;
    }

    /// Whether it runs at `t` under `faults`' outage (`[faults.manager_down]`): not while
    /// down (what it hears is lost and it grants nothing); at its first period back it
    /// restarts, remembering nothing but the bus's resolution.
    pub fn is_up(&mut self, faults: &Faults, t: f64) -> bool {
        let down = faults
            .manager_down
            .filter(|d| d.junction == self.junction_id);
        if down.is_some_and(|d| d.is_down(t)) {
            return false;
        }
        if down.is_some_and(|d| t >= d.until_s) && !self.restarted {
            self.restart();
        }
        true
    }

    /// Its bus node.
    pub fn node(&self) -> u16 {
        manager_node(self.junction)
    }

    /// The manager's part of a period at `now` (its clock): takes the reports and
    /// departures it heard for its junction and its roadside sensor's `readings` (if it
    /// has one), decides, and returns the vehicles that hold a permission now (each is to
    /// be sent a lease).
    pub fn manage(
        &mut self,
        heard: &[Received],
        readings: &[(u16, f64)],
        now: Instant,
    ) -> Vec<u16> {
        for r in heard {
            match r.msg {
                Message::Crossing {
                    report, junction, ..
                } if junction == self.junction => {
                    let _ = self.manager.observe(&report, now);
                }
                Message::Left { id, junction, .. } if junction == self.junction => {
                    self.manager.forget(id)
                }
                _ => {}
            }
        }
        self.measure(readings);
        self.manager.update(now);
        self.manager.granted()
    }

    /// The grant of a lease to `id` sent at `now` (its clock).
    pub fn grant(&self, id: u16, now: Instant) -> Message {
        Message::Grant {
            junction: self.junction,
            id,
            until: self.manager.lease_until(now),
        }
    }
}
