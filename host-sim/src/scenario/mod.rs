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
        // Not a generic TOML table (a syntax error, or a value such as a seed above
        // i64::MAX that only the typed reader takes): judged by its headers, so that the
        // right reader parses it and names what is wrong.
        let has = |h: &str| text.lines().any(|l| l.trim() == h);
        return if has("[road]") {
            Format::Road
        } else if has("[intersection]") {
            Format::Junction
        } else if has("[[intersection]]") || has("[[segment]]") || has("[grid]") {
            Format::Network
        } else {
            Format::Road
        };
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
    faults_fit(&spec, &error::Errors::new(text, path))?;
    Ok(spec)
}

/// The faults name what the world has: a manager that goes down is one of its junctions
/// (by id), a vehicle that goes silent or lies is one of its vehicles — or, in a world
/// with arrivals, an id the arrivals can be given. A fault on nothing would pass for a
/// fault survived.
fn faults_fit(spec: &WorldSpec, e: &error::Errors<'_>) -> Result<(), ScenarioError> {
    if let Some(d) = spec.faults.manager_down {
        if !spec.network.junctions.iter().any(|j| j.id == d.junction) {
            let ids: Vec<String> = spec
                .network
                .junctions
                .iter()
                .map(|j| j.id.to_string())
                .collect();
            let ids = if ids.is_empty() {
                "none".to_string()
            } else {
                ids.join(", ")
            };
            return Err(e.key(
                "faults.manager_down",
                "junction",
                format!(
                    "faults.manager_down.junction = {}: no junction has that id (the scenario's: {ids})",
                    d.junction
                ),
            ));
        }
    }
    let arrivals = matches!(spec.arrivals, crate::world::Arrivals::Poisson(_));
    let exists = |id: u16| {
        spec.vehicles.iter().any(|v| v.id == id) || (arrivals && crate::bus::is_vehicle_id(id))
    };
    let named = [
        ("faults.silent", spec.faults.silent.map(|s| s.id)),
        ("faults.liar", spec.faults.liar.map(|l| l.id)),
    ];
    for (table, id) in named {
        match id {
            Some(id) if !exists(id) => {
                let which = if arrivals {
                    "neither a vehicle of the scenario nor an id arrivals can have (1 to 65279)"
                } else {
                    "no vehicle of the scenario has that id"
                };
                return Err(e.key(table, "id", format!("{table}.id = {id}: {which}")));
            }
            _ => {}
        }
    }
    Ok(())
}

/// Every table of every format: (its name as docs/scenarios.md heads it, its keys).
pub fn tables() -> Vec<(&'static str, &'static [&'static str])> {
    let mut t = Vec::new();
    t.extend(road::keys());
    t.extend(junction::keys());
    t.extend(network::keys());
    t.push(("[faults]", keys::fields::<crate::bus::Faults>()));
    t.push(("[faults.silent]", keys::fields::<crate::bus::Silent>()));
    t.push(("[faults.liar]", keys::fields::<crate::bus::Liar>()));
    t.push((
        "[faults.manager_down]",
        keys::fields::<crate::bus::ManagerDown>(),
    ));
    t.push(("[sensing]", keys::fields::<common::SensingToml>()));
    t
}
