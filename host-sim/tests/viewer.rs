//! The viewer page in a real browser (issue 16): Debian's chromium, headless, driven by
//! Playwright (`tests/viewer/check_viewer.py`), on a road, an intersection, a network and
//! a fleet run over CAN frames. Needs `python3 -m pip install playwright` and `chromium`
//! (README lists the test prerequisites; `.ci/run` installs them). Without them the test
//! fails and says what is missing — unless `HOST_SIM_SKIP_BROWSER=1`, which it then
//! reports loudly as skipped.

use std::path::{Path, PathBuf};
use std::process::Command;

fn scenario(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(name)
}

fn browser_available() -> Result<(), String> {
    let py = Command::new("python3")
        .args(["-c", "import playwright.sync_api"])
        .output()
        .map_err(|e| format!("python3: {e}"))?;
    if !py.status.success() {
        return Err("Python playwright is missing: python3 -m pip install playwright".into());
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
    let check = Command::new("python3")
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
        if std::env::var("HOST_SIM_SKIP_BROWSER").as_deref() == Ok("1") {
            eprintln!("SKIPPED (HOST_SIM_SKIP_BROWSER=1): the browser test needs {why}");
            return;
        }
        panic!("{why} (or set HOST_SIM_SKIP_BROWSER=1 to skip this test, loudly)");
    }
    check("multilane.toml", &[]);
    check("intersection-queues.toml", &[]);
    check("corridor.toml", &[]);
    check("intersection.toml", &["--bus", "can-hub"]);
}
