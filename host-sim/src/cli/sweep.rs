//! The theorems' sweeps: `platoons` (Theorem 1), `traffic` (Theorem 2), `deadends`
//! (Theorem 3), `crossings` (Theorems 4 and 5).

use super::output::{check_duration, code, finish, out, print_json, say, EXIT_BAD_INPUT};
use host_sim::experiments::shard::{self, Header, Output, Shard};
use serde_json::{json, Value};
use std::path::PathBuf;
use std::process::ExitCode;

/// `host-sim platoons`.
#[derive(clap::Args)]
pub struct PlatoonsArgs {
    /// Number of random platoons.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..))]
    cases: u64,
    /// Seed of the sweep.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The followers reuse their certified previous plan instead of solving every step
    /// (planner-core's `ReusePolicy::default()`).
    #[arg(long)]
    reuse: bool,
    /// The invariant every follower keeps toward the vehicle ahead (the adversarial
    /// leader, scripted, is a wall under either).
    #[arg(long, value_enum, default_value = "paper")]
    invariant: super::InvariantArg,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
    /// Run only shard I of N (0-based) and print it as JSON for `host-sim merge`.
    #[arg(long, value_name = "I/N")]
    shard: Option<Shard>,
}

/// `host-sim traffic`.
#[derive(clap::Args)]
pub struct TrafficArgs {
    /// Number of random cases.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    cases: u64,
    /// Seed of the first case.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulated seconds per case.
    #[arg(long, default_value_t = 20.0)]
    duration: f64,
    /// The planners reuse their certified previous plan instead of solving every step
    /// (planner-core's `ReusePolicy::default()`).
    #[arg(long)]
    reuse: bool,
    /// Also run every case with the interior-point method alone, solving every step (the
    /// planner before the active-set step), and report the closed-loop cost given up against it.
    #[arg(long)]
    compare: bool,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, value_enum, default_value = "paper")]
    invariant: super::InvariantArg,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
    /// Run only shard I of N (0-based) and print it as JSON for `host-sim merge`.
    #[arg(long, value_name = "I/N")]
    shard: Option<Shard>,
}

/// Theorem 1 sweep.
pub fn platoons(a: PlatoonsArgs) -> ExitCode {
    let (first, end) = a.shard.unwrap_or(Shard::ALL).range(a.cases);
    use host_sim::experiments::platoon::{sweep_range, Following};
    let following = Following {
        reuse: a.reuse,
        invariant: a.invariant.invariant(),
    };
    let s = sweep_range(first, end, a.seed, following);
    let safe =
        s.collisions + s.invariant_violations + s.limit_violations == 0 && s.cases == end - first;
    let mut settings = json!({"cases": a.cases, "seed": a.seed, "reuse": a.reuse});
    if a.invariant == super::InvariantArg::LeaderAware {
        // Only then: shards of a paper sweep keep their settings as before.
        settings["invariant"] = json!("leader-aware");
    }
    let out = Out {
        sweep: "platoons",
        settings,
        shard: a.shard,
        range: (first, end),
        json: a.json,
    };
    out.print(&s, safe)
}

/// Theorem 2 sweep (with `--compare`, beside the every-step baseline).
pub fn traffic(a: TrafficArgs) -> ExitCode {
    use host_sim::experiments::traffic::{traffic_compare, traffic_sweep_with, Planning};
    if let Err(code) = check_duration(a.duration, 3600.0) {
        return code;
    }
    let (first, end) = a.shard.unwrap_or(Shard::ALL).range(a.cases);
    let leader_aware = a.invariant == super::InvariantArg::LeaderAware;
    let planning = Planning {
        reuse: a.reuse,
        leader_aware,
        ..Planning::DEFAULT
    };
    let mut settings = json!({
        "cases": a.cases, "seed": a.seed, "duration": a.duration, "reuse": a.reuse
    });
    if leader_aware {
        // Only then: shards of a paper sweep keep their settings as before.
        settings["invariant"] = json!("leader-aware");
    }
    if a.compare {
        // Only then: shards of a plain sweep keep their settings as before.
        settings["compare"] = json!(true);
    }
    // Case i's seed is seed + i: it depends on the index alone.
    let (cases, seed) = (end - first, a.seed + first);
    let out = Out {
        sweep: "traffic",
        settings,
        shard: a.shard,
        range: (first, end),
        json: a.json,
    };
    if a.compare {
        let r = traffic_compare(cases, seed, a.duration, 0, planning);
        out.print(&r, r.safe())
    } else {
        let r = traffic_sweep_with(cases, seed, a.duration, 0, planning);
        out.print(&r, r.safe())
    }
}

/// Where a sweep's result goes: a shard's envelope for `host-sim merge`, or the result
/// itself (JSON or text).
struct Out {
    sweep: &'static str,
    settings: Value,
    shard: Option<Shard>,
    range: (u64, u64),
    json: bool,
}

impl Out {
    /// Prints `r` and picks the exit code (a sweep's cases are not judged on liveness).
    fn print<T: serde::Serialize + std::fmt::Display>(self, r: &T, safe: bool) -> ExitCode {
        match self.shard {
            Some(sh) => emit(
                self.sweep,
                self.settings,
                sh,
                self.range,
                r,
                code(safe, true),
            ),
            None => finish(r, self.json, safe, true),
        }
    }
}

/// `host-sim deadends` and `host-sim crossings`.
#[derive(clap::Args)]
pub struct LivenessArgs {
    /// Number of random cases.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    cases: u64,
    /// Seed of the sweep (a case's own seed depends on this and its index alone).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
    /// Run only shard I of N (0-based) and print it as JSON for `host-sim merge`.
    #[arg(long, value_name = "I/N")]
    shard: Option<Shard>,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, value_enum, default_value = "paper")]
    invariant: super::InvariantArg,
}

/// Theorem 3 sweep.
pub fn deadends(a: LivenessArgs) -> ExitCode {
    let (first, end) = a.shard.unwrap_or(Shard::ALL).range(a.cases);
    let r = host_sim::experiments::deadends::sweep_with(
        end - first,
        first,
        a.seed,
        0,
        a.invariant.invariant(),
    );
    liveness("deadends", &a, (first, end), &r, &r.totals, &r.failing)
}

/// Theorems 4–5 sweep.
pub fn crossings(a: LivenessArgs) -> ExitCode {
    let (first, end) = a.shard.unwrap_or(Shard::ALL).range(a.cases);
    let r = host_sim::experiments::crossings::sweep_with(
        end - first,
        first,
        a.seed,
        0,
        a.invariant.invariant(),
    );
    liveness("crossings", &a, (first, end), &r, &r.totals, &r.failing)
}

/// `host-sim grids`.
#[derive(clap::Args)]
pub struct GridsArgs {
    /// Number of random grids.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(1..))]
    cases: u64,
    /// Seed of the sweep.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulated seconds per grid.
    #[arg(long, default_value_t = 180.0)]
    duration: f64,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, value_enum, default_value = "paper")]
    invariant: super::InvariantArg,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
    /// Run only shard I of N (0-based) and print it as JSON for `host-sim merge`.
    #[arg(long, value_name = "I/N")]
    shard: Option<Shard>,
}

/// Random grids: no collision, no deadlock.
pub fn grids(a: GridsArgs) -> ExitCode {
    if let Err(code) = check_duration(a.duration, 3600.0) {
        return code;
    }
    let (first, end) = a.shard.unwrap_or(Shard::ALL).range(a.cases);
    let invariant = a.invariant.invariant();
    let r = host_sim::experiments::network::grids(
        (end - first, first),
        a.seed,
        a.duration,
        invariant,
        0,
    );
    let safe =
        r.collisions + r.invariant_violations + r.limit_violations + r.unpermitted_entries == 0;
    let exit = code(safe, r.deadlocks == 0);
    let value = match serde_json::to_value(&r) {
        Ok(v) => v,
        Err(e) => return bad(&e.to_string()),
    };
    if let Some(sh) = a.shard {
        let mut settings = json!({"cases": a.cases, "seed": a.seed, "duration": a.duration});
        if invariant != planner_core::Invariant::Paper {
            // Only then: shards of a paper sweep keep their settings as before.
            settings["invariant"] = json!(host_sim::world::invariant_name(invariant));
        }
        return emit("grids", settings, sh, (first, end), &value, exit);
    }
    let notes: String = r
        .unfinished
        .iter()
        .map(|u| {
            format!(
                "\n  case {} ({}, {} lanes): {} of {} due trips done; {}",
                u.case, u.grid, u.lanes, u.due_completed, u.due, u.reason
            )
        })
        .collect();
    print_sweep("grids", a.cases, a.json, &value, &notes, &r.failing, exit)
}

/// `host-sim worlds`.
#[derive(Debug, clap::Args)]
pub struct WorldsArgs {
    /// World sizes (vehicles, comma-separated; each 1 to the 8x8 grid's capacity).
    #[arg(long, value_delimiter = ',', default_value = "100,500,1000,2000,5000")]
    vehicles: Vec<usize>,
    /// Simulated seconds per world.
    #[arg(long, default_value_t = 5.0)]
    duration: f64,
    /// Also run each world with every message delayed by this many seconds and jittered
    /// by up to as many more (at most 10, the loader's bound).
    #[arg(long)]
    delay: Option<f64>,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, value_enum, default_value = "paper")]
    invariant: super::InvariantArg,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// Worlds of each size: no collision, no violation, no blind step.
pub fn worlds(a: WorldsArgs) -> ExitCode {
    if let Err(code) = check_duration(a.duration, 600.0) {
        return code;
    }
    if a.delay
        .is_some_and(|d| !(d.is_finite() && d > 0.0 && d <= 10.0))
    {
        return bad("--delay must be in (0, 10] s");
    }
    if a.vehicles.contains(&0) {
        return bad("--vehicles: every size must be at least 1");
    }
    let r = match host_sim::experiments::worlds::worlds(
        &a.vehicles,
        a.duration,
        a.delay,
        a.invariant.invariant(),
    ) {
        Ok(r) => r,
        Err(e) if e.starts_with("internal") => {
            eprintln!("error: {e}");
            return ExitCode::from(super::output::EXIT_INTERNAL);
        }
        Err(e) => return bad(&e),
    };
    let exit = code(
        r.collisions + r.invariant_violations == 0,
        r.blind_steps == 0,
    );
    let value = match serde_json::to_value(&r) {
        Ok(v) => v,
        Err(e) => return bad(&e.to_string()),
    };
    let printed = if a.json {
        print_json(&value)
    } else {
        let mut text = String::from(
            "| vehicles | grid | delay (s) | sim s | wall s | × real time | cost vs clean | fallback steps | blind | collisions |\n|---|---|---|---|---|---|---|---|---|---|\n",
        );
        for w in &r.worlds {
            text += &format!(
                "| {} | {} | {} | {:.1} | {:.1} | {:.3} | {:.2} | {} | {} | {} |\n",
                w.vehicles,
                w.grid,
                w.delay_s,
                w.sim_seconds,
                w.wall_seconds,
                w.realtime_factor,
                w.cost_vs_clean,
                w.fallback_steps,
                w.blind_steps,
                w.collisions
            );
        }
        say(text.trim_end())
    };
    match printed {
        Ok(()) => exit,
        Err(c) => c,
    }
}

/// A sweep's report: one JSON object, or its numbers, `notes` (lines that say more of
/// some cases) and each failing case's reason and file.
fn print_sweep(
    sweep: &str,
    cases: u64,
    json: bool,
    value: &Value,
    notes: &str,
    failing: &[host_sim::experiments::sweep::Failing],
    exit: ExitCode,
) -> ExitCode {
    let printed = if json {
        print_json(value)
    } else {
        let mut text = format!("{sweep}, {cases} cases:\n{}{notes}", human(value));
        for f in failing {
            text += &format!(
                "\n\n# failing case {} ({}): {}\n{}",
                f.case, f.label, f.reason, f.scenario
            );
        }
        say(&text)
    };
    match printed {
        Ok(()) => exit,
        Err(c) => c,
    }
}

/// The red team's sweeps (`outages`, `liars`, `ids`): their shard's JSON, or the report
/// and its failing cases.
pub fn red_team(a: LivenessArgs, sweep: &'static str) -> ExitCode {
    use host_sim::experiments::redteam::{ids, junction_faults, Kind};
    let (first, end) = a.shard.unwrap_or(Shard::ALL).range(a.cases);
    let (value, failing, exit) = match sweep {
        "layouts" => {
            let r = host_sim::experiments::layouts::sweep(end - first, first, a.seed, 0);
            let exit = code(
                r.collisions + r.invariant_violations + r.limit_violations + r.unpermitted_entries
                    == 0,
                r.clean(),
            );
            (serde_json::to_value(&r), r.failing, exit)
        }
        "ids" => {
            let r = ids(end - first, first, a.seed, 0);
            let exit = code(
                r.collisions + r.invariant_violations + r.node_ids == 0,
                r.wrapped == r.cases,
            );
            (serde_json::to_value(&r), r.failing, exit)
        }
        _ => {
            let kind = if sweep == "liars" {
                Kind::Liars
            } else {
                Kind::Outages
            };
            let r = junction_faults(kind, end - first, first, a.seed, 0);
            let exit = code(r.safe(), r.live());
            (serde_json::to_value(&r), r.failing, exit)
        }
    };
    let value = match value {
        Ok(v) => v,
        Err(e) => return bad(&e.to_string()),
    };
    if let Some(sh) = a.shard {
        let settings = json!({"cases": a.cases, "seed": a.seed});
        return emit(sweep, settings, sh, (first, end), &value, exit);
    }
    print_sweep(sweep, a.cases, a.json, &value, "", &failing, exit)
}

/// A liveness sweep's answer: its shard's JSON, or the report.
fn liveness<T: serde::Serialize + std::fmt::Debug>(
    sweep: &str,
    a: &LivenessArgs,
    range: (u64, u64),
    r: &T,
    t: &host_sim::experiments::sweep::Totals,
    failing: &[host_sim::experiments::sweep::Failing],
) -> ExitCode {
    match a.shard {
        Some(sh) => {
            let mut settings = json!({"cases": a.cases, "seed": a.seed});
            if a.invariant == super::InvariantArg::LeaderAware {
                settings["invariant"] = json!("leader-aware");
            }
            emit(sweep, settings, sh, range, r, liveness_code(t))
        }
        None => report(r, a.json, t, failing),
    }
}

fn liveness_code(t: &host_sim::experiments::sweep::Totals) -> ExitCode {
    let safe =
        t.collisions + t.invariant_violations + t.limit_violations + t.unpermitted_entries == 0;
    code(safe, t.unfinished + t.deadlocks == 0)
}

/// Prints a shard's output (always JSON: it is for `host-sim merge`).
pub(super) fn emit<T: serde::Serialize>(
    sweep: &str,
    settings: Value,
    shard: Shard,
    (first, end): (u64, u64),
    result: &T,
    exit: ExitCode,
) -> ExitCode {
    let result = match serde_json::to_value(result) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    let header = Header {
        sweep: sweep.into(),
        settings,
        shard,
        first,
        end,
    };
    match print_json(&Output { header, result }) {
        Ok(()) => exit,
        Err(code) => code,
    }
}

/// `host-sim merge FILES…`: the shards of one sweep, combined into its unsharded result.
pub fn merge(files: &[PathBuf], json: bool) -> ExitCode {
    let mut parts = Vec::with_capacity(files.len());
    for f in files {
        let text = match std::fs::read_to_string(f) {
            Ok(t) => t,
            Err(e) => return bad(&format!("{}: {e}", f.display())),
        };
        match serde_json::from_str::<Output>(&text) {
            Ok(p) => parts.push(p),
            Err(e) => return bad(&format!("{}: not a shard's output ({e})", f.display())),
        }
    }
    let sweep = parts
        .first()
        .map(|p| p.header.sweep.clone())
        .unwrap_or_default();
    let merged = match shard::merge(parts) {
        Ok(m) => m,
        Err(e) => return bad(&format!("cannot merge: {e}")),
    };
    let exit = merged_exit(&sweep, &merged);
    let printed = if json {
        print_json(&merged)
    } else {
        say(&format!(
            "{sweep}, {} shards merged:\n{}",
            files.len(),
            human(&merged)
        ))
    };
    match printed {
        Ok(()) => exit,
        Err(code) => code,
    }
}

/// The exit code the unsharded run would give: unsafe events anywhere in the result (for
/// `experiment faults`, on the faulty bus only), unfinished vehicles or deadlocks, runs
/// that did not complete their lane changes. The fault grid reports liveness per cell and
/// judges safety alone; demand judges deadlocks per row.
fn merged_exit(sweep: &str, v: &Value) -> ExitCode {
    fn unsafe_events(v: &Value) -> u64 {
        const UNSAFE: [&str; 5] = [
            "collisions",
            "invariant_violations",
            "limit_violations",
            "unpermitted_entries",
            "node_ids",
        ];
        match v {
            Value::Object(m) => m
                .iter()
                .map(|(k, x)| match x.as_u64() {
                    Some(n) if UNSAFE.contains(&k.as_str()) => n,
                    _ => unsafe_events(x),
                })
                .sum(),
            Value::Array(a) => a.iter().map(unsafe_events).sum(),
            _ => 0,
        }
    }
    let n = |v: &Value, k: &str| v.get(k).and_then(Value::as_u64).unwrap_or(0);
    let events = match v.get("faulty_unsafe_events").and_then(Value::as_u64) {
        Some(e) => e,
        None => unsafe_events(v),
    };
    let runs = v.get("multilane_faulty").unwrap_or(v);
    let live = match sweep {
        // A liar costs liveness by design: the sweep judges safety.
        "faults-grid" | "liars" => true,
        "ids" => n(v, "wrapped") == n(v, "cases"),
        "grids" => n(v, "deadlocks") == 0,
        "layouts" => ["refused_without_line", "deadlocks", "internal_errors"]
            .iter()
            .all(|k| n(v, k) == 0),
        "demand" => v
            .get("results")
            .and_then(Value::as_array)
            .is_some_and(|rows| rows.iter().all(|r| n(r, "deadlocks") == 0)),
        _ => n(v, "unfinished") + n(v, "deadlocks") == 0 && n(runs, "completed") == n(runs, "runs"),
    };
    code(events == 0, live)
}

/// The top-level numbers of a merged result, one per line.
fn human(v: &Value) -> String {
    let Some(m) = v.as_object() else {
        return v.to_string();
    };
    m.iter()
        .filter(|(_, x)| x.is_number())
        .map(|(k, x)| format!("  {k}: {x}"))
        .collect::<Vec<_>>()
        .join("\n")
}

fn bad(msg: &str) -> ExitCode {
    eprintln!("error: {msg}");
    ExitCode::from(EXIT_BAD_INPUT)
}

/// Prints a liveness sweep (the failing cases' scenario files after a human summary) and
/// picks the exit code.
fn report<T: serde::Serialize + std::fmt::Debug>(
    r: &T,
    json: bool,
    t: &host_sim::experiments::sweep::Totals,
    failing: &[host_sim::experiments::sweep::Failing],
) -> ExitCode {
    if json {
        if let Err(code) = super::output::print_json(r) {
            return code;
        }
    } else {
        out!(
            "{} cases, {} vehicles: {} collisions, {} invariant violations, {} limit violations, \
             {} unpermitted entries, {} unfinished vehicles, {} deadlocks; every goal met by \
             {:.1} s at the latest",
            t.cases,
            t.vehicles,
            t.collisions,
            t.invariant_violations,
            t.limit_violations,
            t.unpermitted_entries,
            t.unfinished,
            t.deadlocks,
            t.max_finish_time_s
        );
        for f in failing {
            out!(
                "\n# failing case {} ({}): {}\n{}",
                f.case,
                f.label,
                f.reason,
                f.scenario
            );
        }
    }
    let safe =
        t.collisions + t.invariant_violations + t.limit_violations + t.unpermitted_entries == 0;
    super::output::code(safe, t.unfinished + t.deadlocks == 0)
}
