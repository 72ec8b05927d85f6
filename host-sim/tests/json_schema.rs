//! docs/json.md is the reference of every `--json` output: this test runs each command
//! (small settings) and fails when an output has a key the page does not list, or lacks a
//! key the page says it has in that kind of run.
//!
//! Keys are flattened as the page writes them: `a.b` for a member of an object, `a[].b`
//! for a member of the objects in an array. A key the page lists without members (say
//! `faults`, "the faults of the run") is not looked into.

use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// One documented key: its name and the "when" condition (empty: always).
#[derive(Debug)]
struct DocKey {
    key: String,
    when: String,
}

/// docs/json.md's tables, by section title (`run`, `experiment demand`, ...).
fn doc() -> BTreeMap<String, Vec<DocKey>> {
    let text = std::fs::read_to_string(root().join("docs/json.md")).expect("docs/json.md");
    let mut out: BTreeMap<String, Vec<DocKey>> = BTreeMap::new();
    let mut section = String::new();
    for line in text.lines() {
        if let Some(t) = line.strip_prefix("## ") {
            section = t.trim().to_string();
            continue;
        }
        let cols: Vec<&str> = line.split('|').map(str::trim).collect();
        if cols.len() < 4 || !cols[1].starts_with('`') {
            continue;
        }
        let key = cols[1].trim_matches('`').to_string();
        out.entry(section.clone()).or_default().push(DocKey {
            key,
            when: cols[2].to_string(),
        });
    }
    out
}

/// Every key of `v`, flattened; arrays record themselves and their elements' members
/// under `name[]`.
fn flatten(v: &Value, prefix: &str, out: &mut BTreeSet<String>) {
    match v {
        Value::Object(m) => {
            for (k, c) in m {
                let name = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                out.insert(name.clone());
                flatten(c, &name, out);
            }
        }
        Value::Array(a) => {
            for c in a {
                flatten(c, &format!("{prefix}[]"), out);
            }
        }
        _ => {}
    }
}

/// The parent of a flattened key (`a[].b` → `a`, `a.b` → `a`), if any.
fn parent(key: &str) -> Option<&str> {
    let cut = key.rfind('.')?;
    Some(key[..cut].strip_suffix("[]").unwrap_or(&key[..cut]))
}

fn run_json(args: &[&str]) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .current_dir(root())
        .args(args)
        .arg("--json")
        .output()
        .expect("host-sim runs");
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(&text).unwrap_or_else(|e| {
        panic!(
            "{args:?}: not one JSON object ({e}); exit {:?}\n{text}\n{}",
            out.status.code(),
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

/// Checks one command's output against its section; `when` lists the conditions that
/// hold in this run (documented keys under any other condition must be absent).
fn check(section: &str, args: &[&str], when: &[&str]) {
    let doc = doc();
    let keys = doc
        .get(section)
        .unwrap_or_else(|| panic!("docs/json.md has no `## {section}`"));
    let listed: BTreeSet<&str> = keys.iter().map(|k| k.key.as_str()).collect();
    let has_members = |k: &str| listed.iter().any(|l| parent(l) == Some(k));
    let mut got = BTreeSet::new();
    flatten(&run_json(args), "", &mut got);
    let mut errors = Vec::new();
    for k in &got {
        let under_opaque = {
            let mut p = parent(k);
            let mut hit = false;
            while let Some(q) = p {
                hit |= listed.contains(q) && !has_members(q);
                p = parent(q);
            }
            hit
        };
        if !listed.contains(k.as_str()) && !under_opaque {
            errors.push(format!("output has `{k}`, docs/json.md does not list it"));
        }
    }
    for k in keys {
        // "deadlock, by kind": in deadlock runs, and only in the entries of some kinds.
        let mut parts = k.when.split(", ");
        let cond = parts.next().unwrap_or("");
        let by_kind = parts.next() == Some("by kind");
        let expected = cond.is_empty() || when.contains(&cond);
        let required = expected && !by_kind;
        if required && !got.contains(&k.key) && !array_is_empty(&got, &k.key) {
            errors.push(format!(
                "docs/json.md lists `{}`, the output lacks it",
                k.key
            ));
        }
        if !expected && got.contains(&k.key) {
            errors.push(format!(
                "`{}` is documented for `{}` runs only",
                k.key, k.when
            ));
        }
    }
    assert!(
        errors.is_empty(),
        "{section} {args:?}:\n  {}",
        errors.join("\n  ")
    );
}

/// `a[].b` cannot be present when the array `a` is empty: not an error.
fn array_is_empty(got: &BTreeSet<String>, key: &str) -> bool {
    match key.rfind("[]") {
        Some(i) => {
            let array = &key[..i];
            got.contains(array) && !got.iter().any(|g| g.starts_with(&format!("{array}[]")))
        }
        None => false,
    }
}

#[test]
fn the_page_parses_into_every_section() {
    let d = doc();
    for s in [
        "run",
        "platoons",
        "traffic",
        "traffic --compare",
        "deadends",
        "crossings",
        "experiment multilane",
        "experiment throughput",
        "experiment faults",
        "experiment faults --grid",
        "experiment demand",
        "experiment network",
        "scale",
        "scale --compare",
        "scale --sweep",
        "bench-planner",
        "outages, liars",
        "ids",
        "layouts",
        "grids",
        "worlds",
    ] {
        assert!(d.get(s).is_some_and(|k| k.len() >= 3), "section {s}");
    }
    let mut probe = BTreeSet::new();
    flatten(
        &serde_json::json!({"a": {"b": [{"c": 1}]}, "d": []}),
        "",
        &mut probe,
    );
    let want: BTreeSet<String> = ["a", "a.b", "a.b[].c", "d"].map(String::from).into();
    assert_eq!(probe, want);
}

#[test]
fn run_outputs_match_the_page() {
    check("run", &["run", "scenarios/multilane.toml"], &[]);
    check(
        "run",
        &["run", "scenarios/intersection.toml"],
        &["junction"],
    );
    check("run", &["run", "scenarios/corridor.toml"], &["junction"]);
    check(
        "run",
        &["run", "host-sim/tests/liveness/con-deadlock.toml"],
        &["junction", "deadlock"],
    );
    check(
        "run",
        &["run", "scenarios/intersection.toml", "--bus", "can-hub"],
        &["junction", "fleet"],
    );
}

#[test]
fn sweep_outputs_match_the_page() {
    check("platoons", &["platoons", "--cases", "3"], &[]);
    check(
        "traffic",
        &["traffic", "--cases", "2", "--duration", "2"],
        &[],
    );
    check(
        "traffic --compare",
        &["traffic", "--cases", "2", "--duration", "2", "--compare"],
        &[],
    );
    check("deadends", &["deadends", "--cases", "2"], &[]);
    check("crossings", &["crossings", "--cases", "1"], &[]);
    check("outages, liars", &["outages", "--cases", "1"], &[]);
    check("outages, liars", &["liars", "--cases", "2"], &[]);
    check("ids", &["ids", "--cases", "1"], &[]);
    check("layouts", &["layouts", "--cases", "3"], &[]);
    check("grids", &["grids", "--cases", "1", "--duration", "10"], &[]);
    check(
        "worlds",
        &[
            "worlds",
            "--vehicles",
            "50",
            "--duration",
            "1",
            "--delay",
            "1",
        ],
        &[],
    );
}

#[test]
fn experiment_outputs_match_the_page() {
    check(
        "experiment multilane",
        &["experiment", "multilane", "--seeds", "2"],
        &[],
    );
    check(
        "experiment throughput",
        &["experiment", "throughput", "--seeds", "1"],
        &[],
    );
    check(
        "experiment attacks",
        &[
            "experiment",
            "attacks",
            "--only",
            "forged-grant,manager-crash",
        ],
        &[],
    );
    check(
        "experiment faults",
        &[
            "experiment",
            "faults",
            "--seeds",
            "1",
            "--throughput-seeds",
            "1",
        ],
        &[],
    );
    check(
        "experiment faults --grid",
        &[
            "experiment",
            "faults",
            "--grid",
            "--losses",
            "0",
            "--delays",
            "0",
            "--runs",
            "1",
        ],
        &[],
    );
    check(
        "experiment demand",
        &[
            "experiment",
            "demand",
            "--rates",
            "100",
            "--duration",
            "60",
            "--seeds",
            "1",
        ],
        &[],
    );
    check(
        "experiment network",
        &[
            "experiment",
            "network",
            "--grid",
            "1x1",
            "--rate",
            "100",
            "--duration",
            "30",
        ],
        &[],
    );
}

#[test]
fn benchmark_outputs_match_the_page() {
    check(
        "scale",
        &["scale", "--vehicles", "20", "--duration", "1"],
        &[],
    );
    check(
        "scale",
        &["scale", "--vehicles", "20", "--duration", "1", "--traffic"],
        &[],
    );
    check(
        "scale",
        &["scale", "--vehicles", "20", "--duration", "1", "--reuse"],
        &["reuse"],
    );
    check(
        "scale --compare",
        &["scale", "--vehicles", "20", "--duration", "1", "--compare"],
        &[],
    );
    check(
        "scale --sweep",
        &[
            "scale",
            "--sweep",
            "--sweep-vehicles",
            "10",
            "--sweep-threads",
            "1",
            "--duration",
            "0.5",
        ],
        &[],
    );
    check(
        "bench-planner",
        &["bench-planner", "--problems", "5", "--reps", "1"],
        &[],
    );
}
