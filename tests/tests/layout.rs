//! The library crates read from their trees (planner-core, can-gateway, host-sim):
//!
//! - modules depend on each other one way: no import cycle between the top-level folders
//!   of a crate, and none between its files either, counting `crate::`, `super::` and
//!   `self::` paths (grouped `use` paths included);
//! - no function is longer than [`MAX_FN_LINES`].
//!
//! A folder's `mod.rs` and the files it declares are one room, as smoltcp's
//! `wire/mod.rs` is: the files may use what `mod.rs` defines (the folder's shared
//! vocabulary) and `mod.rs` assembles and re-exports them, so edges between a module and
//! its own ancestors are not counted. Between the files of a folder, between folders and
//! across nesting levels otherwise, dependencies go one way. Unit-test modules
//! (`#[cfg(test)]`, at the end of a file) are left out: they are not part of the
//! structure.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The longest function allowed, in lines from its signature to its closing brace.
const MAX_FN_LINES: usize = 100;

/// The crates whose sources are read.
const CRATES: [&str; 3] = ["planner-core", "can-gateway", "host-sim"];

/// A module's path inside its crate: `["world", "step"]` for `world/step.rs`, `[]` for
/// `lib.rs` and `main.rs`, `["world"]` for `world/mod.rs`.
type ModPath = Vec<String>;

type Graph = BTreeMap<ModPath, BTreeSet<ModPath>>;

fn src(krate: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace")
        .join(krate)
        .join("src")
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

fn module_path(root: &Path, file: &Path) -> ModPath {
    let rel = file.strip_prefix(root).expect("under src");
    let mut parts: ModPath = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().to_string())
        .collect();
    if let Some(last) = parts.last_mut() {
        *last = last.trim_end_matches(".rs").to_string();
    }
    if parts.last().is_some_and(|l| l == "mod") || parts == ["lib"] || parts == ["main"] {
        parts.pop();
    }
    parts
}

/// The code of a file: its inline unit-test module (`#[cfg(test)] mod tests {`, at the
/// end of a file) and every comment removed.
fn code_of(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let end = lines
        .windows(2)
        .position(|w| {
            w[0].trim() == "#[cfg(test)]" && w[1].starts_with("mod ") && w[1].ends_with('{')
        })
        .unwrap_or(lines.len());
    lines[..end]
        .iter()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// `a::b::{c, d::e}` after a path's first segment → `[[a,b,c],[a,b,d,e]]`.
fn expand(rest: &str) -> Vec<Vec<String>> {
    let mut segs = Vec::new();
    let mut s = rest.trim_start();
    loop {
        if let Some(group) = s.strip_prefix('{') {
            return group_items(group)
                .into_iter()
                .flat_map(|item| expand(item.trim()))
                .map(|tail| segs.iter().cloned().chain(tail).collect())
                .collect();
        }
        let name: String = s
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        s = &s[name.len()..];
        if !name.is_empty() {
            segs.push(name);
        }
        match s.strip_prefix("::") {
            Some(after) => s = after.trim_start(),
            None => return vec![segs],
        }
    }
}

/// The top-level items of a `{…}` group, up to its closing brace.
fn group_items(group: &str) -> Vec<&str> {
    let (mut depth, mut start, mut out) = (0usize, 0usize, Vec::new());
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                out.push(&group[start..i]);
                return out;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                out.push(&group[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    out
}

/// Every module path named in `code` (written in module `me`), resolved to the longest
/// prefix that is a module.
fn named(code: &str, me: &ModPath, modules: &BTreeSet<ModPath>) -> BTreeSet<ModPath> {
    let mut out = BTreeSet::new();
    for (i, _) in code.match_indices("::") {
        let head_start = code[..i]
            .rfind(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .map_or(0, |j| j + 1);
        // Only a path's first segment: `a::b::c` is read once, at `a`.
        if code[..head_start].ends_with("::") {
            continue;
        }
        let base = match &code[head_start..i] {
            "crate" => Vec::new(),
            "self" => me.clone(),
            "super" => me[..me.len().saturating_sub(1)].to_vec(),
            _ => continue,
        };
        for path in expand(&code[i + 2..]) {
            let mut full = base.clone();
            for seg in path {
                if seg == "super" {
                    full.pop();
                } else {
                    full.push(seg);
                }
            }
            while !modules.contains(&full) && !full.is_empty() {
                full.pop();
            }
            out.insert(full);
        }
    }
    out
}

/// The file graph of a crate, with the edges between a module and its ancestors left out.
fn file_graph(krate: &str) -> Graph {
    let root = src(krate);
    let mut files = Vec::new();
    rust_files(&root, &mut files);
    let modules: BTreeSet<ModPath> = files.iter().map(|f| module_path(&root, f)).collect();
    let mut graph = Graph::new();
    for f in &files {
        let me = module_path(&root, f);
        let code = code_of(&std::fs::read_to_string(f).expect("readable"));
        let deps = named(&code, &me, &modules)
            .into_iter()
            .filter(|d| !d.starts_with(&me) && !me.starts_with(d));
        graph.entry(me.clone()).or_default().extend(deps);
    }
    graph
}

/// The same graph between top-level folders.
fn folder_graph(files: &Graph) -> Graph {
    let mut graph = Graph::new();
    for (from, tos) in files {
        let Some(top) = from.first() else { continue };
        let deps = graph.entry(vec![top.clone()]).or_default();
        for to in tos {
            if let Some(t) = to.first().filter(|t| *t != top) {
                deps.insert(vec![t.clone()]);
            }
        }
    }
    graph
}

/// A cycle in `graph` through `node`, if any (depth-first).
fn cycle(graph: &Graph, node: &ModPath, path: &mut Vec<ModPath>) -> Option<Vec<ModPath>> {
    if let Some(i) = path.iter().position(|p| p == node) {
        let mut c = path[i..].to_vec();
        c.push(node.clone());
        return Some(c);
    }
    path.push(node.clone());
    for next in graph.get(node).into_iter().flatten() {
        if let Some(c) = cycle(graph, next, path) {
            return Some(c);
        }
    }
    path.pop();
    None
}

fn any_cycle(graph: &Graph) -> Option<String> {
    graph.keys().find_map(|m| {
        cycle(graph, m, &mut Vec::new()).map(|c| {
            c.iter()
                .map(|p| p.join("/"))
                .collect::<Vec<_>>()
                .join(" → ")
        })
    })
}

#[test]
fn modules_depend_on_each_other_one_way() {
    for krate in CRATES {
        let files = file_graph(krate);
        assert!(files.len() >= 6, "{krate}: {files:?}");
        if let Some(c) = any_cycle(&files) {
            panic!("{krate}: import cycle between files: {c}");
        }
        if let Some(c) = any_cycle(&folder_graph(&files)) {
            panic!("{krate}: import cycle between folders: {c}");
        }
    }
    // The reader sees what it must: a grouped `super::` path, a `self::` one and a
    // nested group each give their module (ancestors and the module itself are named
    // too; the graph drops them).
    let modules: BTreeSet<ModPath> = [
        vec![],
        vec!["w".to_string()],
        vec!["w".to_string(), "a".to_string()],
        vec!["w".to_string(), "b".to_string()],
        vec!["x".to_string()],
    ]
    .into_iter()
    .collect();
    let me = vec!["w".to_string(), "a".to_string()];
    let code = "use super::{b::Thing, Other};\nlet _ = crate::x::f(self::g());";
    let got = named(code, &me, &modules);
    let want: BTreeSet<ModPath> = [&["w"][..], &["w", "b"], &["w", "a"], &["x"]]
        .iter()
        .map(|p| p.iter().map(|s| s.to_string()).collect())
        .collect();
    assert_eq!(got, want);
    let nested = named("use crate::{w::{a::X, b}, x};", &vec![], &modules);
    assert_eq!(nested.len(), 3, "{nested:?}");
    // The test itself can see a cycle between files of one folder.
    let mut g = file_graph("host-sim");
    let (step, vehicle) = (
        vec!["world".to_string(), "step".to_string()],
        vec!["world".to_string(), "vehicle".to_string()],
    );
    assert!(g.get(&step).is_some_and(|d| d.contains(&vehicle)), "{g:?}");
    g.entry(vehicle).or_default().insert(step);
    assert!(any_cycle(&g).is_some());
}

/// Every `fn` item's length: from its signature line to the closing brace at its indent.
fn functions(text: &str) -> Vec<(usize, usize, String)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (i, l) in lines.iter().enumerate() {
        let t = l.trim_start();
        let t = ["pub ", "pub(crate) ", "pub(super) "]
            .iter()
            .find_map(|p| t.strip_prefix(p))
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
    let mut long = Vec::new();
    for krate in CRATES {
        let root = src(krate);
        let mut files = Vec::new();
        rust_files(&root, &mut files);
        for f in &files {
            let text = std::fs::read_to_string(f).expect("readable");
            for (n, line, name) in functions(&text) {
                if n > MAX_FN_LINES {
                    let rel = f.strip_prefix(&root).expect("under src").display();
                    long.push(format!("{krate}/src/{rel}:{line} {name}: {n} lines"));
                }
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
