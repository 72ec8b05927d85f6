//! Outputs are written whole or not at all: a refused run (bad input, exit 2) or a run
//! that fails part-way (a CAN bus error, exit 4) leaves every existing output file
//! byte-identical, and a complete run replaces it in one rename, leaving no temporary
//! file behind. One test per output flag: `--trace`, `--plot`, `--html`, `--output`
//! (the JSON or summary to a file) and the experiments' `--plot`.

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
}

fn scenario(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(name)
}

/// A fresh directory for one test.
fn dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("host-sim-outputs-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

/// The names in `d`, sorted.
fn listing(d: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(d)
        .expect("dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// What a user already had at an output's path.
const OLD: &[u8] = b"precious bytes the user already had\n";

/// Runs `host-sim` with `args`, where `{out}` stands for `path` (which holds [`OLD`]);
/// checks the exit code and that `path` still holds exactly [`OLD`] and nothing was left
/// beside it.
fn refused_leaves(path: &Path, args: &[&str], code: i32) {
    std::fs::write(path, OLD).expect("old output");
    let args: Vec<String> = args
        .iter()
        .map(|a| a.replace("{out}", &path.display().to_string()))
        .collect();
    let out = bin().args(&args).output().expect("runs");
    assert_eq!(
        out.status.code(),
        Some(code),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        std::fs::read(path).expect("still there"),
        OLD,
        "{args:?} touched {}",
        path.display()
    );
    let d = path.parent().expect("dir");
    assert_eq!(
        listing(d),
        vec![path.file_name().unwrap().to_string_lossy().into_owned()],
        "{args:?} left a file behind"
    );
}

/// A typo in the scenario's name, an unknown bus option and a bad seed are refused with
/// exit 2; each leaves the output as it was.
fn refusals(flag: &str, path: &Path) {
    let good = scenario("road-end.toml").display().to_string();
    let cases: [Vec<&str>; 3] = [
        vec!["run", "scenarios/road_end.toml", flag, "{out}"],
        vec!["run", &good, flag, "{out}", "--can-fd"],
        vec!["run", &good, flag, "{out}", "--seed", "nope"],
    ];
    for args in &cases {
        refused_leaves(path, args, 2);
    }
}

/// A bus that cannot be used (an interface no kernel has): refused up front (2) where
/// the kernel has no CAN, or failing when the fleet opens its sockets (4) where it has;
/// either way the output is as it was.
fn bus_failure(flag: &str, path: &Path) {
    let good = scenario("road-end.toml").display().to_string();
    let out = bin()
        .args(["run", &good, "--bus", "nosuchcan9"])
        .output()
        .expect("runs");
    // On machines without CAN this is refused up front (2), elsewhere it fails at open
    // (4): either way nothing may be touched.
    let code = out.status.code().expect("exit code");
    assert!(code == 2 || code == 4, "{code}");
    refused_leaves(
        path,
        &["run", &good, "--bus", "nosuchcan9", flag, "{out}"],
        code,
    );
}

/// The complete run replaces the old content in place and leaves nothing beside it.
fn completes(flag: &str, path: &Path, check: impl Fn(&[u8])) {
    std::fs::write(path, OLD).expect("old output");
    let out = bin()
        .arg("run")
        .arg(scenario("road-end.toml"))
        .arg(flag)
        .arg(path)
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bytes = std::fs::read(path).expect("written");
    assert_ne!(bytes, OLD);
    check(&bytes);
    assert_eq!(listing(path.parent().expect("dir")).len(), 1);
}

#[test]
fn trace_is_replaced_only_by_a_complete_run() {
    let p = dir("trace").join("trace.csv");
    refusals("--trace", &p);
    bus_failure("--trace", &p);
    completes("--trace", &p, |b| {
        assert!(b.starts_with(b"t,id,x,y,theta"));
    });
}

#[test]
fn plot_is_replaced_only_by_a_complete_run() {
    let p = dir("plot").join("road-end.png");
    refusals("--plot", &p);
    bus_failure("--plot", &p);
    completes("--plot", &p, |b| assert!(b.starts_with(b"\x89PNG")));
}

#[test]
fn html_is_replaced_only_by_a_complete_run() {
    let p = dir("html").join("road-end.html");
    refusals("--html", &p);
    bus_failure("--html", &p);
    completes("--html", &p, |b| {
        assert!(String::from_utf8_lossy(b).contains("<html"));
    });
}

#[test]
fn output_file_is_replaced_only_by_a_complete_run() {
    let p = dir("output").join("summary.json");
    refusals("--output", &p);
    bus_failure("--output", &p);
    std::fs::write(&p, OLD).expect("old");
    let out = bin()
        .arg("run")
        .arg(scenario("road-end.toml"))
        .arg("--json")
        .arg("--output")
        .arg(&p)
        .output()
        .expect("runs");
    assert!(out.status.success());
    assert!(
        out.stdout.is_empty(),
        "with --output nothing goes to stdout"
    );
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&p).expect("written")).expect("JSON");
    assert_eq!(v["collisions"], 0);
    assert_eq!(listing(p.parent().expect("dir")).len(), 1);
}

/// An experiment's `--plot` too: refused arguments leave it, a complete run replaces it.
#[test]
fn experiment_plot_is_replaced_only_by_a_complete_run() {
    let p = dir("experiment").join("fig9.svg");
    refused_leaves(
        &p,
        &[
            "experiment",
            "throughput",
            "--duration",
            "-1",
            "--plot",
            "{out}",
        ],
        2,
    );
    std::fs::write(&p, OLD).expect("old");
    let out = bin()
        .args(["experiment", "throughput", "--duration", "5", "--plot"])
        .arg(&p)
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let svg = std::fs::read_to_string(&p).expect("written");
    assert!(svg.contains("<svg"));
    assert_eq!(listing(p.parent().expect("dir")).len(), 1);
}

/// A run killed part-way (a crash, a power cut, ^C) leaves the outputs as they were: the
/// targets are only ever replaced by a rename once complete.
#[test]
fn a_run_killed_part_way_leaves_every_output_as_it_was() {
    let d = dir("killed");
    let (trace, html, plot) = (d.join("t.csv"), d.join("v.html"), d.join("p.png"));
    for p in [&trace, &html, &plot] {
        std::fs::write(p, OLD).expect("old");
    }
    let mut child = bin()
        .arg("run")
        .arg(scenario("highway-100.toml"))
        .arg("--trace")
        .arg(&trace)
        .arg("--html")
        .arg(&html)
        .arg("--plot")
        .arg(&plot)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("starts");
    // Long enough for the run to be writing its trace (it takes tens of seconds).
    std::thread::sleep(std::time::Duration::from_millis(1500));
    assert!(
        child.try_wait().expect("status").is_none(),
        "the run ended before it could be killed"
    );
    child.kill().expect("killed");
    child.wait().expect("reaped");
    for p in [&trace, &html, &plot] {
        assert_eq!(std::fs::read(p).expect("there"), OLD, "{}", p.display());
    }
}
