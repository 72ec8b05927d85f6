//! Every experiment that can be sharded, by the name a shard's header gives it: `host-sim
//! merge` reads the shards' settings back into the experiment's own settings type and
//! reports and judges the merged result with that type's [`Experiment`] implementation —
//! the same code the unsharded run goes through.

use super::crossings::Crossings;
use super::deadends::Deadends;
use super::demand::DemandSettings;
use super::experiment::{merge_as, Experiment};
use super::fault_grid::GridSettings;
use super::faults::FaultSettings;
use super::layouts::Layouts;
use super::multilane::MultilaneSettings;
use super::network::Grids;
use super::platoon::Platoons;
use super::redteam::{Ids, Liars, Outages};
use super::shard::{check, MergeError, Output};
use super::throughput::ThroughputSettings;
use super::traffic::Traffic;
use crate::verdict::Verdict;
use serde_json::Value;

/// The names of every experiment a shard can come from.
pub const NAMES: [&str; 14] = [
    Platoons::NAME,
    Traffic::NAME,
    Deadends::NAME,
    Crossings::NAME,
    Outages::NAME,
    Liars::NAME,
    Ids::NAME,
    Layouts::NAME,
    Grids::NAME,
    MultilaneSettings::NAME,
    ThroughputSettings::NAME,
    FaultSettings::NAME,
    GridSettings::NAME,
    DemandSettings::NAME,
];

/// The shards of one experiment, merged: its name, its report as the unsharded run prints
/// it, and its verdict.
pub fn merge(parts: Vec<Output>) -> Result<(String, Value, Verdict), MergeError> {
    let (header, results) = check(parts)?;
    let merge = match header.sweep.as_str() {
        Platoons::NAME => merge_as::<Platoons>,
        Traffic::NAME => merge_as::<Traffic>,
        Deadends::NAME => merge_as::<Deadends>,
        Crossings::NAME => merge_as::<Crossings>,
        Outages::NAME => merge_as::<Outages>,
        Liars::NAME => merge_as::<Liars>,
        Ids::NAME => merge_as::<Ids>,
        Layouts::NAME => merge_as::<Layouts>,
        Grids::NAME => merge_as::<Grids>,
        MultilaneSettings::NAME => merge_as::<MultilaneSettings>,
        ThroughputSettings::NAME => merge_as::<ThroughputSettings>,
        FaultSettings::NAME => merge_as::<FaultSettings>,
        GridSettings::NAME => merge_as::<GridSettings>,
        DemandSettings::NAME => merge_as::<DemandSettings>,
        other => {
            return Err(MergeError::Shape(format!(
                "no experiment is called {other:?} ({})",
                NAMES.join(", ")
            )))
        }
    };
    let (report, verdict) = merge(&header, results)?;
    Ok((header.sweep, report, verdict))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiments::experiment::{run_shard, run_whole};
    use crate::experiments::platoon::Platoons;
    use crate::experiments::shard::{MergeError, Shard};
    use crate::verdict::Judged;

    #[test]
    fn every_name_is_one_experiment() {
        for (i, a) in NAMES.iter().enumerate() {
            assert!(!NAMES[..i].contains(a), "{a} twice");
        }
    }

    /// Shards merged through the registry are judged and reported as the whole run.
    #[test]
    fn merged_shards_are_the_whole_run() {
        let e = Platoons {
            cases: 3,
            seed: 4,
            reuse: false,
            invariant: planner_core::Invariant::Paper,
            trucks: 0,
        };
        let whole = run_whole(&e, 1).expect("one part");
        let parts: Vec<Output> = (0..2)
            .map(|index| {
                run_shard(&e, Shard { index, count: 2 }, 1)
                    .expect("a shard")
                    .0
            })
            .collect();
        let (name, merged, verdict) = merge(parts).expect("merges");
        assert_eq!(name, "platoons");
        assert_eq!(verdict, whole.verdict());
        let n = |v: &Value, k: &str| v.get(k).and_then(Value::as_u64);
        let w = serde_json::to_value(&whole).expect("json");
        for k in [
            "cases",
            "vehicles",
            "planner_steps",
            "collisions",
            "fallback_steps",
        ] {
            assert_eq!(n(&merged, k), n(&w, k), "{k}");
        }
    }

    #[test]
    fn a_shard_of_no_experiment_is_refused() {
        let e = Platoons {
            cases: 1,
            seed: 1,
            reuse: false,
            invariant: planner_core::Invariant::Paper,
            trucks: 0,
        };
        let (mut out, _) = run_shard(&e, Shard::ALL, 1).expect("a shard");
        out.header.sweep = "nothing".into();
        assert!(matches!(merge(vec![out]), Err(MergeError::Shape(m)) if m.contains("platoons")));
    }
}
