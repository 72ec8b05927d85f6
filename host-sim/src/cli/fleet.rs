//! `host-sim run FILE --bus can-hub|IFACE`: the world as a fleet of tasks on CAN.

use super::output::bad_input;
use can_gateway::secoc::Key;
use host_sim::fleet::can::{simulation_keys, Keys};
use host_sim::fleet::{self, FleetError, FleetSummary, Medium};
use host_sim::world::{SolverChoice, TraceRow, WorldSpec};
use std::path::Path;
use std::process::ExitCode;
use std::sync::Arc;

/// `--bus`: the CAN medium of a fleet (`in-process` is handled by the caller).
pub fn medium(bus: &str) -> Result<Medium, String> {
    bus.parse()
}

/// Checks `--bus` before anything runs.
pub fn check_bus(bus: &str) -> Result<(), ExitCode> {
    medium(bus).map(|_| ()).map_err(bad_input)
}

/// Whether the scenario in `file` can run as a fleet.
pub fn fits_the_bus(file: &Path, spec: &WorldSpec) -> Result<(), ExitCode> {
    match fleet::unsupported(spec) {
        Some(why) => Err(bad_input(format!("{}: `--bus`: {why}", file.display()))),
        None => Ok(()),
    }
}

/// How the fleet's nodes talk: authenticated with `keys`, if given; one CAN FD frame
/// per message when `fd`.
pub struct Link {
    /// The fleet's keys.
    pub keys: Option<Arc<Keys>>,
    /// CAN FD.
    pub fd: bool,
}

/// Runs the fleet on `bus` over `link`.
pub fn run(
    bus: &str,
    spec: WorldSpec,
    (solver, seed): (SolverChoice, Option<u64>),
    link: Link,
    trace: &mut dyn FnMut(&TraceRow),
) -> Result<FleetSummary, FleetError> {
    let m = medium(bus).map_err(FleetError::Unsupported)?;
    fleet::Fleet::new()
        .solver(solver)
        .seed(seed)
        .keys(link.keys)
        .fd(link.fd)
        .run(spec, m, trace)
}

pub use host_sim::fleet::can::SIMULATION_MASTER;

/// The fleet's keys: none without `auth`; from `file`; else derived from
/// [`SIMULATION_MASTER`].
pub fn keys(auth: bool, file: Option<&Path>) -> Result<Option<Arc<Keys>>, String> {
    if !auth && file.is_none() {
        return Ok(None);
    }
    let Some(file) = file else {
        return Ok(Some(Arc::new(simulation_keys(&SIMULATION_MASTER))));
    };
    let at = |e: String| format!("{}: {e}", file.display());
    let text = std::fs::read_to_string(file).map_err(|e| at(e.to_string()))?;
    parse_keys(&text).map(|k| Some(Arc::new(k))).map_err(at)
}

/// A key file: `master = "hex"` (every node's key derived from it) and/or a `[nodes]`
/// table of `"0xSA" = "hex"` (or decimal addresses), which take precedence.
pub fn parse_keys(text: &str) -> Result<Keys, String> {
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct File {
        master: Option<String>,
        #[serde(default)]
        nodes: std::collections::BTreeMap<String, String>,
    }
    let f: File = toml::from_str(text).map_err(|e| e.to_string())?;
    if f.master.is_none() && f.nodes.is_empty() {
        return Err("no key: give `master` or a `[nodes]` table".into());
    }
    let mut keys = match &f.master {
        Some(m) => simulation_keys(&hex_key(m).map_err(|e| format!("master: {e}"))?),
        None => Keys::new(),
    };
    for (sa, k) in &f.nodes {
        let addr =
            parse_address(sa).ok_or_else(|| format!("nodes: {sa:?} is not an address 0–255"))?;
        let key = hex_key(k).map_err(|e| format!("nodes.{sa}: {e}"))?;
        keys.insert(addr, key)
            .map_err(|e| format!("nodes.{sa}: {e:?}"))?;
    }
    Ok(keys)
}

fn parse_address(s: &str) -> Option<u8> {
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u8::from_str_radix(h, 16).ok(),
        None => s.parse().ok(),
    }
}

/// An AES-128 key from 32 hex digits.
fn hex_key(s: &str) -> Result<Key, String> {
    let b = s.as_bytes();
    if b.len() != 32 {
        return Err(format!("a key is 32 hex digits, not {}", b.len()));
    }
    let mut k = [0u8; 16];
    for (i, pair) in b.chunks(2).enumerate() {
        let txt = std::str::from_utf8(pair).map_err(|_| "not hex".to_string())?;
        k[i] = u8::from_str_radix(txt, 16).map_err(|_| format!("{txt:?} is not hex"))?;
    }
    Ok(Key(k))
}
