//! Every sweep and experiment behind one trait, Clarabel's way: the settings are the
//! implementing type (written once — the command line flattens them into its flags, a
//! shard's header carries them to `host-sim merge`), checked by [`Experiment::validate`]
//! before anything runs; [`Experiment::run`] runs any range of its cases;
//! [`Experiment::report`] turns the parts of all its cases into its report, whether they
//! ran in one process or in shards; the report's [`Judged::verdict`] is what every
//! command and the merge conclude.
//!
//! A part is what the cases of a range yield: for the paper's experiments, the runs
//! themselves (their means, spreads and ratios are computed once, over all runs); for
//! the sweeps, a report whose fields add up case by case ([`super::shard::combine_all`]).

pub use super::refusal::{duration_within, SettingsError};
use super::shard::{Header, MergeError, Output, Shard};
use crate::verdict::{Judged, Verdict};
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::Value;

/// A sweep or an experiment; `Self` is its settings. One that is sharded is also
/// written and read back (its settings and its parts: serde), as [`run_shard`] and
/// [`merge_as`] ask.
pub trait Experiment {
    /// Its name: the command's, and a shard header's `sweep`.
    const NAME: &'static str;
    /// What the cases of one range yield (printed by a shard, read back by the merge).
    type Part;
    /// What it reports.
    type Report: Serialize + Judged;

    /// Refuses settings it cannot run (by default none: every value its flags parse to
    /// can run).
    fn validate(&self) -> Result<(), SettingsError> {
        Ok(())
    }

    /// Its cases (what shards divide).
    fn cases(&self) -> u64;

    /// Cases [first, end) on `threads` threads (0: one per core), or why they could not
    /// run (settings already validated: a bus that failed, or a bug).
    fn run(&self, range: (u64, u64), threads: usize) -> Result<Self::Part, RunError>;

    /// The report from the parts of all its cases, in case order (one part when it ran
    /// whole); refused when a part is not shaped as it should be.
    fn report(&self, parts: Vec<Self::Part>) -> Result<Self::Report, MergeError>;
}

/// Why validated settings could not run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RunError {
    /// A CAN bus failed (exit 4).
    Bus(String),
    /// A bug: what failed (exit 5).
    Internal(String),
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Bus(e) => write!(f, "bus: {e}"),
            RunError::Internal(e) => write!(f, "internal: {e} (a bug: please report it)"),
        }
    }
}

impl std::error::Error for RunError {}

impl From<MergeError> for RunError {
    /// A run's own part that does not report: a bug.
    fn from(e: MergeError) -> Self {
        RunError::Internal(e.to_string())
    }
}

/// The report of an experiment that runs whole: its one part, or a shape error naming
/// `name` when there is not exactly one.
pub fn only_part<T>(mut parts: Vec<T>, name: &str) -> Result<T, MergeError> {
    match (parts.pop(), parts.is_empty()) {
        (Some(r), true) => Ok(r),
        _ => Err(MergeError::Shape(format!("{name} runs whole: one part"))),
    }
}

/// Runs every case of `e` and reports (settings already validated).
pub fn run_whole<E: Experiment>(e: &E, threads: usize) -> Result<E::Report, RunError> {
    Ok(e.report(vec![e.run((0, e.cases()), threads)?])?)
}

/// Runs shard `shard` of `e`: its output for `host-sim merge`, and the verdict on its own
/// cases (a shard exits as the whole would on them).
pub fn run_shard<E>(e: &E, shard: Shard, threads: usize) -> Result<(Output, Verdict), RunError>
where
    E: Experiment + Serialize,
    E::Part: Serialize,
{
    let range = shard.range(e.cases());
    let part = e.run(range, threads)?;
    let result = to_value(&part)?;
    let verdict = e.report(vec![part])?.verdict();
    let header = Header {
        sweep: E::NAME.into(),
        settings: to_value(e)?,
        shard,
        first: range.0,
        end: range.1,
    };
    Ok((Output { header, result }, verdict))
}

/// The merged report of `E`'s shards (already checked to belong together, in shard
/// order) and its verdict.
pub fn merge_as<E>(header: &Header, parts: Vec<Value>) -> Result<(Value, Verdict), MergeError>
where
    E: Experiment + DeserializeOwned,
    E::Part: DeserializeOwned,
{
    let e: E = parse("settings", header.settings.clone())?;
    e.validate()
        .map_err(|err| MergeError::Shape(format!("settings: {err}")))?;
    let parts = parts
        .into_iter()
        .map(|p| parse("result", p))
        .collect::<Result<Vec<E::Part>, _>>()?;
    let report = e.report(parts)?;
    Ok((to_value(&report)?, report.verdict()))
}

fn parse<T: DeserializeOwned>(what: &str, v: Value) -> Result<T, MergeError> {
    serde_json::from_value(v).map_err(|e| MergeError::Shape(format!("{what}: {e}")))
}

fn to_value<T: Serialize>(t: &T) -> Result<Value, MergeError> {
    serde_json::to_value(t).map_err(|e| MergeError::Shape(e.to_string()))
}
