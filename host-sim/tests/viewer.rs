//! The viewer page in a real browser: Debian's chromium, headless, driven by Playwright
//! (`tests/viewer/check_viewer.py`), on a road, an intersection, a network and a fleet run
//! over CAN frames. README's test command (`scripts/test.sh`) sets up Playwright in a
//! virtual environment and chromium with apt-get; run bare, the test needs `python3` with
//! `playwright` and `chromium` on the PATH, and fails saying what is missing. It is
//! skipped only when the test script could not set them up (`TESTS_SKIP=browser`), with a
//! line in the normal output and in the script's list of skips.

use std::path::{Path, PathBuf};
use std::process::Command;

fn scenario(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(name)
}

use crate::support;
use support::{python, skip_or_fail};

fn browser_available() -> Result<(), String> {
    let py = Command::new(python())
        .args(["-c", "import playwright.sync_api"])
        .output()
        .map_err(|e| format!("{}: {e}", python()))?;
    if !py.status.success() {
        return Err(format!("Python playwright is missing from {}", python()));
    }
    let found = ["chromium", "chromium-browser"].iter().any(|b| {
        Command::new("sh")
            .args(["-c", &format!("command -v {b}")])
            .output()
            .is_ok_and(|o| o.status.success())
    });
    if !found {
        return Err("chromium is missing: apt-get install chromium".into());
    }
    Ok(())
}

/// Runs `file` with `--html` and `--trace` (and `extra`), then the browser check.
fn check(file: &str, extra: &[&str]) {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("viewer-{}-{file}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let (html, trace) = (dir.join("page.html"), dir.join("trace.csv"));
    let out = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .arg("run")
        .arg(scenario(file))
        .arg("--html")
        .arg(&html)
        .arg("--trace")
        .arg(&trace)
        .args(extra)
        .output()
        .expect("host-sim runs");
    assert!(
        out.status.success(),
        "{file}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let human = String::from_utf8_lossy(&out.stdout);
    assert!(
        human.contains(&format!("wrote {}", html.display())),
        "{human}"
    );
    let check = Command::new(python())
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/viewer/check_viewer.py"))
        .arg(&html)
        .arg(&trace)
        .output()
        .expect("python3 runs");
    println!("{file}: {}", String::from_utf8_lossy(&check.stdout));
    assert!(
        check.status.success(),
        "{file}: {}{}",
        String::from_utf8_lossy(&check.stdout),
        String::from_utf8_lossy(&check.stderr)
    );
}

#[test]
fn the_viewer_plays_road_intersection_network_and_fleet_runs_in_chromium() {
    if let Err(why) = browser_available() {
        let test = "host-sim viewer test (the page in chromium)";
        return skip_or_fail("browser", test, &why);
    }
    check("multilane.toml", &[]);
    check("intersection-queues.toml", &[]);
    check("corridor.toml", &[]);
    check("intersection.toml", &["--bus", "can-hub"]);
    check("trucks.toml", &[]);
}
