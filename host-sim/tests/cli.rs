//! The `host-sim` binary: exit codes, JSON, traces, plots, argument checking.

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

/// Parses stdout as one JSON object holding every key in `keys`.
fn json_with(stdout: &[u8], keys: &[&str]) -> serde_json::Value {
    let v: serde_json::Value = serde_json::from_slice(stdout).expect("one JSON object");
    for key in keys {
        assert!(v.get(key).is_some(), "missing {key}: {v}");
    }
    v
}

/// Runs `cmd`, requires it to succeed, and parses its stdout as [`json_with`] does.
fn json_of(cmd: &mut Command, keys: &[&str]) -> serde_json::Value {
    let out = cmd.output().expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    json_with(&out.stdout, keys)
}

fn tmp(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("host-sim-cli-{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temp dir");
    d.join(name)
}

#[test]
fn run_writes_json_trace_and_plots() {
    let trace = tmp("road-end.csv");
    let png = tmp("road-end.png");
    let out = bin()
        .args(["run"])
        .arg(scenario("road-end.toml"))
        .args(["--json", "--trace"])
        .arg(&trace)
        .arg("--plot")
        .arg(&png)
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = json_with(
        &out.stdout,
        &[
            "scenario",
            "vehicles",
            "sim_seconds",
            "collisions",
            "invariant_violations",
            "min_gap_m",
            "fallback_steps",
            "completed",
        ],
    );
    assert_eq!(v["collisions"], 0);
    assert_eq!(v["completed"], true);
    let csv = std::fs::read_to_string(&trace).expect("trace written");
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("t,id,x,y,theta,v,omega,lane,target_lane,mode,place,length,width,brake,invariant")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // 10 vehicles × 6000 steps.
    assert_eq!(rows.len(), 60_000);
    for r in &rows {
        assert_eq!(r.len(), 15);
        // road-end.toml names no invariant: the default, the leader-aware one.
        assert_eq!(r[11..], ["4.5", "1.7", "7.9", "leader-aware"], "{r:?}");
        assert_eq!(r[10], "s0", "a straight road is segment 0");
        assert!(r[..7].iter().all(|x| x.parse::<f64>().is_ok()), "{r:?}");
        assert!(
            [
                "cruise",
                "lane_change",
                "yield",
                "fallback",
                "waiting",
                "crossing",
                "done"
            ]
            .contains(&r[9]),
            "{r:?}"
        );
    }
    let bytes = std::fs::read(&png).expect("png written");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let svg = tmp("road-end.svg");
    let out = bin()
        .arg("run")
        .arg(scenario("road-end.toml"))
        .arg("--plot")
        .arg(&svg)
        .output()
        .expect("runs");
    assert!(out.status.success());
    // On a terminal (no --json) the summary says where the picture went.
    let human = String::from_utf8_lossy(&out.stdout);
    assert!(
        human.contains(&format!("wrote {}", svg.display())),
        "{human}"
    );
    assert!(human.contains("SAFE"), "{human}");
    let text = std::fs::read_to_string(&svg).expect("svg written");
    assert!(text.starts_with("<svg") && text.contains("road-end"));
}

#[test]
fn bad_input_exits_2_and_runs_nothing() {
    let trace = tmp("never.csv");
    let _ = std::fs::remove_file(&trace);
    // Bad plot extension: rejected before the run; no trace file appears.
    let out = bin()
        .arg("run")
        .arg(scenario("road-end.toml"))
        .arg("--trace")
        .arg(&trace)
        .args(["--plot", "out.jpg"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains(".png or .svg"));
    assert!(!trace.exists());
    // A plot into a directory that does not exist: refused before the run, no JSON.
    let out = bin()
        .arg("run")
        .arg(scenario("stop-and-go.toml"))
        .arg("--json")
        .args(["--plot", "/nonexistent-dir/x.png"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    assert!(out.stdout.is_empty());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--plot /nonexistent-dir/x.png"), "{err}");
    // Same for the viewer page.
    let out = bin()
        .arg("run")
        .arg(scenario("road-end.toml"))
        .args(["--html", "/nonexistent-dir/x.html"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--html /nonexistent-dir/x.html"));
    // Bad scenario: file:line: problem on stderr.
    let bad = tmp("bad.toml");
    std::fs::write(&bad, "name = \"x\"\nduration_s = 5.0\nwhat = 1\n").expect("write");
    let out = bin().arg("run").arg(&bad).output().expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.toml:3:"), "{err}");
    // Unknown solver, unknown flag: clap's usage errors, exit 2.
    let out = bin()
        .arg("run")
        .arg(scenario("road-end.toml"))
        .args(["--solver", "cplex"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let out = bin()
        .args(["scale", "--vehicles", "0"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let out = bin()
        .args(["scale", "--duration", "-3"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    // A clock that cannot start there; f32 with a solver the MCU does not have.
    for args in [
        vec!["--clock-start", "-1"],
        vec!["--clock-start", "NaN"],
        vec!["--clock-start", "2e9"],
        vec!["--precision", "f32", "--solver", "clarabel"],
        vec!["--precision", "f16"],
        // A cut that is no cut: longer than the file's duration_s, empty, not a time.
        vec!["--duration", "1000"],
        vec!["--duration", "0"],
        vec!["--duration", "NaN"],
    ] {
        let out = bin()
            .arg("run")
            .arg(scenario("road-end.toml"))
            .args(&args)
            .output()
            .expect("runs");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(out.stdout.is_empty(), "{args:?}");
    }
}

/// `--duration` cuts a run short, and a deadline past the cut comes forward to it: the
/// goal the vehicle has not reached by then is missed (exit 3).
#[test]
fn a_run_cut_short_ends_there_and_is_judged_there() {
    let f = tmp("cut.toml");
    std::fs::write(
        &f,
        "name = \"cut\"\nduration_s = 8.0\n[road]\nlanes = 1\n[[vehicle]]\nid = 1\nx = 0.0\nlane = 0\nv = 10.0\ngoal_x = 60.0\n",
    )
    .expect("write");
    let run = |cut: &str| {
        let out = bin()
            .arg("run")
            .arg(&f)
            .args(["--json", "--duration", cut])
            .output()
            .expect("runs");
        let v = json_with(&out.stdout, &["completed", "sim_seconds"]);
        (out.status.code(), v)
    };
    let (code, v) = run("8");
    assert_eq!(
        (code, &v["completed"]),
        (Some(0), &serde_json::json!(true)),
        "{v}"
    );
    let (code, v) = run("2.5");
    assert_eq!(code, Some(3), "{v}");
    assert_eq!(v["completed"], false);
    assert_eq!(v["sim_seconds"], 2.5);
}

#[test]
fn missed_liveness_goal_exits_3() {
    let f = tmp("unreachable.toml");
    std::fs::write(
        &f,
        "name = \"far\"\nduration_s = 2.0\n[road]\nlanes = 1\n[[vehicle]]\nid = 1\nx = 0.0\nlane = 0\nv = 10.0\ngoal_x = 1000.0\n",
    )
    .expect("write");
    let out = bin()
        .arg("run")
        .arg(&f)
        .arg("--json")
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(3));
    let v = json_with(&out.stdout, &["completed"]);
    assert_eq!(v["completed"], false);
}

#[test]
fn scale_prints_its_figures() {
    let v = json_of(
        bin().args(["scale", "--vehicles", "60", "--duration", "2", "--json"]),
        &[
            "vehicles",
            "sim_seconds",
            "wall_seconds",
            "realtime_factor",
            "planner_steps_per_second",
        ],
    );
    assert_eq!(v["vehicles"], 60);
    assert_eq!(v["collisions"], 0);
    assert_eq!(v["kind"], "platoons");
    // Every follower plans every step and solves it; the leader drives at random.
    assert_eq!(v["solves_per_step"], 1.0);
    assert_eq!(v["step"]["steps"], 57 * 200);
    let p = |k: &str| v["step"][k].as_f64().expect("µs");
    assert!(0.0 < p("p50_us") && p("p50_us") <= p("p90_us") && p("p90_us") <= p("p99_us"));
    assert!(p("p99_us") <= p("max_us"));
}

#[test]
fn scale_traffic_changes_lanes_densely_and_safely_and_the_sweep_plots() {
    let v = json_of(
        bin().args([
            "scale",
            "--vehicles",
            "60",
            "--duration",
            "4",
            "--traffic",
            "--json",
        ]),
        &["kind", "step", "solves_per_step", "lane_changes"],
    );
    assert_eq!(v["kind"], "traffic");
    assert_eq!(
        (v["collisions"].clone(), v["invariant_violations"].clone()),
        (0.into(), 0.into())
    );
    assert!(v["lane_changes"].as_u64().expect("count") > 0, "{v}");
    assert!(
        v["lateral_iterations_per_step"].as_f64().expect("mean") > 0.0,
        "{v}"
    );
    assert_eq!(v["step"]["steps"], 60 * 400);

    let plot = tmp("scale.svg");
    let _ = std::fs::remove_file(&plot);
    let v = json_of(
        bin()
            .args([
                "scale",
                "--sweep",
                "--sweep-vehicles",
                "10,20",
                "--sweep-threads",
                "1",
            ])
            .args(["--duration", "0.5", "--json", "--plot"])
            .arg(&plot),
        &["runs", "sim_seconds"],
    );
    let runs = v["runs"].as_array().expect("runs");
    let kinds: Vec<(&str, u64)> = runs
        .iter()
        .map(|r| {
            (
                r["kind"].as_str().unwrap_or(""),
                r["vehicles"].as_u64().unwrap_or(0),
            )
        })
        .collect();
    assert_eq!(
        kinds,
        [
            ("platoons", 10),
            ("platoons", 20),
            ("traffic", 10),
            ("traffic", 20)
        ]
    );
    let svg = std::fs::read_to_string(&plot).expect("the plot");
    assert!(
        svg.contains("<svg") && svg.contains("Traffic, 1 thread"),
        "{plot:?}"
    );
    // The sweep's flags need --sweep; a bad list is refused before anything runs.
    for bad in [
        vec!["--sweep-vehicles", "10"],
        vec!["--sweep", "--sweep-threads", "0"],
        vec!["--sweep", "--plot", "x.txt"],
    ] {
        let out = bin().arg("scale").args(&bad).output().expect("runs");
        assert_eq!(out.status.code(), Some(2), "{bad:?}");
    }
}

/// `scale --compare`: the same roads with the solver as before its active-set step (the
/// interior-point method alone) and with the default solver, both safe, the active-set
/// step answering most solves in fewer Newton steps at the same closed-loop cost (both
/// find the optima); with `--reuse` the current arm also skips solves. Bad settings are
/// refused before anything runs.
#[test]
fn scale_compares_the_solver_with_the_interior_point_method_alone() {
    let keys = [
        "baseline",
        "current",
        "speedup",
        "iterations_ratio",
        "tracking_cost_change",
    ];
    let args = [
        "scale",
        "--vehicles",
        "40",
        "--duration",
        "2",
        "--compare",
        "--json",
    ];
    let v = json_of(bin().args(args), &keys);
    for arm in ["baseline", "current"] {
        let r = &v[arm];
        assert_eq!(
            (r["collisions"].clone(), r["invariant_violations"].clone()),
            (0.into(), 0.into()),
            "{arm}: {r}"
        );
        assert_eq!(r["step"]["steps"], 38 * 200, "{arm}");
        assert_eq!(r["reuse"], serde_json::Value::Null, "{arm}");
    }
    assert_eq!(v["baseline"]["solver"], "ours_interior_point");
    assert_eq!(v["current"]["solver"], "ours");
    let f = |a: &str, k: &str| v[a][k].as_f64().expect("number");
    assert_eq!(f("baseline", "active_set_share"), 0.0);
    assert!(f("current", "active_set_share") > 0.5, "{v}");
    assert_eq!(
        f("baseline", "solves_per_step"),
        f("current", "solves_per_step")
    );
    assert!(v["iterations_ratio"].as_f64().expect("ratio") < 0.75, "{v}");
    // Both solve to the same tolerance: the closed loops cost the same to 1e-6.
    let change = v["tracking_cost_change"].as_f64().expect("change");
    assert!(change.abs() < 1e-6, "{change}");

    // With --reuse the current arm also applies certified plans without solving.
    let v = json_of(bin().args(args).arg("--reuse"), &keys);
    let f = |a: &str, k: &str| v[a][k].as_f64().expect("number");
    assert_eq!(v["baseline"]["reuse"], serde_json::Value::Null);
    assert_eq!(v["current"]["reuse"]["tolerance"], 0.01);
    assert_eq!(v["current"]["reuse"]["max_age"], 4);
    let reuses = f("current", "reuses_per_step");
    assert!(reuses > 0.0, "{v}");
    // Every planner step either solved or reused (or braked without either).
    assert!((f("current", "solves_per_step") + reuses) <= 1.0 + 1e-12);
    assert!(f("current", "certified_gap_per_reuse") > 0.0);
    // What reuse gives up on the road is small: within a percent of the closed-loop cost.
    let change = v["tracking_cost_change"].as_f64().expect("change");
    assert!(change.abs() < 0.01, "{change}");
    for bad in [
        vec!["--reuse-tolerance", "-1"],
        vec!["--reuse-tolerance", "NaN"],
        vec!["--compare", "--sweep"],
        vec!["--solver", "fastest"],
    ] {
        let out = bin().arg("scale").args(&bad).output().expect("runs");
        assert_eq!(out.status.code(), Some(2), "{bad:?}");
    }
}

#[test]
fn bench_can_carries_every_message_in_each_configuration() {
    let v = json_of(
        bin().args(["bench-can", "--messages", "400", "--json"]),
        &["results"],
    );
    let rows = v["results"].as_array().expect("rows");
    let configs: Vec<&str> = rows.iter().filter_map(|r| r["config"].as_str()).collect();
    assert_eq!(configs, ["classic", "classic+secoc", "fd", "fd+secoc"]);
    // A state is 4 classic frames, 5 with its authenticator, and 1 CAN FD frame either way.
    for (r, frames) in rows.iter().zip([1600, 2000, 400, 400]) {
        assert_eq!(r["received"], 400, "{r}");
        assert_eq!(r["frames"], frames, "{r}");
    }
}

#[test]
fn experiment_attacks_prints_its_rows_and_refuses_unknown_names() {
    let v = json_of(
        bin().args([
            "experiment",
            "attacks",
            "--only",
            "forged-grant",
            "--world",
            "intersection",
            "--json",
        ]),
        &["medium", "authenticated", "can_fd", "algorithm", "results"],
    );
    let rows = v["results"].as_array().expect("rows");
    assert_eq!(rows.len(), 1);
    for key in [
        "attack",
        "attempts",
        "accepted",
        "collisions",
        "invariant_violations",
        "unpermitted_entries",
        "completed",
    ] {
        assert!(rows[0].get(key).is_some(), "{key}: {}", rows[0]);
    }
    assert_eq!(rows[0]["accepted"], 0);
    assert!(rows[0]["clean_done_at_s"].is_f64(), "{}", rows[0]);
    // Without the baseline run, its figures are null.
    let v = json_of(
        bin()
            .args([
                "experiment",
                "attacks",
                "--only",
                "flood",
                "--world",
                "multilane",
            ])
            .args(["--no-baseline", "--json"]),
        &["results"],
    );
    let row = &v["results"][0];
    assert_eq!(row["attack"], "flood");
    assert!(
        row["clean_done_at_s"].is_null() && row["clean_wall_seconds"].is_null(),
        "{row}"
    );
    assert!(row["done_at_s"].is_f64(), "{row}");
    for bad in [
        ["--only", "teleport"],
        ["--world", "moon"],
        ["--algorithm", "CON"],
        ["--bus", "not/an/iface"],
    ] {
        let out = bin()
            .args(["experiment", "attacks"])
            .args(bad)
            .output()
            .expect("runs");
        assert_eq!(out.status.code(), Some(2), "{bad:?}");
        assert!(out.stdout.is_empty(), "{bad:?}");
    }
}

#[test]
fn clarabel_can_drive_the_planners() {
    // A follower closing on a braking leader, planned by Clarabel: the verifier accepts
    // its plans (no fallback) and the run is safe.
    let f = tmp("clarabel.toml");
    std::fs::write(
        &f,
        "name = \"cl\"\nduration_s = 3.0\n[road]\nlanes = 1\n\
         [[vehicle]]\nid = 1\nx = 0.0\nlane = 0\nv = 15.0\ndriver = \"script\"\n\
         script = [{ until_s = 1.0, accel = -7.9 }]\n\
         [[vehicle]]\nid = 2\nx = -40.0\nlane = 0\nv = 15.0\n",
    )
    .expect("write");
    let out = bin()
        .arg("run")
        .arg(&f)
        .args(["--json", "--solver", "clarabel"])
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = json_with(&out.stdout, &["solver", "fallback_steps", "collisions"]);
    assert_eq!(v["solver"], "clarabel");
    assert_eq!(v["fallback_steps"], 0, "{v}");
    assert_eq!(v["collisions"], 0);
}

#[test]
fn experiment_multilane_prints_its_json_and_a_plot() {
    let png = tmp("fig7.png");
    let out = bin()
        .args([
            "experiment",
            "multilane",
            "--seeds",
            "3",
            "--json",
            "--plot",
        ])
        .arg(&png)
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = json_with(
        &out.stdout,
        &[
            "runs",
            "collisions",
            "invariant_violations",
            "completed",
            "max_completion_time_s",
            "mean_completion_time_s",
            "max_lane_change_distance_m",
            "bound_m",
        ],
    );
    assert_eq!(v["runs"], 3);
    assert_eq!(v["completed"], 3);
    assert_eq!(v["collisions"], 0);
    let bytes = std::fs::read(&png).expect("plot written");
    assert!(bytes.starts_with(b"\x89PNG"), "a PNG");
    // Bad arguments: exit 2, nothing run.
    for args in [
        vec!["experiment", "multilane", "--seeds", "0"],
        vec!["experiment", "multilane", "--plot", "x.gif"],
        vec!["experiment", "nowhere"],
        vec!["traffic", "--duration", "0"],
    ] {
        let out = bin().args(&args).output().expect("runs");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
    }
}

#[test]
fn a_multilane_scenario_runs_with_clarabel_too() {
    let out = bin()
        .arg("run")
        .arg(scenario("multilane.toml"))
        .args(["--json", "--solver", "clarabel"])
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = json_with(&out.stdout, &["solver", "collisions", "lane_changes"]);
    assert_eq!(v["solver"], "clarabel");
    assert_eq!(v["collisions"], 0);
    assert_eq!(v["invariant_violations"], 0);
    assert_eq!(v["completed"], true, "{v}");
}

#[test]
fn intersection_run_and_throughput_experiment() {
    let png = tmp("fig8.png");
    let out = bin()
        .arg("run")
        .arg(scenario("intersection.toml"))
        .args(["--json", "--plot"])
        .arg(&png)
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = json_with(
        &out.stdout,
        &["scenario", "completed", "crossed", "collisions"],
    );
    assert_eq!(v["completed"], true);
    assert_eq!(v["crossed"], 8);
    assert!(std::fs::read(&png).expect("plot").starts_with(b"\x89PNG"));
    let bars = tmp("fig9.svg");
    let out = bin()
        .args([
            "experiment",
            "throughput",
            "--duration",
            "20",
            "--seeds",
            "1",
            "--json",
            "--plot",
        ])
        .arg(&bars)
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = json_with(&out.stdout, &["results"]);
    let rows = v["results"].as_array().expect("rows");
    assert_eq!(rows.len(), planner_core::crossing::Algorithm::ALL.len());
    for row in rows {
        for k in [
            "algorithm",
            "crossed_mean",
            "crossed_std",
            "crossing_time_mean_s",
            "crossing_time_max_s",
            "collisions",
            "invariant_violations",
        ] {
            assert!(row.get(k).is_some(), "{k} in {row}");
        }
    }
    assert!(std::fs::read_to_string(&bars)
        .expect("svg")
        .contains("<svg"));
    for args in [
        vec!["experiment", "throughput", "--duration", "-1"],
        vec!["experiment", "throughput", "--seeds", "0"],
        vec!["experiment", "throughput", "--plot", "x.bmp"],
    ] {
        let out = bin().args(&args).output().expect("runs");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
    }
}

/// `--auth` and `--keys`: a key file authenticates the fleet; a bad one, or
/// authentication without a CAN bus, is refused before anything runs, naming the file
/// and the key.
#[test]
fn key_files_are_checked_and_authenticate_the_fleet() {
    let good = tmp("keys-good.toml");
    std::fs::write(
        &good,
        "master = \"000102030405060708090a0b0c0d0e0f\"\n[nodes]\n\"0xF1\" = \"ffeeddccbbaa99887766554433221100\"\n",
    )
    .expect("write");
    let out = bin()
        .arg("run")
        .arg(scenario("intersection.toml"))
        .args(["--bus", "can-hub", "--json", "--keys"])
        .arg(&good)
        .output()
        .expect("runs");
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = json_with(&out.stdout, &["authenticated", "can"]);
    assert_eq!(v["authenticated"], true);
    assert_eq!(v["can"]["rejected"], serde_json::json!({}));
    for (name, text, says) in [
        (
            "keys-short.toml",
            "master = \"0011\"\n",
            "master: a key is 32 hex digits, not 4",
        ),
        (
            "keys-hex.toml",
            "[nodes]\n\"5\" = \"zz0102030405060708090a0b0c0d0e0f\"\n",
            "nodes.5: \"zz\" is not hex",
        ),
        (
            "keys-addr.toml",
            "[nodes]\n\"0x100\" = \"000102030405060708090a0b0c0d0e0f\"\n",
            "\"0x100\" is not an address",
        ),
        ("keys-none.toml", "", "no key"),
        (
            "keys-extra.toml",
            "master = \"000102030405060708090a0b0c0d0e0f\"\nsalt = 1\n",
            "unknown field",
        ),
    ] {
        let f = tmp(name);
        std::fs::write(&f, text).expect("write");
        let out = bin()
            .arg("run")
            .arg(scenario("intersection.toml"))
            .args(["--bus", "can-hub", "--keys"])
            .arg(&f)
            .output()
            .expect("runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains(name) && err.contains(says), "{name}: {err}");
        assert!(out.stdout.is_empty());
    }
    let out = bin()
        .arg("run")
        .arg(scenario("intersection.toml"))
        .arg("--auth")
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--bus can-hub"));
}

/// The summary agrees with itself, in text and in JSON: in the open grid (vehicles still
/// arriving at the end) goals met, unfinished and under way add up to the vehicles with
/// goals, and the text claims every goal met only when none is under way; in the closed
/// corridor every vehicle's goals are met and counted as such.
#[test]
fn summaries_agree_with_themselves_in_text_and_json() {
    for (name, open) in [("grid-3x3.toml", true), ("corridor.toml", false)] {
        let v = json_of(
            bin().arg("run").arg(scenario(name)).arg("--json"),
            &["goals", "goals_met", "unfinished", "under_way", "completed"],
        );
        let n = |k: &str| v[k].as_u64().expect("a count");
        assert!(n("goals") > 0, "{name}: {v}");
        assert_eq!(
            n("goals"),
            n("goals_met") + n("unfinished") + n("under_way"),
            "{name}: {v}"
        );
        assert_eq!(v["completed"], true, "{name}: {v}");
        assert_eq!(n("under_way") > 0, open, "{name}: {v}");
        let out = bin().arg("run").arg(scenario(name)).output().expect("runs");
        let text = String::from_utf8_lossy(&out.stdout);
        let claims_all = text.contains("every goal met");
        assert_eq!(claims_all, !open, "{name}: {text}");
        if open {
            let done = format!("{} of {} vehicles done", n("goals_met"), n("goals"));
            assert!(text.contains(&done), "{name}: {text}");
        }
    }
}

/// `run --firmware` checks the world and the vehicles before it starts any QEMU, and
/// refuses what a computer in the loop cannot be: each refusal is bad input (exit 2),
/// says why, and writes nothing.
#[test]
fn firmware_in_the_loop_refuses_what_it_cannot_run() {
    // Any existing file stands for the image: the checks come before it is run.
    let elf = scenario("multilane.toml");
    let refused = |file: &str, extra: &[&str], why: &str| {
        let trace = tmp(&format!("firmware-refused-{why}.csv").replace(' ', "-"));
        let out = bin()
            .arg("run")
            .arg(scenario(file))
            .arg("--firmware")
            .arg(&elf)
            .args(extra)
            .arg("--trace")
            .arg(&trace)
            .output()
            .expect("runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{file} {extra:?}: {err}");
        assert!(err.contains(why), "{file} {extra:?}: {err}");
        assert!(!trace.exists(), "{file} {extra:?} wrote its trace");
    };
    refused(
        "intersection.toml",
        &["--firmware-vehicles", "1"],
        "drives a road",
    );
    refused(
        "multilane.toml",
        &["--firmware-vehicles", "2", "--invariant", "leader-aware"],
        "paper's invariant",
    );
    refused(
        "multilane-faults.toml",
        &["--firmware-vehicles", "2", "--invariant", "paper"],
        "no [faults]",
    );
    refused(
        "multilane.toml",
        &["--firmware-vehicles", "99"],
        "vehicle 99 is not",
    );
    refused(
        "multilane.toml",
        &["--firmware-vehicles", "2,2"],
        "named twice",
    );
    refused(
        "multilane.toml",
        &["--firmware-vehicles", "2", "--firmware-board", "an999"],
        "an386, an500 or an505",
    );
    refused(
        "multilane.toml",
        &["--firmware-vehicles", "2", "--bus", "can-hub"],
        "in-process bus",
    );
    let out = bin()
        .arg("run")
        .arg(scenario("multilane.toml"))
        .args(["--firmware", "/nonexistent/sil", "--firmware-vehicles", "2"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no such file"));
    // The two flags go together.
    let out = bin()
        .arg("run")
        .arg(scenario("multilane.toml"))
        .arg("--firmware")
        .arg(&elf)
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
}
