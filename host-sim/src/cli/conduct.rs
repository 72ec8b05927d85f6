//! Every sweep and experiment the same way ([`Experiment`]): settings checked, then the
//! whole run or one shard, a plot if asked, the report printed, the exit code from its
//! verdict; and `host-sim merge`, which judges merged shards as the whole run would be.

use super::output::{bad_input, draw_plot, exit, finish, plot_output, print_json, say};
use super::output::{EXIT_BAD_INPUT, EXIT_BUS, EXIT_INTERNAL};
use host_sim::experiments::experiment::{run_shard, run_whole, Experiment, RunError};
use host_sim::experiments::shard::{Output, Shard};
use host_sim::experiments::sweep::human;
use serde::Serialize;
use std::fmt::Display;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// How a sweep or an experiment answers: `--json`, `--shard`.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct Answer {
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Run only shard I of N (0-based) of its cases and print it as JSON for `host-sim
    /// merge`.
    #[arg(long, value_name = "I/N")]
    pub shard: Option<Shard>,
}

/// A sweep: its settings and how it answers.
#[derive(clap::Args)]
pub struct SweepCmd<E: clap::Args> {
    /// Its settings.
    #[command(flatten)]
    pub settings: E,
    /// `--json`, `--shard`.
    #[command(flatten)]
    pub answer: Answer,
}

/// An experiment that is one run, not a set of cases to shard: its settings and `--json`.
#[derive(clap::Args)]
pub struct OneCmd<E: clap::Args> {
    /// Its settings.
    #[command(flatten)]
    pub settings: E,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Draws a report to a `.png` or `.svg` path.
pub type Drawing<'a, R> = &'a dyn Fn(&R, &Path) -> Result<(), String>;

/// Runs `e` as its flags say: settings refused before anything runs (exit 2); with
/// `--shard`, that shard's JSON for `host-sim merge` (exit by its own cases' verdict);
/// else the whole run ([`whole`]).
pub fn conduct<E>(
    e: &E,
    answer: Answer,
    plot: Option<(&PathBuf, Drawing<'_, E::Report>)>,
) -> ExitCode
where
    E: Experiment + Serialize,
    E::Part: Serialize,
    E::Report: Display,
{
    let Some(shard) = answer.shard else {
        return whole(e, answer.json, plot);
    };
    if let Err(err) = e.validate() {
        return bad_input(err);
    }
    match run_shard(e, shard, 0) {
        Ok((output, verdict)) => print_json(&output).map_or_else(|c| c, |()| exit(verdict)),
        Err(err) => internal(E::NAME, err),
    }
}

/// Runs all of `e`: settings refused before anything runs (exit 2), a plot's path
/// checked writable before the run, the report drawn and printed, and the exit code of
/// its verdict.
pub fn whole<E>(e: &E, json: bool, plot: Option<(&PathBuf, Drawing<'_, E::Report>)>) -> ExitCode
where
    E: Experiment,
    E::Report: Display,
{
    if let Err(err) = e.validate() {
        return bad_input(err);
    }
    let staged = match plot_output(plot.map(|(p, _)| p.as_path())) {
        Ok(s) => s,
        Err(code) => return code,
    };
    let report = match run_whole(e, 0) {
        Ok(r) => r,
        Err(err) => return internal(E::NAME, err),
    };
    if let (Some(out), Some((_, draw))) = (staged, plot) {
        let shown = out.target().display().to_string();
        if let Err(code) = draw_plot(out, |p| draw(&report, p)) {
            return code;
        }
        eprintln!("wrote {shown}");
    }
    finish(&report, json)
}

/// A run that failed after its settings were accepted: its bus (exit 4), or a bug, never
/// the input's fault (exit 5).
fn internal(name: &str, err: RunError) -> ExitCode {
    eprintln!("error: {name}: {err}");
    ExitCode::from(match err {
        RunError::Bus(_) => EXIT_BUS,
        RunError::Internal(_) => EXIT_INTERNAL,
    })
}

/// `host-sim merge FILES…`: the shards of one experiment, combined into its unsharded
/// result and judged by its own verdict.
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
    let (name, merged, verdict) = match host_sim::experiments::registry::merge(parts) {
        Ok(m) => m,
        Err(e) => return bad(&format!("cannot merge: {e}")),
    };
    let printed = if json {
        print_json(&merged)
    } else {
        say(&format!(
            "{name}, {} shards merged:\n{}",
            files.len(),
            human(&merged)
        ))
    };
    match printed {
        Ok(()) => exit(verdict),
        Err(code) => code,
    }
}

fn bad(msg: &str) -> ExitCode {
    eprintln!("error: {msg}");
    ExitCode::from(EXIT_BAD_INPUT)
}
