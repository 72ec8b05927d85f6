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

/// Every text file of the repository under `dir` (sources, docs, scripts, scenarios),
/// skipping build outputs, virtual environments and git's own.
fn text_files(dir: &Path, out: &mut Vec<PathBuf>) {
    const SKIP: [&str; 4] = ["target", ".git", ".venv", "test-python"];
    const TEXT: [&str; 12] = [
        "md", "rs", "toml", "sh", "py", "html", "yaml", "yml", "sbatch", "dbc", "svg", "x",
    ];
    for entry in std::fs::read_dir(dir).expect("readable").flatten() {
        let p = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if p.is_dir() {
            if !SKIP.contains(&name.as_str()) {
                text_files(&p, out);
            }
        } else if p.extension().is_some_and(|e| TEXT.iter().any(|t| e == *t))
            || ["run", "init", "Containerfile"].contains(&name.as_str())
        {
            out.push(p);
        }
    }
}

/// Where `text` cites a tracker or a file the repository does not hold: "issue N" (the
/// tracker's numbers mean nothing to a reader of a clone) or the folder beside the
/// checkout where the project's work was specified.
fn outside_citations(text: &str) -> Vec<String> {
    let lower = text.to_lowercase();
    let mut found = Vec::new();
    for (i, _) in lower.match_indices("issue") {
        let rest = lower[i + "issue".len()..].trim_start_matches('s');
        let rest = rest.strip_prefix(' ').unwrap_or("x");
        if rest
            .trim_start_matches('#')
            .starts_with(|c: char| c.is_ascii_digit())
        {
            found.push(lower[i..(i + 12).min(lower.len())].to_string());
        }
    }
    for needle in [concat!("../", "shared"), concat!("shared/", "spec.md")] {
        found.extend(lower.match_indices(needle).map(|(_, s)| s.to_string()));
    }
    found
}

/// The repository stands alone: no source, page, script or scenario cites "issue N" of
/// a tracker a clone does not have, or the folder beside the checkout; the spec it cites
/// is docs/spec.md.
#[test]
fn the_repository_cites_nothing_it_does_not_hold() {
    let mut files = Vec::new();
    text_files(&root(), &mut files);
    assert!(files.len() > 150, "only {} files found", files.len());
    let mut bad = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap_or_default();
        for hit in outside_citations(&text) {
            bad.push(format!("{}: {hit}", f.display()));
        }
    }
    assert!(
        bad.is_empty(),
        "citations of what a clone lacks:\n{}",
        bad.join("\n")
    );
}

/// The citation finder finds what it must and nothing else.
#[test]
fn the_citation_finder_sees_issue_numbers_and_the_shared_folder() {
    // Written in pieces, so that this file does not cite them itself.
    let issue = "Issue";
    assert_eq!(
        outside_citations(&format!("fixed ({issue} 14, item 2)")).len(),
        1
    );
    assert_eq!(
        outside_citations(&format!("{issue}s 35 and 42; {issue} #7")).len(),
        2
    );
    assert_eq!(
        outside_citations(&format!("see ../{}/SPEC.md", "shared")).len(),
        2
    );
    assert!(outside_citations("a known issue in 2 cases; issues: none").is_empty());
}
