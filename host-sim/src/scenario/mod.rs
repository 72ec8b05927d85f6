//! Scenario files (TOML): one format for every world, with shorthands. A file describes a
//! network — `[[segment]]`s and `[[intersection]]`s, or a `[grid]` of them — and its
//! vehicles; a `[road]` table is a network of one straight road, a single
//! `[intersection]` table one junction with its own inlet and outlet tracks. Every file
//! may have `[faults]`, `[sensing]` and `deadlock_s`.
//!
//! Parsing is strict and happens before anything runs: unknown keys, impossible layouts,
//! values out of range and initial states that violate the safety invariant are refused
//! with the file, the line and the problem (`host-sim run` exits 2). Every key, its unit,
//! default and limits: `docs/scenarios.md`.

pub mod common;
pub mod error;
pub mod junction;
pub mod keys;
pub mod network;
pub mod road;

pub use error::{line_of, ScenarioError};
pub use road::{DriverKind, Phase};

use crate::world::WorldSpec;
use std::path::Path;

/// Which format a scenario text is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// `[road]`: one straight road.
    Road,
    /// A single `[intersection]` table: one junction.
    Junction,
    /// `[[segment]]`, `[[intersection]]`, `[grid]`: a network.
    Network,
}

/// The format of `text` (by its tables; the parser of that format checks the rest).
pub fn format_of(text: &str) -> Format {
    let Ok(t) = toml::from_str::<toml::Table>(text) else {
        return Format::Road;
    };
    match (t.get("road"), t.get("intersection")) {
        (Some(_), _) => Format::Road,
        (None, Some(toml::Value::Table(_))) => Format::Junction,
        (None, _) if t.contains_key("segment") || t.contains_key("grid") => Format::Network,
        (None, Some(_)) => Format::Network,
        (None, None) => Format::Road,
    }
}

/// Reads and validates a scenario file.
pub fn load(path: &Path) -> Result<WorldSpec, ScenarioError> {
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError {
        file: path.to_path_buf(),
        line: None,
        problem: format!("cannot read: {e}"),
    })?;
    parse(&text, path)
}

/// Parses and validates scenario text; `path` only names it in errors.
pub fn parse(text: &str, path: &Path) -> Result<WorldSpec, ScenarioError> {
    let spec = match format_of(text) {
        Format::Road => road::RoadScenario::parse(text, path).map(|s| s.world()),
        Format::Junction => junction::JunctionScenario::parse(text, path).map(|s| s.world()),
        Format::Network => network::NetworkScenario::parse(text, path).map(|s| s.world()),
    }?;
    faults_fit(&spec).map_err(|problem| ScenarioError {
        file: path.to_path_buf(),
        line: None,
        problem,
    })?;
    Ok(spec)
}

/// The faults name what the world has: a manager that goes down is one of its junctions.
fn faults_fit(spec: &WorldSpec) -> Result<(), String> {
    let junctions = spec.network.junctions.len();
    match spec.faults.manager_down {
        Some(d) if d.junction >= junctions => Err(format!(
            "faults.manager_down.junction = {}: the scenario has {junctions} junction(s)",
            d.junction
        )),
        _ => Ok(()),
    }
}
