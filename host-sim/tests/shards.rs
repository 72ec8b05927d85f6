//! Sharded sweeps: four shards run as separate processes and merged give the
//! unsharded result field for field (wall-clock times aside; floats to 1e-9 relative), and
//! shards that do not belong together are refused.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
}

fn json_of(args: &[&str]) -> Value {
    let out = bin().args(args).output().expect("host-sim runs");
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{args:?}: {e}\n{}", String::from_utf8_lossy(&out.stderr)))
}

fn dir(name: &str) -> PathBuf {
    // Tests run in parallel: every call its own directory.
    static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("shards-{}-{name}-{k}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

/// Runs `sweep` (one or more command words) with `args` in `n` shards, each its own
/// process, concurrently.
fn shards(sweep: &[&str], args: &[&str], n: u64) -> Vec<PathBuf> {
    let d = dir(&sweep.join("-"));
    let children: Vec<(PathBuf, std::process::Child)> = (0..n)
        .map(|i| {
            let path = d.join(format!("shard-{i}.json"));
            let file = std::fs::File::create(&path).expect("shard file");
            let child = bin()
                .args(sweep)
                .args(args)
                .args(["--shard", &format!("{i}/{n}"), "--json"])
                .stdout(file)
                .spawn()
                .expect("a shard starts");
            (path, child)
        })
        .collect();
    children
        .into_iter()
        .map(|(path, mut c)| {
            c.wait().expect("a shard ends");
            path
        })
        .collect()
}

fn merged(files: &[PathBuf]) -> Value {
    let mut args = vec!["merge".to_string(), "--json".to_string()];
    args.extend(files.iter().map(|f| f.display().to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    json_of(&args)
}

/// Field-for-field equality, wall-clock times aside.
fn same(key: &str, a: &Value, b: &Value) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let kx: Vec<&String> = x.keys().collect();
            let ky: Vec<&String> = y.keys().collect();
            assert_eq!(kx, ky, "keys of {key}");
            for (k, v) in x {
                if k != "wall_seconds" {
                    same(&format!("{key}.{k}"), v, &y[k]);
                }
            }
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{key}");
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                same(&format!("{key}[{i}]"), p, q);
            }
        }
        (Value::Number(p), Value::Number(q)) if p.is_f64() || q.is_f64() => {
            let (p, q) = (
                p.as_f64().unwrap_or(f64::NAN),
                q.as_f64().unwrap_or(f64::NAN),
            );
            assert!(
                (p - q).abs() <= 1e-9 * p.abs().max(q.abs()).max(1e-300),
                "{key}: {p} against {q}"
            );
        }
        _ => assert_eq!(a, b, "{key}"),
    }
}

fn check(sweep: &str, args: &[&str]) {
    check_command(&[sweep], args);
}

fn check_command(sweep: &[&str], args: &[&str]) {
    let mut whole: Vec<&str> = sweep.to_vec();
    whole.extend_from_slice(args);
    whole.push("--json");
    let unsharded = json_of(&whole);
    let files = shards(sweep, args, 4);
    same(&sweep.join(" "), &merged(&files), &unsharded);
}

#[test]
fn four_platoon_shards_merge_into_the_unsharded_sweep() {
    check("platoons", &["--cases", "12", "--seed", "5"]);
}

#[test]
fn four_traffic_shards_merge_into_the_unsharded_sweep() {
    check(
        "traffic",
        &["--cases", "6", "--duration", "3", "--seed", "9"],
    );
}

#[test]
fn four_traffic_comparison_shards_merge_into_the_unsharded_comparison() {
    // Its cost given up and iterations ratio are ratios of sums: the merge recomputes them.
    check(
        "traffic",
        &[
            "--cases",
            "5",
            "--duration",
            "2",
            "--seed",
            "3",
            "--compare",
            "--reuse",
        ],
    );
}

#[test]
fn four_experiment_shards_merge_into_the_unsharded_experiments() {
    // Means, standard deviations and ratios are not sums of parts: these merge the runs
    // and aggregate them once. Three multi-lane runs in four shards leave one empty.
    check_command(
        &["experiment", "multilane"],
        &["--seeds", "3", "--seed", "4"],
    );
    check_command(
        &["experiment", "throughput"],
        &["--seeds", "2", "--duration", "15", "--loss", "0.2"],
    );
    check_command(
        &["experiment", "faults"],
        &[
            "--seeds",
            "2",
            "--throughput-seeds",
            "1",
            "--duration",
            "15",
        ],
    );
}

#[test]
fn four_fault_grid_and_demand_shards_merge_into_the_unsharded_experiments() {
    // One loss, one delay: five cells (the grid's one and the four variants) × every
    // workload, one run each.
    check_command(
        &["experiment", "faults"],
        &[
            "--grid", "--losses", "0.5", "--delays", "0.1", "--runs", "1",
        ],
    );
    // Rates given in another order are the same experiment (it runs them ascending).
    check_command(
        &["experiment", "demand"],
        &[
            "--rates",
            "200,100",
            "--duration",
            "60",
            "--seeds",
            "2",
            "--algorithms",
            "PIPE,STOP",
        ],
    );
}

#[test]
fn four_liveness_shards_merge_into_the_unsharded_sweeps() {
    check("deadends", &["--cases", "3", "--seed", "2"]);
    check("crossings", &["--cases", "2", "--seed", "2"]);
}

#[test]
fn four_red_team_shards_merge_into_the_unsharded_sweeps() {
    for sweep in ["outages", "liars", "ids", "layouts"] {
        check(sweep, &["--cases", "2", "--seed", "7"]);
    }
    check(
        "grids",
        &["--cases", "2", "--duration", "20", "--seed", "7"],
    );
}

#[test]
fn shards_that_do_not_belong_together_are_refused() {
    let a = shards(&["platoons"], &["--cases", "4", "--seed", "1"], 2);
    let b = shards(&["deadends"], &["--cases", "2", "--seed", "1"], 2);
    let refused = |files: &[&Path], says: &str| {
        let out = bin().arg("merge").args(files).output().expect("runs");
        assert_eq!(out.status.code(), Some(2), "{files:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{err}");
        assert!(out.stdout.is_empty());
    };
    refused(&[&a[0], &a[0]], "shard 0 is given twice");
    refused(&[&a[0]], "shard 1 is missing");
    refused(&[&a[0], &b[1]], "different sweeps");
    let c = shards(&["platoons"], &["--cases", "4", "--seed", "2"], 2);
    refused(&[&a[0], &c[1]], "other settings");
    let junk = dir("junk").join("junk.json");
    std::fs::write(&junk, "{}").expect("write");
    refused(&[&junk], "not a shard's output");
    // A bad --shard is refused before anything runs.
    let out = bin()
        .args(["platoons", "--shard", "4/4"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
}
