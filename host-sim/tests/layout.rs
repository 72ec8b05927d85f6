//! host-sim's source reads from its tree: modules depend on each other one way
//! (no import cycle between the folders of `src/`), and no function is longer than
//! [`MAX_FN_LINES`].

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The longest function allowed, in lines from its signature to its closing brace.
const MAX_FN_LINES: usize = 100;

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("src readable").flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The top-level module a file belongs to (`world/step.rs` → `world`, `lib.rs` → ``).
fn module_of(file: &Path) -> String {
    let rel = file.strip_prefix(src()).expect("under src");
    let first = rel.components().next().expect("a component");
    let name = first.as_os_str().to_string_lossy();
    name.strip_suffix(".rs").unwrap_or(&name).to_string()
}

/// `crate::X` used in code (comments and doc comments do not count).
fn uses(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for line in text.lines() {
        let code = line.split("//").next().unwrap_or("");
        let mut rest = code;
        while let Some(i) = rest.find("crate::") {
            rest = &rest[i + "crate::".len()..];
            let name: String = rest
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            out.insert(name);
        }
    }
    out
}

/// A cycle in `graph` through `node`, if any (depth-first).
fn cycle(
    graph: &BTreeMap<String, BTreeSet<String>>,
    node: &str,
    path: &mut Vec<String>,
) -> Option<Vec<String>> {
    if let Some(i) = path.iter().position(|p| p == node) {
        let mut c = path[i..].to_vec();
        c.push(node.to_string());
        return Some(c);
    }
    path.push(node.to_string());
    for next in graph.get(node).into_iter().flatten() {
        if let Some(c) = cycle(graph, next, path) {
            return Some(c);
        }
    }
    path.pop();
    None
}

#[test]
fn modules_depend_on_each_other_one_way() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in &files {
        let m = module_of(f);
        if m == "lib" || m == "main" {
            continue;
        }
        let text = std::fs::read_to_string(f).expect("readable");
        let deps = graph.entry(m.clone()).or_default();
        deps.extend(uses(&text).into_iter().filter(|d| *d != m));
    }
    assert!(graph.len() >= 8, "{graph:?}");
    for m in graph.keys() {
        if let Some(c) = cycle(&graph, m, &mut Vec::new()) {
            panic!("import cycle: {}", c.join(" → "));
        }
    }
    // The test itself can see a cycle.
    let mut g = graph.clone();
    g.entry("monitor".into())
        .or_default()
        .insert("world".into());
    assert!(cycle(&g, "world", &mut Vec::new()).is_some());
}

/// Every `fn` item's length: from its signature line to the closing brace at its indent.
fn functions(text: &str) -> Vec<(usize, usize, String)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (i, l) in lines.iter().enumerate() {
        let t = l.trim_start();
        let t = t
            .strip_prefix("pub ")
            .or_else(|| t.strip_prefix("pub(crate) "))
            .unwrap_or(t);
        let t = t.strip_prefix("const ").unwrap_or(t);
        let Some(sig) = t.strip_prefix("fn ") else {
            continue;
        };
        let indent = l.len() - l.trim_start().len();
        let close = format!("{}}}", " ".repeat(indent));
        // A declaration without a body (in a trait) ends at its `;` before any `{`.
        let opens = lines[i..]
            .iter()
            .position(|x| x.contains('{') || x.trim_end().ends_with(';'));
        if opens.is_some_and(|o| !lines[i + o].contains('{')) {
            continue;
        }
        let one_line = l.trim_end().ends_with('}');
        let end = if one_line {
            1
        } else {
            lines[i..]
                .iter()
                .position(|x| x.trim_end() == close)
                .map_or(1, |n| n + 1)
        };
        let name = sig.split(['(', '<']).next().unwrap_or("").to_string();
        out.push((end, i + 1, name));
    }
    out
}

#[test]
fn functions_are_short_enough_to_read_at_once() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut long = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).expect("readable");
        for (n, line, name) in functions(&text) {
            if n > MAX_FN_LINES {
                let rel = f
                    .strip_prefix(src())
                    .expect("under src")
                    .display()
                    .to_string();
                long.push(format!("{rel}:{line} {name}: {n} lines"));
            }
        }
    }
    assert!(
        long.is_empty(),
        "longer than {MAX_FN_LINES} lines:\n{}",
        long.join("\n")
    );
    let probe = "fn a() {\n    x;\n}\n    pub fn b(\n        y: u8,\n    ) {\n    }\n";
    let got: Vec<(usize, String)> = functions(probe)
        .into_iter()
        .map(|(n, _, s)| (n, s))
        .collect();
    assert_eq!(got, vec![(3, "a".to_string()), (4, "b".to_string())]);
}
