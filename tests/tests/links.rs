//! Every relative link in README.md and docs/ leads somewhere: the file exists, and an
//! anchor (`page.md#a-heading`) names a heading of that page as GitHub spells its anchors
//! (lower case, punctuation dropped, spaces as hyphens, repeats numbered -1, -2 …).

use std::collections::HashSet;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// The pages checked: README.md and every Markdown file under docs/.
fn pages() -> Vec<PathBuf> {
    let root = root();
    let mut out = vec![root.join("README.md")];
    let mut dirs = vec![root.join("docs")];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir)
            .expect("docs/ is readable")
            .flatten()
        {
            let p = entry.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|e| e == "md") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// GitHub's anchor for a heading's text.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

/// The lines of a Markdown page outside fenced code blocks (and not their fences).
fn prose(text: &str) -> impl Iterator<Item = &str> {
    let mut fenced = false;
    text.lines().filter(move |line| {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            return false;
        }
        !fenced
    })
}

/// The anchors of a Markdown page: its headings' slugs (outside code blocks), numbered
/// as GitHub numbers repeats.
fn anchors(text: &str) -> HashSet<String> {
    let mut out = HashSet::new();
    for line in prose(text).filter(|l| l.starts_with('#')) {
        let base = slug(line.trim_start_matches('#').replace('`', "").as_str());
        let mut name = base.clone();
        let mut n = 0;
        while out.contains(&name) {
            n += 1;
            name = format!("{base}-{n}");
        }
        out.insert(name);
    }
    out
}

/// The targets of the inline links `[text](target)` of a page, outside code.
fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in prose(text) {
        let mut rest = line;
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let Some(end) = after.find(')') else { break };
            out.push(after[..end].to_string());
            rest = &after[end..];
        }
    }
    out
}

#[test]
fn every_relative_link_and_anchor_resolves() {
    let mut broken = Vec::new();
    let mut checked = 0;
    for page in pages() {
        let text = std::fs::read_to_string(&page).expect("readable");
        let dir = page.parent().map(Path::to_path_buf).unwrap_or_default();
        for target in links(&text) {
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            checked += 1;
            let (file, anchor) = target.split_once('#').unwrap_or((target.as_str(), ""));
            let path = if file.is_empty() {
                page.clone()
            } else {
                dir.join(file)
            };
            if !path.exists() {
                broken.push(format!("{}: {target} (no such file)", page.display()));
                continue;
            }
            if anchor.is_empty() || path.extension().is_none_or(|e| e != "md") {
                continue;
            }
            let page_anchors = anchors(&std::fs::read_to_string(&path).unwrap_or_default());
            if !page_anchors.contains(anchor) {
                broken.push(format!("{}: {target} (no such heading)", page.display()));
            }
        }
    }
    assert!(
        checked > 50,
        "only {checked} links found: is the parser blind?"
    );
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

/// The checker itself: GitHub's slugs, repeats numbered, code blocks and absolute links
/// left alone.
#[test]
fn the_checker_reads_links_and_headings_as_github_does() {
    assert_eq!(
        slug("Networks that freeze, and networks that finish"),
        "networks-that-freeze-and-networks-that-finish"
    );
    assert_eq!(
        slug("1. The invariant (Lemma 3)"),
        "1-the-invariant-lemma-3"
    );
    let a = anchors("# A\n## A\n```\n# not a heading\n```\n### `code` b\n");
    assert!(a.contains("a") && a.contains("a-1") && a.contains("code-b"));
    assert!(!a.contains("not-a-heading"));
    assert_eq!(
        links("see [x](a.md#b) and [y](https://e.org) ![p](docs/p.png)\n```\n[z](no.md)\n```"),
        ["a.md#b", "https://e.org", "docs/p.png"]
    );
}
