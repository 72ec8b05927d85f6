//! Settings that several experiments share, as the command line reads them: the
//! invariant, the solver, and a faulty bus. Each experiment's settings struct derives its
//! flags from its own fields (its doc comments are the help), so a setting is written in
//! one place.

use crate::bus::Faults;
use crate::world::SolverChoice;
use clap::builder::{PossibleValuesParser, TypedValueParser};
use planner_core::crossing::Algorithm;
use planner_core::Invariant;
use serde::{Deserialize, Serialize};

/// `--invariant paper|leader-aware`.
pub fn invariant() -> impl TypedValueParser<Value = Invariant> {
    PossibleValuesParser::new(["paper", "leader-aware"]).map(|s| match s.as_str() {
        "leader-aware" => Invariant::LeaderAware,
        _ => Invariant::Paper,
    })
}

/// `true` for the paper's invariant (which sweeps' shard headers leave out, so that
/// shards of the paper's sweeps keep the settings they always had).
pub fn is_paper(i: &Invariant) -> bool {
    *i == Invariant::Paper
}

/// For serde's `skip_serializing_if`: a count or percent left at 0.
pub fn is_zero(n: &u8) -> bool {
    *n == 0
}

/// `--solver ours|ours-interior-point|clarabel`.
pub fn solver() -> impl TypedValueParser<Value = SolverChoice> {
    PossibleValuesParser::new(["ours", "ours-interior-point", "clarabel"]).map(|s| {
        match s.as_str() {
            "ours-interior-point" => SolverChoice::OursInteriorPoint,
            "clarabel" => SolverChoice::Clarabel,
            _ => SolverChoice::Ours,
        }
    })
}

/// A faulty bus for an experiment (none by default); written in a shard's header as the
/// [`Faults`] it makes.
#[derive(clap::Args, Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "Faults", into = "Faults")]
pub struct FaultFlags {
    /// Probability that a receiver loses a message.
    #[arg(long, default_value_t = 0.0)]
    pub loss: f64,
    /// Delivery delay (s).
    #[arg(long, default_value_t = 0.0)]
    pub delay: f64,
    /// Extra delay drawn uniformly from [0, jitter] (s).
    #[arg(long, default_value_t = 0.0)]
    pub jitter: f64,
    /// Probability that a receiver gets a message twice.
    #[arg(long, default_value_t = 0.0)]
    pub duplicate: f64,
    /// Probability that a message is held back 20 ms (later ones overtake it).
    #[arg(long, default_value_t = 0.0)]
    pub reorder: f64,
}

impl FaultFlags {
    /// No fault.
    pub const NONE: Self = Self {
        loss: 0.0,
        delay: 0.0,
        jitter: 0.0,
        duplicate: 0.0,
        reorder: 0.0,
    };

    /// The bus's faults.
    pub fn faults(&self) -> Faults {
        Faults {
            loss: self.loss,
            delay_s: self.delay,
            jitter_s: self.jitter,
            duplicate: self.duplicate,
            reorder: self.reorder,
            ..Faults::NONE
        }
    }

    /// Checks them as a scenario's `[faults]` are checked, naming the flags.
    pub fn validate(&self) -> Result<(), super::refusal::SettingsError> {
        self.faults().validate().map_err(flag_error)
    }
}

/// A fault's error, its scenario key (`faults.delay_s = …`) spelled as its flag
/// (`--delay = …`).
pub fn flag_error(e: String) -> super::refusal::SettingsError {
    let text = e.replace("faults.", "--").replace("_s ", " ");
    let flag = ["--loss", "--delay", "--jitter", "--duplicate", "--reorder"]
        .into_iter()
        .find(|f| text.starts_with(f))
        .unwrap_or("--faults");
    super::refusal::SettingsError::raw(flag, text)
}

impl From<FaultFlags> for Faults {
    fn from(f: FaultFlags) -> Self {
        f.faults()
    }
}

impl From<Faults> for FaultFlags {
    fn from(f: Faults) -> Self {
        Self {
            loss: f.loss,
            delay: f.delay_s,
            jitter: f.jitter_s,
            duplicate: f.duplicate,
            reorder: f.reorder,
        }
    }
}

/// An algorithm by its name, in any case (`STOP`, `STOP-1`, `FIFO`, `CON`, `CON-fair`,
/// `PIPE`, `PLATOON`).
pub fn algorithm(name: &str) -> Result<Algorithm, String> {
    Algorithm::ALL
        .iter()
        .copied()
        .find(|a| a.name().eq_ignore_ascii_case(name))
        .ok_or_else(|| {
            let all: Vec<&str> = Algorithm::ALL.iter().map(|a| a.name()).collect();
            format!("unknown {name:?} ({})", all.join(", "))
        })
}

/// Algorithms written by their names ([`Algorithm::name`]).
pub mod algorithm_names {
    use planner_core::crossing::Algorithm;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    /// Writes each algorithm's name.
    pub fn serialize<S: Serializer>(all: &[Algorithm], s: S) -> Result<S::Ok, S::Error> {
        let names: Vec<&str> = all.iter().map(|a| a.name()).collect();
        names.serialize(s)
    }

    /// Reads algorithms by their names.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Algorithm>, D::Error> {
        Vec::<String>::deserialize(d)?
            .iter()
            .map(|n| super::algorithm(n).map_err(serde::de::Error::custom))
            .collect()
    }
}

/// One algorithm written by its name ([`Algorithm::name`]).
pub mod algorithm_name {
    use planner_core::crossing::Algorithm;
    use serde::{Deserialize, Deserializer, Serializer};

    /// Writes the algorithm's name.
    pub fn serialize<S: Serializer>(a: &Algorithm, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(a.name())
    }

    /// Reads an algorithm by its name.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Algorithm, D::Error> {
        super::algorithm(&String::deserialize(d)?).map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiments::demand::DemandSettings;
    use crate::experiments::experiment::{duration_within, Experiment};

    #[test]
    fn refusals_name_their_flag() {
        let bad = FaultFlags {
            loss: 1.5,
            ..FaultFlags::NONE
        };
        assert_eq!(bad.validate().map_err(|e| e.flag), Err("--loss"));
        let late = FaultFlags {
            delay: -1.0,
            ..FaultFlags::NONE
        };
        let e = late.validate().expect_err("a negative delay");
        assert_eq!(e.flag, "--delay");
        assert!(e.message.starts_with("--delay = -1"), "{e}");
        assert_eq!(
            duration_within(0.0, 10.0).map_err(|e| e.flag),
            Err("--duration")
        );
        let twice = DemandSettings {
            algorithms: vec![Algorithm::Fifo, Algorithm::Fifo],
            rates: vec![100.0],
            duration: 60.0,
            seeds: 1,
            invariant: Invariant::Paper,
            trucks: 0,
        };
        let e = twice.validate().expect_err("FIFO twice");
        assert_eq!(
            (e.flag, e.message.as_str()),
            ("--algorithms", "--algorithms: FIFO given twice")
        );
    }

    #[test]
    fn flags_are_written_as_the_faults_they_make() {
        let f = FaultFlags {
            loss: 0.25,
            delay: 0.5,
            ..FaultFlags::NONE
        };
        let v = serde_json::to_value(f).expect("json");
        assert_eq!(v, serde_json::to_value(f.faults()).expect("json"));
        let back: FaultFlags = serde_json::from_value(v).expect("read back");
        assert_eq!(back, f);
        assert_eq!(algorithm("con-FAIR"), Ok(Algorithm::ConcurrentFair));
        assert!(algorithm("green-wave").is_err());
    }
}
