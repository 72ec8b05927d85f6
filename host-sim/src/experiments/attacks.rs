//! `host-sim experiment attacks`: every attack of the threat model on the
//! paper's intersection (Fig. 8, under a live algorithm) and on its multi-lane road, each
//! run as a fleet on a CAN medium — the in-process hub by default — with every node
//! authenticating (SecOC-style, keys derived from the simulation master key) unless
//! asked to run without, to show what the authentication is for.
//!
//! Rows, per world:
//! - an intruder's attacks ([`Attack`]): forged grant, replayed grant, replayed state,
//!   spoofed id, flood — `attempts` are the messages (flood: frames) it wrote, `accepted`
//!   those receivers took that no genuine node sent in that period, summed over receivers
//!   (the fleet's [`crate::fleet::ledger::Ledger`]);
//! - a vehicle lying about its position ([`LIE_M`] further on, from [`LIE_FROM_S`]):
//!   `attempts` are its lies as planners heard them, `accepted` those taken into a view
//!   (the codec accepts them — the key is the liar's own; the plausibility checks do not);
//! - the manager's crash and restart (intersection only; down over [`OUTAGE_S`]):
//!   `attempts` its periods down, `accepted` the grants it sent while down.
//!
//! Every row reports the monitors' collisions, invariant violations and unpermitted
//! entries, whether every vehicle reached its goal (`completed`), and what the attack
//! cost in liveness: when the last goal was reached, beside the same world's run without
//! any attack.

use super::experiment::{Experiment, RunError, SettingsError};
use super::shard::MergeError;
use crate::bus::{Faults, Liar, ManagerDown};
use crate::fleet::can::{simulation_keys, Keys, SIMULATION_MASTER};
use crate::fleet::intruder::Attack;
use crate::fleet::{Fleet, FleetError, FleetSummary, Medium};
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::WorldSpec;
use planner_core::crossing::Algorithm;
use serde::Serialize;
use std::path::Path;
use std::sync::Arc;

/// The liar: vehicle 1, claiming to be this much further on (m)…
pub const LIE_M: f64 = 5.0;
/// …from this time on (s).
pub const LIE_FROM_S: f64 = 2.0;
/// The manager's outage (s): down from, restarted at — while vehicles are inside A_S.
pub const OUTAGE_S: (f64, f64) = (3.0, 6.0);

const INTERSECTION: &str = include_str!("../../../scenarios/intersection.toml");
const MULTILANE: &str = include_str!("../../../scenarios/multilane.toml");

/// The attack experiment's settings (its flags).
#[derive(Debug, Clone, clap::Args)]
pub struct Settings {
    /// The fleets' medium: `can-hub` or a SocketCAN interface such as `vcan0`.
    #[arg(long = "bus", default_value = "can-hub", value_parser = clap::value_parser!(Medium))]
    pub medium: Medium,
    /// Run without authentication, to see what it keeps out (every node authenticates,
    /// SecOC, unless this is given).
    #[arg(long = "without-auth", action = clap::ArgAction::SetFalse)]
    pub authenticated: bool,
    /// Every message as one CAN FD frame.
    #[arg(long = "can-fd")]
    pub fd: bool,
    /// The intersection's algorithm (STOP, STOP-1, FIFO, CON-fair, PIPE, PLATOON).
    #[arg(long, default_value = "FIFO", value_parser = live_algorithm)]
    pub algorithm: Algorithm,
    /// Only these rows (comma-separated): forged-grant, replayed-grant,
    /// replayed-state, spoofed-id, flood, lying-vehicle, manager-crash.
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// Only these worlds (comma-separated): intersection, multilane.
    #[arg(long = "world", value_delimiter = ',')]
    pub worlds: Vec<String>,
    /// Skip each world's run without an attack (its `clean_*` figures are then null).
    #[arg(long = "no-baseline", action = clap::ArgAction::SetFalse)]
    pub baseline: bool,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = super::flags::invariant())]
    pub invariant: planner_core::Invariant,
}

/// A live algorithm by its name, in any case (the paper's Concurrent Crossing as written
/// is not live).
pub fn live_algorithm(name: &str) -> Result<Algorithm, String> {
    super::flags::algorithm(name)
        .ok()
        .filter(|a| *a != Algorithm::Concurrent)
        .ok_or_else(|| {
            format!(
                "{name:?} is not a live algorithm (STOP, STOP-1, FIFO, CON-fair, PIPE, PLATOON)"
            )
        })
}

impl Experiment for Settings {
    const NAME: &'static str = "attacks";
    type Part = AttackReport;
    type Report = AttackReport;

    fn validate(&self) -> Result<(), SettingsError> {
        let names = row_names();
        if let Some(bad) = self.only.iter().find(|o| !names.contains(&o.as_str())) {
            let why = format!("unknown row {bad:?} ({})", names.join(", "));
            return Err(SettingsError::new("--only", why));
        }
        match self.worlds.iter().find(|w| !WORLDS.contains(&w.as_str())) {
            Some(bad) => Err(SettingsError::new(
                "--world",
                format!("unknown {bad:?} ({})", WORLDS.join(", ")),
            )),
            None => Ok(()),
        }
    }

    /// Every attack on every world, as one fleet after another.
    fn cases(&self) -> u64 {
        1
    }

    fn run(&self, _range: (u64, u64), _threads: usize) -> Result<AttackReport, RunError> {
        experiment(self).map_err(|e| RunError::Bus(e.to_string()))
    }

    fn report(&self, parts: Vec<AttackReport>) -> Result<AttackReport, MergeError> {
        super::experiment::only_part(parts, Self::NAME)
    }
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            medium: Medium::Hub,
            authenticated: true,
            fd: false,
            algorithm: Algorithm::Fifo,
            only: Vec::new(),
            worlds: Vec::new(),
            baseline: true,
            invariant: planner_core::Invariant::Paper,
        }
    }
}

/// One attack on one world.
#[derive(Debug, Clone, Serialize)]
pub struct AttackRow {
    /// The attack (`forged-grant`, …, `lying-vehicle`, `manager-crash`).
    pub attack: String,
    /// The world (`intersection`, `multilane`).
    pub scenario: &'static str,
    /// What the attacker tried (see the module docs per kind).
    pub attempts: u64,
    /// Of those, what got through (see the module docs per kind).
    pub accepted: u64,
    /// Colliding pairs × steps (monitor).
    pub collisions: u64,
    /// Invariant violations (monitor).
    pub invariant_violations: u64,
    /// Entries into A_S without a live permission (monitor).
    pub unpermitted_entries: u64,
    /// Every vehicle reached its goal (crossed and left; is in its target lane).
    pub completed: bool,
    /// Vehicles.
    pub vehicles: usize,
    /// Of those, done: crossed, or in their target lane.
    pub done: u64,
    /// When the last was done, if all were (s).
    pub done_at_s: Option<f64>,
    /// The same world without any attack: when its last vehicle was done (s; `null`
    /// without the baseline run, or if not all were).
    pub clean_done_at_s: Option<f64>,
    /// Frames the nodes' decoders refused (CRC, MAC, freshness, sender …).
    pub frames_rejected: u64,
    /// Wall-clock time of the run (s).
    pub wall_seconds: f64,
    /// Wall-clock time of the same world's run without any attack (s): what receiving
    /// and refusing the attack's frames cost the nodes (`null` without the baseline run).
    pub clean_wall_seconds: Option<f64>,
}

impl AttackRow {
    /// Collisions, invariant violations and unpermitted entries.
    pub fn unsafe_events(&self) -> u64 {
        self.safety().events()
    }

    /// Its findings (a forgery or replay that got through counts as a breach where the
    /// nodes authenticate: [`AttackReport`]'s verdict).
    pub fn safety(&self) -> Safety {
        Safety::of(
            self.collisions,
            self.invariant_violations,
            0,
            self.unpermitted_entries,
        )
    }
}

/// The experiment's JSON.
#[derive(Debug, Clone, Serialize)]
pub struct AttackReport {
    /// The medium (`can-hub`, `socketcan:vcan0`).
    pub medium: String,
    /// Every node authenticated.
    pub authenticated: bool,
    /// CAN FD frames.
    pub can_fd: bool,
    /// The intersection's algorithm.
    pub algorithm: &'static str,
    /// The invariant every planner kept (`paper`, `leader-aware`).
    pub invariant: &'static str,
    /// One row per attack and world.
    pub results: Vec<AttackRow>,
}

/// Every row's name, in order.
pub fn row_names() -> Vec<&'static str> {
    let mut v: Vec<&'static str> = Attack::ALL.iter().map(|a| a.name()).collect();
    v.extend(["lying-vehicle", "manager-crash"]);
    v
}

/// The worlds' names.
pub const WORLDS: [&str; 2] = ["intersection", "multilane"];

/// The two worlds: the Fig. 8 intersection under `algorithm`, and the multi-lane road.
pub fn worlds(algorithm: Algorithm) -> Result<Vec<(&'static str, WorldSpec)>, String> {
    let parse = |text: &str, name: &str| {
        crate::scenario::parse(text, Path::new(name)).map_err(|e| e.to_string())
    };
    let mut junction = parse(INTERSECTION, "intersection.toml")?;
    for j in &mut junction.network.junctions {
        j.algorithm = algorithm;
    }
    Ok(vec![
        ("intersection", junction),
        ("multilane", parse(MULTILANE, "multilane.toml")?),
    ])
}

/// Runs the experiment.
pub fn experiment(s: &Settings) -> Result<AttackReport, FleetError> {
    let keys = s
        .authenticated
        .then(|| Arc::new(simulation_keys(&SIMULATION_MASTER)));
    let worlds = worlds(s.algorithm).map_err(FleetError::Unsupported)?;
    let wanted = |name: &str| s.only.is_empty() || s.only.iter().any(|o| o == name);
    let mut results = Vec::new();
    let chosen = |w: &str| s.worlds.is_empty() || s.worlds.iter().any(|o| o == w);
    for (name, mut spec) in worlds.into_iter().filter(|(w, _)| chosen(w)) {
        spec.invariant = s.invariant;
        let clean = match s.baseline {
            true => Some(run(s, &keys, spec.clone(), None)?.run),
            false => None,
        };
        let mut push = |attack: String, attempts: u64, accepted: u64, f: &FleetSummary| {
            results.push(row(name, attack, (attempts, accepted), f, clean.as_ref()));
        };
        for a in Attack::ALL.into_iter().filter(|a| wanted(a.name())) {
            let f = run(s, &keys, spec.clone(), Some(a))?;
            let i = f.intrusion.unwrap_or(crate::fleet::Intrusion {
                attack: a,
                attempts: 0,
                accepted: 0,
            });
            push(a.name().into(), i.attempts, i.accepted, &f);
        }
        if wanted("lying-vehicle") {
            let f = run(s, &keys, lying(spec.clone()), None)?;
            let lies = f.run.lies.map_or((0, 0), |l| (l.heard, l.taken));
            push("lying-vehicle".into(), lies.0, lies.1, &f);
        }
        if wanted("manager-crash") && !spec.network.junctions.is_empty() {
            let f = run(s, &keys, crashing(spec.clone()), None)?;
            let (from, until) = OUTAGE_S;
            let periods = ((until - from) / crate::monitor::Limits::table_i().h).round() as u64;
            push(
                "manager-crash".into(),
                periods,
                f.grants_while_down.unwrap_or(0),
                &f,
            );
        }
    }
    Ok(AttackReport {
        medium: s.medium.to_string(),
        authenticated: s.authenticated,
        can_fd: s.fd,
        algorithm: s.algorithm.name(),
        invariant: crate::world::invariant_name(s.invariant),
        results,
    })
}

/// One fleet run of `spec` under the settings, with an intruder carrying out `attack`.
fn run(
    s: &Settings,
    keys: &Option<Arc<Keys>>,
    spec: WorldSpec,
    attack: Option<Attack>,
) -> Result<FleetSummary, FleetError> {
    Fleet::new()
        .keys(keys.clone())
        .fd(s.fd)
        .attack(attack)
        .run(spec, s.medium.clone(), &mut |_| {})
}

/// `spec` with vehicle 1 lying about its position.
fn lying(mut spec: WorldSpec) -> WorldSpec {
    spec.faults = Faults {
        liar: Some(Liar {
            id: 1,
            from_s: LIE_FROM_S,
            offset_m: LIE_M,
        }),
        ..spec.faults
    };
    spec
}

/// `spec` with junction 0's manager down over [`OUTAGE_S`].
fn crashing(mut spec: WorldSpec) -> WorldSpec {
    let (from_s, until_s) = OUTAGE_S;
    spec.faults = Faults {
        manager_down: Some(ManagerDown {
            junction: 0,
            from_s,
            until_s,
        }),
        ..spec.faults
    };
    spec
}

fn row(
    scenario: &'static str,
    attack: String,
    (attempts, accepted): (u64, u64),
    f: &FleetSummary,
    clean: Option<&crate::world::summary::Summary>,
) -> AttackRow {
    let r = &f.run;
    let (vehicles_done, done_at_s) = done(r);
    AttackRow {
        attack,
        scenario,
        attempts,
        accepted,
        collisions: r.collisions,
        invariant_violations: r.invariant_violations,
        unpermitted_entries: r.crossing.as_ref().map_or(0, |c| c.unpermitted_entries),
        completed: r.completed,
        vehicles: r.vehicles,
        done: vehicles_done,
        done_at_s,
        clean_done_at_s: clean.and_then(|c| done(c).1),
        frames_rejected: f.can.rejected_total(),
        wall_seconds: r.wall_seconds,
        clean_wall_seconds: clean.map(|c| c.wall_seconds),
    }
}

/// Vehicles done in run `r`, and when the last was, if all were: at a junction, crossed
/// (the run ends when the last has left); on the road, in its target lane.
fn done(r: &crate::world::summary::Summary) -> (u64, Option<f64>) {
    match &r.crossing {
        Some(c) => (c.crossed, r.completed.then_some(r.sim_seconds)),
        None => (
            r.lane_changes.in_target_lane as u64,
            r.lane_changes.all_done_at_s,
        ),
    }
}

impl Judged for AttackReport {
    /// Every row's findings, and where the nodes authenticate, every forgery, replay,
    /// spoof or flood frame that got through as a breach (without authentication they are
    /// expected to get through: that run shows what it keeps out). Live when every row
    /// but the liar's left every vehicle done: a liar's cost in liveness is reported,
    /// not required away (the others stop taking its word and plan around it).
    fn verdict(&self) -> Verdict {
        let intruder = |name: &str| Attack::ALL.iter().any(|a| a.name() == name);
        let breaches: u64 = self
            .results
            .iter()
            .filter(|r| self.authenticated && intruder(&r.attack))
            .map(|r| r.accepted)
            .sum();
        let safety = Safety {
            breaches,
            ..self.results.iter().map(AttackRow::safety).sum()
        };
        let done = self
            .results
            .iter()
            .all(|r| r.completed || r.attack == "lying-vehicle");
        Verdict::new(safety, done)
    }
}

impl std::fmt::Display for AttackReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = self;
        writeln!(
            f,
            "attacks on {} (authenticated: {}, CAN FD: {}, intersection {})",
            r.medium, r.authenticated, r.can_fd, r.algorithm
        )?;
        writeln!(
            f,
            "{:<15} {:<13} {:>8} {:>8} {:>6} {:>6} {:>6} {:>5} {:>9} {:>9}",
            "attack",
            "world",
            "attempts",
            "accepted",
            "coll",
            "viol",
            "unperm",
            "done",
            "done at",
            "clean"
        )?;
        let s = |x: Option<f64>| x.map_or("-".into(), |v| format!("{v:.1} s"));
        for x in &r.results {
            writeln!(
                f,
                "{:<15} {:<13} {:>8} {:>8} {:>6} {:>6} {:>6} {:>5} {:>9} {:>9}",
                x.attack,
                x.scenario,
                x.attempts,
                x.accepted,
                x.collisions,
                x.invariant_violations,
                x.unpermitted_entries,
                format!("{}/{}", x.done, x.vehicles),
                s(x.done_at_s),
                s(x.clean_done_at_s)
            )?;
        }
        Ok(())
    }
}
