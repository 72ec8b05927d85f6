//! The trace alone judges a straight road: `tools/check_trace.py`, which reads nothing but
//! a `--trace` file (its lengths, widths, braking limits and invariants as columns, the
//! rule in `output/trace.rs`), agrees with the monitor on the shipped straight roads under
//! both invariants, and finds what is wrong in a trace made wrong.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::support;

fn out_dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("host-sim-trace-check-{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("a temporary folder");
    d
}

/// `host-sim run scenarios/NAME --invariant INV --trace`: the trace's path.
fn trace(name: &str, invariant: &str, dir: &Path) -> PathBuf {
    let file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(name);
    let out = dir.join(format!("{name}-{invariant}.csv"));
    let run = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .arg("run")
        .arg(&file)
        .args(["--invariant", invariant, "--trace"])
        .arg(&out)
        .output()
        .expect("host-sim runs");
    assert!(
        run.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    out
}

/// The checker's JSON verdict on `trace` (`pairs`, `credited`, `violations`, `first`: the
/// first violations), and its exit code.
fn check(trace: &Path) -> (serde_json::Value, Option<i32>) {
    let out = Command::new(support::python())
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/check_trace.py"))
        .arg(trace)
        .arg("--json")
        .output()
        .expect("python3 runs");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!("{e}: {}", String::from_utf8_lossy(&out.stderr));
    });
    (v, out.status.code())
}

/// (pairs judged, credited, violations) of a verdict.
fn counts(v: &serde_json::Value) -> (u64, u64, u64) {
    let n = |k: &str| v[k].as_u64().expect("a count");
    (n("pairs"), n("credited"), n("violations"))
}

#[test]
fn the_trace_alone_judges_every_pair_as_the_monitor_does() {
    let dir = out_dir();
    for name in ["multilane.toml", "stop-and-go.toml", "road-end.toml"] {
        for invariant in ["paper", "leader-aware"] {
            let (v, code) = check(&trace(name, invariant, &dir));
            let (pairs, credited, violations) = counts(&v);
            assert_eq!((violations, code), (0, Some(0)), "{name} {invariant}");
            assert!(pairs > 1_000, "{name} {invariant}: {pairs} pairs");
            // Credit only where followers keep the leader-aware invariant, and there
            // toward most leaders (scripted leaders are `none`: never credited).
            match invariant {
                "paper" => assert_eq!(credited, 0, "{name}"),
                _ => assert!(credited * 10 > pairs, "{name}: {credited} of {pairs}"),
            }
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_trace_made_wrong_is_judged_wrong() {
    let dir = out_dir().join("wrong");
    std::fs::create_dir_all(&dir).expect("a folder");
    let good = trace("multilane.toml", "leader-aware", &dir);
    let text = std::fs::read_to_string(&good).expect("the trace");
    // The same run claimed under the paper's invariant: its followers were closer than
    // walls allow, so the checker must find them.
    let paper = dir.join("claimed-paper.csv");
    std::fs::write(&paper, text.replace(",leader-aware\n", ",paper\n")).expect("written");
    let (v, code) = check(&paper);
    let (_, credited, violations) = counts(&v);
    assert_eq!(credited, 0);
    assert!(violations > 0 && code == Some(1), "{violations} violations");
    // Every vehicle but one follower that needed the credit claimed as keeping no
    // invariant: that follower may credit none of them, so it is judged wrong again.
    let follower = v["first"][0]["follower"]
        .as_u64()
        .expect("a follower")
        .to_string();
    let none = dir.join("claimed-none.csv");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for l in lines.iter_mut().skip(1) {
        let id = l.split(',').nth(1).unwrap_or_default();
        if id != follower {
            if let Some(stripped) = l.strip_suffix(",leader-aware") {
                *l = format!("{stripped},none");
            }
        }
    }
    std::fs::write(&none, lines.join("\n") + "\n").expect("written");
    let (v, code) = check(&none);
    let (_, _, violations) = counts(&v);
    assert!(violations > 0 && code == Some(1), "{violations} violations");
    let _ = std::fs::remove_dir_all(dir);
}
