//! Safety off the paper's ideal world: the six files that broke it, through the
//! CLI as a user runs them, and their harder variants in-process. Safety may not rest on
//! the bus, on other vehicles' goodwill, or on inputs the loader let through.

use crate::common::{assert_safe, parse, run_world};
use std::path::PathBuf;
use std::process::Command;

fn file(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/issue21")
        .join(name)
}

fn text(name: &str) -> String {
    std::fs::read_to_string(file(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// `host-sim run FILE --json`: exit code, stdout, stderr.
fn run_cli(name: &str) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args(["run", "--json"])
        .arg(file(name))
        .output()
        .expect("host-sim runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn files_that_cannot_be_safe_are_refused_with_the_reason() {
    for (name, says) in [
        // An outlet ending inside A_C: vehicles would leave the system while others
        // still plan around them.
        (
            "A.toml",
            "A.toml:5: intersection: outlet_length: 40 m ends inside A_C",
        ),
        // Coordinates where f64 spacing is centimetres.
        (
            "F.toml",
            "F.toml:5: vehicle 1: x must be finite and within ±1000000 m",
        ),
    ] {
        let (code, stdout, stderr) = run_cli(name);
        assert_eq!(code, Some(2), "{name}: {stderr}");
        assert!(stderr.contains(says), "{name}: {stderr}");
        assert!(stdout.is_empty(), "{name}: nothing runs: {stdout}");
    }
}

#[test]
fn files_that_broke_safety_now_run_safely() {
    for name in ["B.toml", "C.toml", "D.toml", "E.toml"] {
        let (code, stdout, stderr) = run_cli(name);
        assert_eq!(code, Some(0), "{name}: {stderr}\n{stdout}");
        let s: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON object");
        for key in ["collisions", "invariant_violations", "limit_violations"] {
            assert_eq!(s[key], 0, "{name}: {key}: {stdout}");
        }
    }
}

/// `name` with its `faults = …` line replaced by `faults`.
fn with_faults(name: &str, faults: &str) -> String {
    text(name)
        .lines()
        .map(|l| {
            if l.starts_with("faults") {
                format!("faults = {faults}")
            } else {
                l.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn a_fully_braking_leader_at_the_smallest_gap_under_any_delay_loss_or_silence() {
    for faults in [
        "{ delay_s = 0.1 }",
        "{ delay_s = 0.5 }",
        "{ delay_s = 1.0 }",
        "{ delay_s = 0.1, jitter_s = 0.1, duplicate = 0.3, reorder = 0.3 }",
        "{ loss = 0.999 }",
        "{ silent = { id = 1, from_s = 0.0 } }",
    ] {
        let s = run_world(parse(&with_faults("C.toml", faults), "platoon-delay.toml"));
        assert_safe(&s);
        assert_eq!(s.collisions + s.invariant_violations, 0, "{faults}: {s:?}");
    }
}

#[test]
fn a_queue_at_an_all_way_stop_under_any_delay_or_loss() {
    for alg in ["stop", "fifo", "concurrent_fair", "pipelined"] {
        for faults in ["{ delay_s = 0.5 }", "{ delay_s = 1.0 }", "{ loss = 0.9 }"] {
            let t = with_faults("D.toml", faults)
                .replace("algorithm = \"stop\"", &format!("algorithm = \"{alg}\""));
            let s = run_world(parse(&t, "inter-delay.toml"));
            assert_safe(&s);
            assert_eq!(s.unpermitted_entries(), 0, "{alg} {faults}: {s:?}");
        }
    }
}

#[test]
fn two_vehicles_swap_lanes_at_any_loss() {
    for faults in ["{ loss = 0.9 }", "{ loss = 0.99 }", "{ loss = 0.999 }"] {
        let s = run_world(parse(&with_faults("B.toml", faults), "swap-lossy.toml"));
        assert_safe(&s);
    }
}

#[test]
fn a_driver_that_never_yields_is_not_cut_in_front_of_even_if_it_claims_to_cooperate() {
    // E's scripted driver accelerates and never yields. Scripts do not cooperate by
    // default; a lane change starts only when (17) holds as if the script never heard it,
    // and the change enters the script's lane only when the entry check holds then. Even a
    // script that claims to cooperate gets no less under the paper's invariant: the entry
    // check trusts no one. (Under the leader-aware one a claim to cooperate is a claim to
    // be credited as a leader, and a script that lies about it is a liar the plausibility
    // checks cannot see: `a_script_that_lies_about_cooperating_is_credited_but_not_hit`.)
    for (label, t) in [
        ("default", text("E.toml")),
        (
            "claims to cooperate",
            text("E.toml").replace(
                "driver = \"script\"",
                "cooperative = true, driver = \"script\"",
            ),
        ),
    ] {
        let t = t.replace(
            "duration_s = 10.0",
            "duration_s = 10.0\ninvariant = \"paper\"",
        );
        let spec = parse(&t, "cut-in.toml");
        let claims = spec
            .vehicles
            .iter()
            .find(|v| v.id == 2)
            .map(|v| v.cooperative);
        assert_eq!(claims, Some(label != "default"), "{label}");
        let s = run_world(spec);
        assert_safe(&s);
        assert_eq!(
            s.lane_changes.in_target_lane, 1,
            "{label}: {:?}",
            s.lane_changes
        );
    }
}

#[test]
fn a_script_that_lies_about_cooperating_is_credited_but_not_hit() {
    // Under the leader-aware invariant (the default) the planner credits a leader that
    // declares it cooperates and its braking limit: E's script, told to claim it, is
    // credited once the planner is behind it in its lane. The monitor credits only
    // vehicles that do keep the invariant (ground truth: planners), so it counts the
    // pair-steps that relied on the lie as violations; nothing is hit, because the liar
    // never brakes harder than it declared. A lie about cooperating is outside what a
    // receiver can check (docs/spec.md §11, "What breaks the induction"); the paper's
    // invariant, which credits no one, has none (the test above).
    let t = text("E.toml").replace(
        "driver = \"script\"",
        "cooperative = true, driver = \"script\"",
    );
    let honest = run_world(parse(&text("E.toml"), "cut-in.toml"));
    assert_safe(&honest);
    let s = run_world(parse(&t, "cut-in.toml"));
    assert_eq!((s.collisions, s.limit_violations), (0, 0), "{s:?}");
    assert!(
        s.invariant_violations > 0,
        "the lie was not relied on: {s:?}"
    );
    assert_eq!(s.lane_changes.in_target_lane, 1, "{:?}", s.lane_changes);
}
