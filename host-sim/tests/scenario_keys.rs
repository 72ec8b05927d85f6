//! docs/scenarios.md lists every key of every scenario table the loader accepts, and no
//! other: the keys are read from the loader's own types (`scenario::keys`), the document's
//! from its tables (the first cell of each row under a `### table` heading).

use std::collections::{BTreeMap, BTreeSet};

fn documented() -> BTreeMap<String, BTreeSet<String>> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/scenarios.md");
    let text = std::fs::read_to_string(path).expect("docs/scenarios.md");
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut current: Option<String> = None;
    for line in text.lines() {
        if let Some(h) = line.strip_prefix("### ") {
            current = Some(h.trim().trim_matches('`').to_string());
            out.entry(h.trim().trim_matches('`').to_string())
                .or_default();
            continue;
        }
        if line.starts_with("## ") {
            current = None;
        }
        let (Some(table), Some(row)) = (&current, line.strip_prefix('|')) else {
            continue;
        };
        let first = row.split('|').next().unwrap_or("").trim();
        if first == "key" || first.starts_with("---") {
            continue;
        }
        for k in first.split(',') {
            let k = k.trim().trim_matches('`');
            if !k.is_empty() {
                out.entry(table.clone()).or_default().insert(k.to_string());
            }
        }
    }
    out
}

#[test]
fn every_key_the_loader_accepts_is_documented_and_no_other() {
    let docs = documented();
    let mut problems = Vec::new();
    for (table, keys) in host_sim::scenario::tables() {
        let accepted: BTreeSet<String> = keys.iter().map(|k| k.to_string()).collect();
        match docs.get(table) {
            None => problems.push(format!("no `### {table}` section in docs/scenarios.md")),
            Some(doc) => {
                for k in accepted.difference(doc) {
                    problems.push(format!("{table}: `{k}` is accepted but not documented"));
                }
                for k in doc.difference(&accepted) {
                    problems.push(format!("{table}: `{k}` is documented but not accepted"));
                }
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    assert!(docs.len() >= 16, "{docs:?}");
}

/// Every refusal points at a line, and where it points at the line that was changed, it
/// names the key: each `key = value` line of every shipped scenario is replaced, one at a
/// time, by the same key with an adversarial value (zero, negative, huge, tiny, the wrong
/// type, an id at the top of the range; each key of each table once per file), and every
/// fault section is appended with values
/// the world cannot have. A refusal without a place, or one that blames a line without
/// saying which of its keys, is what a user cannot act on.
#[test]
fn every_refusal_of_a_changed_value_says_where_and_which_key() {
    let values = [
        "0", "-1", "1e12", "0.0001", "65535", "\"x\"", "true", "[]", "1e-300", "-0.0", "100000",
        "2", "7", "nan", "inf",
    ];
    let faults = [
        "[faults.manager_down]\njunction = 77\nfrom_s = 1.0\nuntil_s = 2.0",
        "[faults.manager_down]\njunction = 0\nfrom_s = 3.0\nuntil_s = 1.0",
        "[faults.silent]\nid = 65500\nfrom_s = 1.0",
        "[faults.liar]\nid = 65500\nfrom_s = 1.0\noffset_m = 5.0",
        "[faults.liar]\nid = 1\nfrom_s = -1.0\noffset_m = 5.0",
        "[faults.liar]\nid = 1\nfrom_s = 1.0\noffset_m = 1000.0",
    ];
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let (mut tried, mut refused, mut bad) = (0, 0, Vec::new());
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("scenarios/")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    for path in &files {
        let text = std::fs::read_to_string(path).expect("a scenario");
        let lines: Vec<&str> = text.lines().collect();
        let mut judge = |changed: Option<(usize, &str)>, t: &str| {
            tried += 1;
            let Err(e) = host_sim::scenario::parse(t, path) else {
                return;
            };
            refused += 1;
            let names = changed.is_none_or(|(_, key)| e.problem.contains(key));
            let blames = changed.is_some_and(|(line, _)| e.line == Some(line));
            if e.line.is_none() || (blames && !names) {
                bad.push(format!("{changed:?} -> {e}"));
            }
        };
        // Each key of each table once per file (the first of a file's many vehicles
        // stands for the rest: loading a network builds its junctions, tens of ms).
        let (mut table, mut seen) = ("", BTreeSet::new());
        for (i, line) in lines.iter().enumerate() {
            if line.starts_with('[') {
                table = line.trim();
            }
            let Some((key, _)) = line.split_once(" = ") else {
                continue;
            };
            let key = key.trim();
            if key.starts_with('#') || key.contains(' ') || !seen.insert((table, key)) {
                continue;
            }
            for v in values {
                let mut changed = lines.clone();
                let new = format!("{key} = {v}");
                changed[i] = &new;
                judge(Some((i + 1, key)), &changed.join("\n"));
            }
        }
        for f in faults {
            judge(None, &format!("{text}\n{f}\n"));
        }
    }
    assert!(
        bad.is_empty(),
        "{} of {refused} refusals:\n{}",
        bad.len(),
        bad.join("\n")
    );
    // Most of the changes are refused: the test looked at refusals, not at passes.
    assert!(refused * 2 > tried, "{refused} of {tried} refused");
}
