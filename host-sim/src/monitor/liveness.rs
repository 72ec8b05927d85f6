//! Liveness, measured like safety (Theorems 3–5; SPEC §10): who still has a goal, and a
//! deadlock detector.
//!
//! A run is **deadlocked** when no vehicle has moved for `window_s` (10 s by default)
//! while some vehicle still has a goal (a target lane, a junction to cross, a goal x, a
//! destination). It is then ended early and reported with its **wait-for relation**: for
//! each stopped vehicle with a goal, what it waits on — the vehicle ahead, the vehicles it
//! yields to or that block its lane change, a junction manager's grant (and whoever holds
//! the permissions that keep it waiting), or the end of its road — and a cycle of that
//! relation if there is one. A long wait in which something still moves (a red STOP
//! queue while another vehicle crosses) is not a deadlock.

use serde::Serialize;
use std::collections::BTreeMap;

/// The default window (s) without movement that counts as a deadlock.
pub const DEADLOCK_WINDOW_S: f64 = 10.0;
/// A vehicle moved in a period if it applied more than this speed (m/s).
pub const MOVING_MPS: f64 = 1e-3;

/// What a waiting vehicle waits on.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum WaitsOn {
    /// The vehicle ahead of it (in its lane or on its path).
    Vehicle {
        /// That vehicle.
        id: u16,
    },
    /// Vehicles it yields to under the Yield Protocol (20)(21), or that block the start
    /// of its lane change ((16)/(17), or their data is stale).
    LaneChange {
        /// Those vehicles (empty: the free-space condition, or the road ahead).
        ids: Vec<u16>,
    },
    /// The grant of a junction's manager, and the vehicles holding the permissions that
    /// keep it from being granted.
    Grant {
        /// The junction's id.
        junction: u16,
        /// Vehicles holding permissions it conflicts with.
        holders: Vec<u16>,
    },
    /// A grant of a junction's manager that it cannot ask for: its own transmitter is
    /// silent (a fault), so the manager never hears its request. Waiting is the protocol's
    /// answer — entering A_S unpermitted is not — so this is a reason, not a deadlock of
    /// the others: no other vehicle waits on it unless it stands in their way.
    OwnSilence {
        /// The junction's id.
        junction: u16,
    },
    /// The end of its road: a dead end, or a junction's edge of A_C it may not pass yet.
    RoadEnd,
    /// Nothing within reach stops it: its own planner holds it (a certified fallback, or a
    /// plan that waits on what it heard), and `nearest` is the nearest vehicle ahead on
    /// its lane or path, at any distance, if there is one.
    Planner {
        /// The nearest vehicle ahead of it, however far.
        nearest: Option<u16>,
    },
}

impl WaitsOn {
    /// The vehicles this points at.
    fn vehicles(&self) -> Vec<u16> {
        match self {
            WaitsOn::Vehicle { id } => vec![*id],
            WaitsOn::LaneChange { ids } => ids.clone(),
            WaitsOn::Grant { holders, .. } => holders.clone(),
            WaitsOn::RoadEnd | WaitsOn::OwnSilence { .. } => Vec::new(),
            WaitsOn::Planner { nearest } => nearest.iter().copied().collect(),
        }
    }
}

impl std::fmt::Display for WaitsOn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            WaitsOn::Vehicle { id } => write!(f, "vehicle {id} ahead"),
            WaitsOn::LaneChange { ids } if ids.is_empty() => write!(f, "room to change lanes"),
            WaitsOn::LaneChange { ids } => write!(f, "room to change lanes (vehicles {ids:?})"),
            WaitsOn::Grant { junction, holders } if holders.is_empty() => {
                write!(f, "a grant of junction {junction}")
            }
            WaitsOn::Grant { junction, holders } => {
                write!(
                    f,
                    "a grant of junction {junction} (permissions held by {holders:?})"
                )
            }
            WaitsOn::OwnSilence { junction } => write!(
                f,
                "a grant of junction {junction} it cannot ask for: its own transmitter is silent"
            ),
            WaitsOn::RoadEnd => write!(f, "the end of its road"),
            WaitsOn::Planner { nearest: Some(id) } => write!(
                f,
                "its own planner: nothing within reach stops it (vehicle {id} is the nearest ahead)"
            ),
            WaitsOn::Planner { nearest: None } => write!(
                f,
                "its own planner: nothing within reach stops it, and no vehicle is ahead"
            ),
        }
    }
}

/// One vehicle as the liveness monitor sees it at an instant.
#[derive(Debug, Clone, PartialEq)]
pub struct Status {
    /// Id.
    pub id: u16,
    /// It applied a speed above [`MOVING_MPS`] over the last period.
    pub moving: bool,
    /// It still has a goal.
    pub unmet: bool,
    /// What it waits on, if it is waiting.
    pub waits_on: Vec<WaitsOn>,
}

/// One vehicle's entry in a deadlock report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Waiting {
    /// The vehicle.
    pub id: u16,
    /// What it waits on.
    pub waits_on: Vec<WaitsOn>,
}

/// A detected deadlock.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Deadlock {
    /// When it was declared (s): `window_s` after the last movement.
    pub at_s: f64,
    /// Since when nothing has moved (s).
    pub still_since_s: f64,
    /// Every stopped vehicle with a goal, and what it waits on.
    pub waits: Vec<Waiting>,
    /// A cycle of the wait-for relation (vehicle ids, the first repeated at the end), if
    /// there is one.
    pub cycle: Option<Vec<u16>>,
}

impl std::fmt::Display for Deadlock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "deadlock at t = {:.2} s: nothing has moved since t = {:.2} s",
            self.at_s, self.still_since_s
        )?;
        for w in &self.waits {
            let on: Vec<String> = w.waits_on.iter().map(ToString::to_string).collect();
            writeln!(f, "  vehicle {} waits on {}", w.id, on.join(", "))?;
        }
        match &self.cycle {
            Some(c) => {
                let c: Vec<String> = c.iter().map(ToString::to_string).collect();
                write!(f, "  cycle: {}", c.join(" → "))
            }
            None => write!(f, "  no cycle: the chain ends at a road end or a grant"),
        }
    }
}

/// The deadlock detector.
#[derive(Debug, Clone)]
pub struct DeadlockDetector {
    window_s: f64,
    last_move_s: f64,
}

impl DeadlockDetector {
    /// A detector that declares a deadlock after `window_s` without movement.
    pub fn new(window_s: f64) -> Self {
        Self {
            window_s,
            last_move_s: 0.0,
        }
    }

    /// The window (s).
    pub fn window_s(&self) -> f64 {
        self.window_s
    }

    /// Whether the statuses at `t` are worth a full look: something still has a goal and
    /// nothing has moved for the window. Cheap: the world builds the wait-for relation
    /// only when this says so.
    pub fn tick(&mut self, t: f64, any_moving: bool, any_unmet: bool) -> bool {
        if any_moving || !any_unmet {
            self.last_move_s = t;
            return false;
        }
        t - self.last_move_s >= self.window_s - 1e-9
    }

    /// The report of the deadlock found at `t` among `statuses`.
    pub fn report(&self, t: f64, statuses: &[Status]) -> Deadlock {
        let waits: Vec<Waiting> = statuses
            .iter()
            .filter(|s| s.unmet && !s.moving)
            .map(|s| Waiting {
                id: s.id,
                waits_on: s.waits_on.clone(),
            })
            .collect();
        let graph: BTreeMap<u16, Vec<u16>> = waits
            .iter()
            .map(|w| {
                (
                    w.id,
                    w.waits_on.iter().flat_map(WaitsOn::vehicles).collect(),
                )
            })
            .collect();
        Deadlock {
            at_s: t,
            still_since_s: self.last_move_s,
            cycle: find_cycle(&graph),
            waits,
        }
    }
}

/// A cycle of `graph` (a vehicle → the vehicles it waits on), as the ids along it with
/// the first repeated at the end; the one through the smallest id found first.
pub fn find_cycle(graph: &BTreeMap<u16, Vec<u16>>) -> Option<Vec<u16>> {
    // Colour: 0 unseen, 1 on the current path, 2 done.
    let mut colour: BTreeMap<u16, u8> = BTreeMap::new();
    for &start in graph.keys() {
        if colour.get(&start).copied().unwrap_or(0) != 0 {
            continue;
        }
        let mut path: Vec<u16> = vec![start];
        let mut next: Vec<usize> = vec![0];
        colour.insert(start, 1);
        while let (Some(&node), Some(i)) = (path.last(), next.last_mut()) {
            let succ = graph.get(&node).and_then(|s| s.get(*i)).copied();
            *i += 1;
            match succ {
                None => {
                    colour.insert(node, 2);
                    path.pop();
                    next.pop();
                }
                Some(m) => match colour.get(&m).copied().unwrap_or(0) {
                    1 => {
                        let from = path.iter().position(|&p| p == m).unwrap_or(0);
                        let mut cycle = path[from..].to_vec();
                        cycle.push(m);
                        return Some(cycle);
                    }
                    0 => {
                        colour.insert(m, 1);
                        path.push(m);
                        next.push(0);
                    }
                    _ => {}
                },
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cycles_are_found_and_chains_are_not_cycles() {
        let g: BTreeMap<u16, Vec<u16>> = [(1, vec![2]), (2, vec![3]), (3, vec![1]), (4, vec![1])]
            .into_iter()
            .collect();
        assert_eq!(find_cycle(&g), Some(vec![1, 2, 3, 1]));
        let chain: BTreeMap<u16, Vec<u16>> = [(1, vec![2]), (2, vec![3]), (3, vec![])]
            .into_iter()
            .collect();
        assert_eq!(find_cycle(&chain), None);
        let self_loop: BTreeMap<u16, Vec<u16>> = [(5, vec![5])].into_iter().collect();
        assert_eq!(find_cycle(&self_loop), Some(vec![5, 5]));
    }

    #[test]
    fn the_report_follows_every_kind_of_wait_and_says_what_it_is() {
        let d = DeadlockDetector::new(10.0);
        let stopped = |id, waits_on| Status {
            id,
            moving: false,
            unmet: true,
            waits_on,
        };
        // 1 waits on 2 ahead, 2 on a lane change that 3 blocks, 3 on a grant whose
        // conflicting permission 1 holds: a cycle through all three kinds; 4 moves.
        let statuses = [
            stopped(1, vec![WaitsOn::Vehicle { id: 2 }]),
            stopped(2, vec![WaitsOn::LaneChange { ids: vec![3] }]),
            stopped(
                3,
                vec![WaitsOn::Grant {
                    junction: 0,
                    holders: vec![1],
                }],
            ),
            Status {
                id: 4,
                moving: true,
                unmet: true,
                waits_on: vec![WaitsOn::RoadEnd],
            },
        ];
        let r = d.report(12.0, &statuses);
        assert_eq!(r.cycle, Some(vec![1, 2, 3, 1]));
        assert_eq!(r.waits.iter().map(|w| w.id).collect::<Vec<_>>(), [1, 2, 3]);
        // A chain that ends at a road end is no cycle.
        let chain = [
            stopped(1, vec![WaitsOn::Vehicle { id: 2 }]),
            stopped(2, vec![WaitsOn::RoadEnd]),
        ];
        let r = d.report(12.0, &chain);
        assert_eq!(r.cycle, None);
        assert!(
            r.to_string().contains("vehicle 1 waits on vehicle 2 ahead"),
            "{r}"
        );
        assert!(r.to_string().contains("no cycle"), "{r}");
        let said: Vec<String> = [
            WaitsOn::Vehicle { id: 7 },
            WaitsOn::LaneChange { ids: vec![] },
            WaitsOn::LaneChange { ids: vec![1, 2] },
            WaitsOn::Grant {
                junction: 3,
                holders: vec![],
            },
            WaitsOn::Grant {
                junction: 3,
                holders: vec![5],
            },
            WaitsOn::RoadEnd,
            WaitsOn::OwnSilence { junction: 4 },
        ]
        .iter()
        .map(ToString::to_string)
        .collect();
        assert_eq!(
            said,
            [
                "vehicle 7 ahead",
                "room to change lanes",
                "room to change lanes (vehicles [1, 2])",
                "a grant of junction 3",
                "a grant of junction 3 (permissions held by [5])",
                "the end of its road",
                "a grant of junction 4 it cannot ask for: its own transmitter is silent"
            ]
        );
        // A vehicle waiting on its own silence points at no one: a chain ends there.
        let silent = [
            stopped(1, vec![WaitsOn::Vehicle { id: 2 }]),
            stopped(2, vec![WaitsOn::OwnSilence { junction: 0 }]),
        ];
        assert_eq!(d.report(12.0, &silent).cycle, None);
        assert!(WaitsOn::OwnSilence { junction: 0 }.vehicles().is_empty());
    }

    #[test]
    fn the_window_counts_from_the_last_movement() {
        let mut d = DeadlockDetector::new(10.0);
        assert_eq!(d.window_s(), 10.0);
        assert!(!d.tick(0.0, true, true));
        assert!(!d.tick(9.99, false, true));
        assert!(d.tick(10.0, false, true));
        // Something moves: the window starts again.
        assert!(!d.tick(10.5, true, true));
        assert!(!d.tick(20.49, false, true));
        assert!(d.tick(20.5, false, true));
        // Nothing to do is never a deadlock.
        assert!(!d.tick(40.0, false, false));
    }
}
