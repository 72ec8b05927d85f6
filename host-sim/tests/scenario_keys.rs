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
    for (table, keys) in host_sim::scenario::keys::tables() {
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
