//! What every randomized sweep shares: a case's seed, which depends on the sweep's seed
//! and the case's index alone (so that a sweep can be split into shards and rerun case by
//! case), running a case's world to its end, and the report — with every failing case
//! kept as a scenario file that `host-sim run` reproduces.

use crate::verdict::{Judged, Safety, Verdict};
use crate::world::summary::Summary;
use crate::world::{SolverChoice, World, WorldSpec};
use serde::{Deserialize, Serialize};
use serde_json::Value;

/// A randomized sweep's cases and seed (its flags; a shard's header carries them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::Args)]
pub struct Cases {
    /// Number of random cases.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    pub cases: u64,
    /// Seed of the sweep (a case's own seed depends on this and its index alone).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// A randomized sweep's cases and seed, and the invariant every planner keeps (left out
/// of a shard's header when it is the paper's, as shards always had it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct CasesUnder {
    /// Cases and seed.
    #[command(flatten)]
    #[serde(flatten)]
    pub sweep: Cases,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = super::flags::invariant())]
    #[serde(
        default,
        skip_serializing_if = "super::flags::is_paper",
        with = "crate::world::invariant_serde"
    )]
    pub invariant: planner_core::Invariant,
}

/// A sweep's text: its name and cases, its top-level numbers, `notes`, and every failing
/// case's reason and scenario file.
pub fn text<T: Serialize>(
    name: &str,
    cases: u64,
    r: &T,
    notes: &str,
    failing: &[Failing],
) -> String {
    let value = serde_json::to_value(r).unwrap_or_default();
    let text = format!("{name}, {cases} cases:\n{}{notes}", human(&value));
    text + &failing_text(failing)
}

/// The top-level numbers of a result, one per line (a sweep's text summary).
pub fn human(v: &Value) -> String {
    let Some(m) = v.as_object() else {
        return v.to_string();
    };
    m.iter()
        .filter(|(_, x)| x.is_number())
        .map(|(k, x)| format!("  {k}: {x}"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Every failing case's reason and scenario file, each after a blank line.
fn failing_text(failing: &[Failing]) -> String {
    failing
        .iter()
        .map(|f| {
            format!(
                "\n\n# failing case {} ({}): {}\n{}",
                f.case, f.label, f.reason, f.scenario
            )
        })
        .collect()
}

/// A liveness sweep's text: its totals in a sentence, then every failing case's reason
/// and scenario file.
pub fn liveness_text(t: &Totals, failing: &[Failing]) -> String {
    let text = format!(
        "{} cases, {} vehicles: {} collisions, {} invariant violations, {} limit violations, \
         {} unpermitted entries, {} unfinished vehicles, {} deadlocks; every goal met by \
         {:.1} s at the latest",
        t.cases,
        t.vehicles,
        t.collisions,
        t.invariant_violations,
        t.limit_violations,
        t.unpermitted_entries,
        t.unfinished,
        t.deadlocks,
        t.max_finish_time_s
    );
    text + &failing_text(failing)
}

/// The seed of case `index` of a sweep seeded `seed`.
pub fn case_seed(seed: u64, index: u64) -> u64 {
    // SplitMix64 of (seed, index): independent streams per case.
    let mut z = seed
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(index.wrapping_mul(0xBF58_476D_1CE4_E5B9))
        .wrapping_add(0x94D0_49BB_1331_11EB);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Runs `spec` to its end (its duration, its finish, or a deadlock) on the in-process
/// bus, with multi-lane horizon 20.
pub fn run(spec: WorldSpec) -> Summary {
    let t0 = std::time::Instant::now();
    let mut w = World::<20>::new(spec, SolverChoice::Ours, None);
    while !w.finished() {
        // The in-process bus cannot fail.
        if w.step(&mut |_| {}).is_err() {
            break;
        }
    }
    w.summary(t0.elapsed().as_secs_f64())
}

/// One case's result.
#[derive(Debug, Clone)]
pub struct Case {
    /// Its index in the sweep.
    pub index: u64,
    /// Its seed.
    pub seed: u64,
    /// What ran (for a label: an algorithm).
    pub label: &'static str,
    /// Its summary.
    pub summary: Summary,
    /// The scenario file that reproduces it.
    pub scenario: String,
}

impl Case {
    /// Vehicles with a goal unmet at the end (a deadlock leaves them so).
    pub fn unfinished(&self) -> u64 {
        let s = &self.summary;
        s.unfinished as u64 + s.goal_x.saturating_sub(s.goal_x_reached) as u64
    }

    /// `true` if it failed: unsafe, or not every vehicle done.
    pub fn failed(&self) -> bool {
        self.summary.unsafe_events() > 0 || self.unfinished() > 0 || self.summary.deadlock.is_some()
    }

    /// When every goal was met (s): the last lane change's completion, or the end of the
    /// run when every vehicle left.
    pub fn finish_time_s(&self) -> f64 {
        let s = &self.summary;
        match s.crossing {
            Some(_) => s.sim_seconds,
            None => s.lane_changes.all_done_at_s.unwrap_or(s.sim_seconds),
        }
    }
}

/// A failing case, reproducible.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Failing {
    /// Its index.
    pub case: u64,
    /// What ran.
    pub label: String,
    /// Why it failed.
    pub reason: String,
    /// The scenario file: `host-sim run` on it reproduces the failure.
    pub scenario: String,
}

/// Totals over cases.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Totals {
    /// Cases run.
    pub cases: u64,
    /// Vehicles over all cases.
    pub vehicles: u64,
    /// Collisions (pairs × steps).
    pub collisions: u64,
    /// Invariant violations (pairs × steps).
    pub invariant_violations: u64,
    /// Limit violations, road-end overruns and departures from the road.
    pub limit_violations: u64,
    /// Steps × vehicles inside A_S without a permission.
    pub unpermitted_entries: u64,
    /// Vehicles with a goal unmet at the end.
    pub unfinished: u64,
    /// Cases that deadlocked.
    pub deadlocks: u64,
    /// Of the unfinished, those of runs whose deadlock holds a vehicle waiting on a grant
    /// it cannot ask for, its own transmitter silent
    /// ([`crate::monitor::liveness::WaitsOn::OwnSilence`]): the vehicles behind it wait
    /// on it, and a manager that never heard of it may have granted one of them, so the
    /// routes that conflict with that one wait too. Counted in `unfinished` all the same.
    #[serde(default)]
    pub own_silence: u64,
    /// Of the unfinished, those of runs that no deadlock ended, held up at the end by a
    /// vehicle whose transmitter is silent: ahead of them, or in the lane they must
    /// change into, known only by sensors and so taken at the wall and at the fleet's
    /// weakest braking limit (`Summary::held_by_silent`). Counted in `unfinished` all the
    /// same.
    #[serde(default)]
    pub held_by_silent: u64,
    /// Latest time by which a case had every goal met (s).
    pub max_finish_time_s: f64,
    /// Mean of those times (s).
    pub mean_finish_time_s: f64,
    /// Certified-fallback steps (not standstill, not yield).
    pub fallback_steps: u64,
}

impl Judged for Totals {
    /// Collisions, invariant and limit violations, unpermitted entries; live when no
    /// vehicle was left with a goal and no case deadlocked.
    fn verdict(&self) -> Verdict {
        Verdict::new(self.safety(), self.unfinished + self.deadlocks == 0)
    }
}

impl Totals {
    /// Their findings.
    pub fn safety(&self) -> Safety {
        Safety::of(
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            self.unpermitted_entries,
        )
    }

    /// The totals of `cases`.
    pub fn of<'a>(cases: impl Iterator<Item = &'a Case>) -> Self {
        let mut t = Totals::default();
        let mut sum = 0.0;
        for c in cases {
            let s = &c.summary;
            t.cases += 1;
            t.vehicles += s.vehicles as u64;
            t.collisions += s.collisions;
            t.invariant_violations += s.invariant_violations;
            t.limit_violations += s.limit_violations + s.road_end_overruns + s.off_road;
            t.unpermitted_entries += s.unpermitted_entries();
            t.unfinished += c.unfinished();
            t.deadlocks += u64::from(s.deadlock.is_some());
            t.own_silence += own_silence(s);
            t.held_by_silent += s.held_by_silent as u64;
            t.fallback_steps += s.fallback_steps;
            let f = c.finish_time_s();
            t.max_finish_time_s = t.max_finish_time_s.max(f);
            sum += f;
        }
        t.mean_finish_time_s = sum / t.cases.max(1) as f64;
        t
    }

    /// The totals of several totals, as [`Totals::of`] over all their cases: counts add,
    /// the latest finish is the largest, the mean is weighted by cases. Over totals of
    /// one case each, in case order, it is bit for bit `Totals::of` over those cases (a
    /// one-case mean is its finish time exactly), so a shard's runs merge into exactly
    /// the unsharded result.
    pub fn sum<'a>(parts: impl Iterator<Item = &'a Totals>) -> Self {
        let mut t = Totals::default();
        let mut sum = 0.0;
        for p in parts {
            t.cases += p.cases;
            t.vehicles += p.vehicles;
            t.collisions += p.collisions;
            t.invariant_violations += p.invariant_violations;
            t.limit_violations += p.limit_violations;
            t.unpermitted_entries += p.unpermitted_entries;
            t.unfinished += p.unfinished;
            t.deadlocks += p.deadlocks;
            t.own_silence += p.own_silence;
            t.held_by_silent += p.held_by_silent;
            t.fallback_steps += p.fallback_steps;
            t.max_finish_time_s = t.max_finish_time_s.max(p.max_finish_time_s);
            sum += p.mean_finish_time_s * p.cases as f64;
        }
        t.mean_finish_time_s = sum / t.cases.max(1) as f64;
        t
    }

    /// No collision, violation, unpermitted entry, unfinished vehicle or deadlock.
    pub fn clean(&self) -> bool {
        self.collisions
            + self.invariant_violations
            + self.limit_violations
            + self.unpermitted_entries
            + self.unfinished
            + self.deadlocks
            == 0
    }
}

/// `s`'s unfinished vehicles if its deadlock holds a vehicle that waits on a grant it
/// cannot ask for, else 0.
fn own_silence(s: &Summary) -> u64 {
    let silent = s.deadlock.as_ref().is_some_and(|d| {
        d.waits.iter().any(|w| {
            w.waits_on
                .iter()
                .any(|o| matches!(o, crate::monitor::liveness::WaitsOn::OwnSilence { .. }))
        })
    });
    if silent {
        s.unfinished as u64 + s.goal_x.saturating_sub(s.goal_x_reached) as u64
    } else {
        0
    }
}

/// Why `c` failed, in a few words.
pub fn reason(c: &Case) -> String {
    let s = &c.summary;
    let mut why = Vec::new();
    if s.collisions > 0 {
        why.push(format!("{} collisions", s.collisions));
    }
    if s.invariant_violations > 0 {
        why.push(format!("{} invariant violations", s.invariant_violations));
    }
    if s.limit_violations + s.road_end_overruns + s.off_road > 0 {
        why.push("limit violations".to_string());
    }
    if s.unpermitted_entries() > 0 {
        why.push(format!("{} unpermitted entries", s.unpermitted_entries()));
    }
    if let Some(d) = &s.deadlock {
        why.push(format!("deadlock at {:.1} s", d.at_s));
    }
    if c.unfinished() > 0 {
        why.push(format!("{} vehicles unfinished", c.unfinished()));
    }
    why.join(", ")
}

/// How many failing cases a sweep's report keeps (each with its scenario file).
pub const KEEP_FAILING: usize = 20;

/// Adds the failing case `make` builds to `list`, unless it holds [`KEEP_FAILING`]
/// already (the case's file is only written for those kept).
pub fn keep_failing(list: &mut Vec<Failing>, make: impl FnOnce() -> Failing) {
    if list.len() < KEEP_FAILING {
        list.push(make());
    }
}

/// The failing cases among `cases` (at most `keep`), each with its scenario file.
pub fn failing<'a>(cases: impl Iterator<Item = &'a Case>, keep: usize) -> Vec<Failing> {
    cases
        .filter(|c| c.failed())
        .take(keep)
        .map(|c| Failing {
            case: c.index,
            label: c.label.into(),
            reason: reason(c),
            scenario: c.scenario.clone(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cases_seed_depends_on_its_index_and_the_sweeps_seed() {
        assert_eq!(case_seed(1, 5), case_seed(1, 5));
        assert_ne!(case_seed(1, 5), case_seed(1, 6));
        assert_ne!(case_seed(1, 5), case_seed(2, 5));
    }
}
