//! Sweeps split into shards, and shards merged back.
//!
//! A sweep's case i is built from the sweep's seed and i alone ([`super::sweep::case_seed`],
//! or `seed + i` for `traffic`), so shard I of N runs the cases
//! [⌊I·K/N⌋, ⌊(I+1)·K/N⌋) of a K-case sweep and nothing else depends on N. A shard writes
//! its result inside an envelope that names the sweep, its settings and its range;
//! [`check`] makes sure the shards belong together (one sweep, the same settings, every
//! index once); an experiment's runs are then aggregated once over all shards
//! ([`Runs`]), and a sweep's reports combined by what each field is
//! ([`combine_all`]): counts add, maxima take
//! the max, minima the min, means are weighted by cases, failing cases are concatenated in
//! case order (at most [`super::sweep::KEEP_FAILING`]), the seed must agree and wall-clock
//! times add. The merged result is the unsharded one (floats up to rounding).

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use std::fmt;
use std::str::FromStr;

/// Shard `index` of `count` (0-based, as Slurm array tasks and Kubernetes completion
/// indexes are).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// This shard (0 ≤ index < count).
    pub index: u64,
    /// Shards in all (≥ 1).
    pub count: u64,
}

/// Why a `--shard` value was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ShardError {
    /// Not `I/N` with two integers.
    Syntax,
    /// N is 0, or I is not below N.
    Range,
}

impl fmt::Display for ShardError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ShardError::Syntax => write!(f, "expected I/N (e.g. 0/4)"),
            ShardError::Range => write!(f, "need N ≥ 1 and 0 ≤ I < N"),
        }
    }
}

impl std::error::Error for ShardError {}

impl FromStr for Shard {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (i, n) = s.split_once('/').ok_or(ShardError::Syntax)?;
        let index: u64 = i.trim().parse().map_err(|_| ShardError::Syntax)?;
        let count: u64 = n.trim().parse().map_err(|_| ShardError::Syntax)?;
        if count == 0 || index >= count {
            return Err(ShardError::Range);
        }
        Ok(Self { index, count })
    }
}

impl Shard {
    /// The whole sweep as one shard.
    pub const ALL: Self = Self { index: 0, count: 1 };

    /// The case indices [first, end) of this shard of a `cases`-case sweep.
    pub fn range(&self, cases: u64) -> (u64, u64) {
        let at = |i: u64| (u128::from(cases) * u128::from(i) / u128::from(self.count)) as u64;
        (at(self.index), at(self.index + 1))
    }
}

/// What a shard ran: enough for [`check`] to make sure that shards belong together.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// The sweep (`platoons`, `traffic`, `deadends`, `crossings`).
    pub sweep: String,
    /// Its settings (every argument but `--shard`), which must agree across shards.
    pub settings: Value,
    /// Which shard.
    pub shard: Shard,
    /// Its cases: [first, end).
    pub first: u64,
    /// One past its last case.
    pub end: u64,
}

/// A shard's output: the header and the sweep's result over the shard's cases.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Output {
    /// What ran.
    pub header: Header,
    /// The result, as the unsharded sweep would print it for these cases.
    pub result: Value,
}

/// Why shards could not be merged.
#[derive(Debug, Clone, PartialEq)]
pub enum MergeError {
    /// No shard given.
    Empty,
    /// Shards of different sweeps.
    DifferentSweeps(String, String),
    /// Shards run with different settings or shard counts.
    DifferentSettings(u64),
    /// The same shard twice.
    Duplicate(u64),
    /// A shard is missing.
    Missing(u64),
    /// A result is not shaped like its sweep's.
    Shape(String),
}

impl fmt::Display for MergeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MergeError::Empty => write!(f, "no shard to merge"),
            MergeError::DifferentSweeps(a, b) => {
                write!(f, "shards of different sweeps: {a} and {b}")
            }
            MergeError::DifferentSettings(i) => {
                write!(
                    f,
                    "shard {i} was run with other settings or another shard count"
                )
            }
            MergeError::Duplicate(i) => write!(f, "shard {i} is given twice"),
            MergeError::Missing(i) => write!(f, "shard {i} is missing"),
            MergeError::Shape(why) => write!(f, "not a sweep result: {why}"),
        }
    }
}

impl std::error::Error for MergeError {}

/// Checks that `parts` are the shards of one sweep (one sweep, the same settings and shard
/// count, every shard once) and gives its header and their results in shard order.
pub fn check(mut parts: Vec<Output>) -> Result<(Header, Vec<Value>), MergeError> {
    let first = parts.first().ok_or(MergeError::Empty)?.header.clone();
    for p in &parts {
        let h = &p.header;
        if h.sweep != first.sweep {
            return Err(MergeError::DifferentSweeps(
                first.sweep.clone(),
                h.sweep.clone(),
            ));
        }
        if h.settings != first.settings || h.shard.count != first.shard.count {
            return Err(MergeError::DifferentSettings(h.shard.index));
        }
    }
    parts.sort_by_key(|p| p.header.shard.index);
    for (i, p) in parts.iter().enumerate() {
        let at = p.header.shard.index;
        if at < i as u64 {
            return Err(MergeError::Duplicate(at));
        }
        if at > i as u64 {
            return Err(MergeError::Missing(i as u64));
        }
    }
    if (parts.len() as u64) < first.shard.count {
        return Err(MergeError::Missing(parts.len() as u64));
    }
    Ok((first, parts.into_iter().map(|p| p.result).collect()))
}

/// A sweep's reports over consecutive ranges of its cases → its report over all of them,
/// field by field as the module's doc says (one report is returned as it is).
pub fn combine_all<T: Serialize + DeserializeOwned>(mut parts: Vec<T>) -> Result<T, MergeError> {
    if parts.len() <= 1 {
        return parts.pop().ok_or(MergeError::Empty);
    }
    let shape = |e: serde_json::Error| MergeError::Shape(e.to_string());
    let mut values = parts.iter().map(serde_json::to_value);
    let mut acc = values.next().ok_or(MergeError::Empty)?.map_err(shape)?;
    for next in values {
        acc = combine("", &acc, &next.map_err(shape)?)?;
    }
    serde_json::from_value(acc).map_err(shape)
}

/// What a shard of an experiment prints: its runs, each as the experiment's aggregation
/// needs it, so that the merge aggregates all runs at once exactly as the unsharded
/// experiment does (its means, standard deviations and ratios are not sums of parts).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Runs<T> {
    /// The shard's runs, in run order.
    pub runs: Vec<T>,
    /// The shard's wall-clock time (s).
    pub wall_seconds: f64,
}

impl<T> Runs<T> {
    /// The runs `f` makes, and how long it took.
    pub fn timed(f: impl FnOnce() -> Vec<T>) -> Self {
        let t0 = std::time::Instant::now();
        let runs = f();
        Self {
            runs,
            wall_seconds: t0.elapsed().as_secs_f64(),
        }
    }

    /// Consecutive parts as one: their runs in order, their wall-clock times added.
    pub fn concat(parts: Vec<Self>) -> Self {
        let mut all = Self {
            runs: Vec::new(),
            wall_seconds: 0.0,
        };
        for p in parts {
            all.runs.extend(p.runs);
            all.wall_seconds += p.wall_seconds;
        }
        all
    }
}

/// Combines two results of the same shape, field by field (see the module's doc).
fn combine(key: &str, a: &Value, b: &Value) -> Result<Value, MergeError> {
    let shape = || MergeError::Shape(format!("`{key}` differs in kind between shards"));
    Ok(match (a, b) {
        // Counts by kind (`layouts`' refusals): each shard has the kinds it met.
        (Value::Object(x), Value::Object(y)) if key == "refusals" => {
            // In the order of their names, as each shard prints them.
            let mut out: std::collections::BTreeMap<String, Value> =
                x.clone().into_iter().collect();
            for (k, n) in y {
                let sum = match out.get(k) {
                    Some(m) => combine(k, m, n)?,
                    None => n.clone(),
                };
                out.insert(k.clone(), sum);
            }
            Value::Object(out.into_iter().collect())
        }
        (Value::Object(x), Value::Object(y)) => Value::Object(combine_objects(x, y)?),
        (Value::Array(x), Value::Array(y)) if key == "algorithms" => {
            if x.len() != y.len() {
                return Err(shape());
            }
            let rows = x.iter().zip(y).map(|(p, q)| combine(key, p, q));
            Value::Array(rows.collect::<Result<_, _>>()?)
        }
        (Value::Array(x), Value::Array(y)) => {
            let keep = if key == "failing" {
                super::sweep::KEEP_FAILING
            } else {
                usize::MAX
            };
            Value::Array(x.iter().chain(y).take(keep).cloned().collect())
        }
        _ if key == "seed" || a.is_string() || a.is_boolean() => {
            if a != b {
                return Err(MergeError::Shape(format!("`{key}` differs: {a} and {b}")));
            }
            a.clone()
        }
        (Value::Null, x) | (x, Value::Null)
            if key.starts_with("min_") || key.starts_with("max_") =>
        {
            x.clone()
        }
        (Value::Number(x), Value::Number(y)) => number(key, x, y),
        _ => return Err(shape()),
    })
}

/// Two numbers of the field `key`: a maximum, a minimum, a sum.
fn number(key: &str, x: &serde_json::Number, y: &serde_json::Number) -> Value {
    let (max, min) = (key.starts_with("max_"), key.starts_with("min_"));
    if let (Some(p), Some(q)) = (x.as_u64(), y.as_u64()) {
        return Value::from(if max {
            p.max(q)
        } else if min {
            p.min(q)
        } else {
            p + q
        });
    }
    let (p, q) = (
        x.as_f64().unwrap_or(f64::NAN),
        y.as_f64().unwrap_or(f64::NAN),
    );
    Value::from(if max {
        p.max(q)
    } else if min {
        p.min(q)
    } else {
        p + q
    })
}

/// Two objects: every field combined; a mean (`mean_*`) weighted by the objects' cases.
fn combine_objects(
    x: &Map<String, Value>,
    y: &Map<String, Value>,
) -> Result<Map<String, Value>, MergeError> {
    let cases = |m: &Map<String, Value>| m.get("cases").and_then(Value::as_f64);
    let (nx, ny) = (cases(x), cases(y));
    let mut out = Map::new();
    for (k, a) in x {
        let b = y
            .get(k)
            .ok_or_else(|| MergeError::Shape(format!("`{k}` missing in a shard")))?;
        let v = match (k.starts_with("mean_"), nx, ny, a.as_f64(), b.as_f64()) {
            (true, Some(n), Some(m), Some(p), Some(q)) if n + m > 0.0 => {
                Value::from((p * n + q * m) / (n + m))
            }
            _ => combine(k, a, b)?,
        };
        out.insert(k.clone(), v);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// Shards checked and combined field by field.
    fn merge(parts: Vec<Output>) -> Result<Value, MergeError> {
        combine_all(check(parts)?.1)
    }

    #[test]
    fn shards_cover_every_case_once() {
        for (cases, n) in [(10, 4), (3, 4), (1_000_000, 7), (5, 1)] {
            let mut next = 0;
            for i in 0..n {
                let (a, b) = Shard { index: i, count: n }.range(cases);
                assert_eq!(a, next);
                next = b;
            }
            assert_eq!(next, cases);
        }
        assert_eq!("2/4".parse(), Ok(Shard { index: 2, count: 4 }));
        assert_eq!("4/4".parse::<Shard>(), Err(ShardError::Range));
        assert_eq!("0/0".parse::<Shard>(), Err(ShardError::Range));
        assert_eq!("a/4".parse::<Shard>(), Err(ShardError::Syntax));
        assert_eq!("3".parse::<Shard>(), Err(ShardError::Syntax));
    }

    fn part(index: u64, count: u64, result: Value) -> Output {
        Output {
            header: Header {
                sweep: "deadends".into(),
                settings: json!({"cases": 10, "seed": 1}),
                shard: Shard { index, count },
                first: 0,
                end: 0,
            },
            result,
        }
    }

    #[test]
    fn fields_combine_by_what_they_are() {
        let a = json!({"cases": 2, "collisions": 1, "max_finish_time_s": 5.0,
                       "mean_finish_time_s": 3.0, "min_gap_m": 0.7, "seed": 1,
                       "failing": [{"case": 1}], "wall_seconds": 1.5});
        let b = json!({"cases": 6, "collisions": 0, "max_finish_time_s": 4.0,
                       "mean_finish_time_s": 1.0, "min_gap_m": 0.6, "seed": 1,
                       "failing": [{"case": 7}], "wall_seconds": 2.5});
        let m = merge(vec![part(1, 2, b), part(0, 2, a)]).expect("merges");
        assert_eq!(
            m,
            json!({"cases": 8, "collisions": 1, "max_finish_time_s": 5.0,
                   "mean_finish_time_s": 1.5, "min_gap_m": 0.6, "seed": 1,
                   "failing": [{"case": 1}, {"case": 7}], "wall_seconds": 4.0})
        );
    }

    #[test]
    fn shards_that_do_not_belong_together_are_refused() {
        let r = json!({"cases": 1, "seed": 1});
        assert_eq!(merge(vec![]), Err(MergeError::Empty));
        assert_eq!(
            merge(vec![part(0, 2, r.clone()), part(0, 2, r.clone())]),
            Err(MergeError::Duplicate(0))
        );
        assert_eq!(
            merge(vec![part(0, 3, r.clone()), part(2, 3, r.clone())]),
            Err(MergeError::Missing(1))
        );
        assert_eq!(
            merge(vec![part(0, 2, r.clone())]),
            Err(MergeError::Missing(1))
        );
        let mut other = part(1, 2, r.clone());
        other.header.settings = json!({"cases": 10, "seed": 2});
        assert_eq!(
            merge(vec![part(0, 2, r.clone()), other]),
            Err(MergeError::DifferentSettings(1))
        );
        let mut other = part(1, 2, r.clone());
        other.header.sweep = "crossings".into();
        assert!(matches!(
            merge(vec![part(0, 2, r.clone()), other]),
            Err(MergeError::DifferentSweeps(..))
        ));
        let mut seed2 = r.clone();
        seed2["seed"] = json!(2);
        assert!(matches!(
            merge(vec![part(0, 2, r), part(1, 2, seed2)]),
            Err(MergeError::Shape(_))
        ));
    }
}
