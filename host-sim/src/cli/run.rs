//! `host-sim run FILE`: a scenario — a road, an intersection or a network — every vehicle
//! its own planner, talking only over the bus; its trace, plot and viewer page.

use super::output::{
    bad_input, check_plot, commit, exit, print_json, staged, EXIT_BUS, EXIT_FIRMWARE, EXIT_INTERNAL,
};
use host_sim::firmware::{Board, FirmwareSpec};
use host_sim::output::plot::PlotData;
use host_sim::output::staged::Staged;
use host_sim::output::trace::TraceWriter;
use host_sim::output::viewer::Viewer;
use host_sim::verdict::Judged;
use host_sim::world::summary::Summary;
use host_sim::world::{SolverChoice, TraceRow, World, WorldSpec};
use std::io::{BufWriter, IsTerminal};
use std::path::PathBuf;
use std::process::ExitCode;

/// What `run` was asked.
pub struct RunArgs {
    /// The scenario file.
    pub file: PathBuf,
    /// Overrides the scenario's seed.
    pub seed: Option<u64>,
    /// Cuts the run short (s).
    pub duration: Option<f64>,
    /// One JSON object instead of the human summary.
    pub json: bool,
    /// CSV trace.
    pub trace: Option<PathBuf>,
    /// PNG/SVG plot.
    pub plot: Option<PathBuf>,
    /// The viewer page (HTML).
    pub html: Option<PathBuf>,
    /// The multi-lane planners' solver.
    pub solver: SolverChoice,
    /// `in-process`, `can-hub`, or an interface.
    pub bus: String,
    /// Authenticate every message.
    pub auth: bool,
    /// The key file (else keys derived from the simulation master key).
    pub keys: Option<PathBuf>,
    /// One CAN FD frame per message.
    pub can_fd: bool,
    /// Every planner, manager and codec in this precision.
    pub precision: host_sim::world::precision::Precision,
    /// Every node's clock at the start (s).
    pub clock_start: f64,
    /// The invariant, over the scenario's.
    pub invariant: Option<planner_core::Invariant>,
    /// Computers in the loop: the image, its board's name, the vehicles.
    pub firmware: Option<(PathBuf, String, Vec<u16>)>,
}

/// Where a run's rows go, and the staged files they end in (nothing is written to an
/// output's path before the run is complete).
struct Sinks {
    trace: Option<(TraceWriter<BufWriter<std::fs::File>>, Staged)>,
    plot: Option<(PlotData, Staged)>,
    viewer: Option<(Viewer, Staged)>,
}

impl Sinks {
    fn row(&mut self, r: &TraceRow) {
        if let Some((w, _)) = self.trace.as_mut() {
            w.row(r);
        }
        if let Some((p, _)) = self.plot.as_mut() {
            p.add(r);
        }
        if let Some((v, _)) = self.viewer.as_mut() {
            v.add(r);
        }
    }
}

/// `host-sim run`.
pub fn run(a: RunArgs) -> ExitCode {
    let keys = match link_keys(&a) {
        Ok(k) => k,
        Err(code) => return code,
    };
    match prepare(&a) {
        Ok((spec, sinks)) => match firmware(&a, &spec) {
            Ok(fw) => execute(&a, keys, (spec, fw), sinks),
            Err(code) => code,
        },
        Err(code) => code,
    }
}

/// The computers in the loop asked for, checked against the scenario: a road (one
/// segment, no junctions), the in-process bus, the paper's invariant, no faults or
/// sensors (the firmware plans from what it hears), planner-driven vehicles; a board
/// QEMU has, a readable image, QEMU on the path.
fn firmware(a: &RunArgs, spec: &WorldSpec) -> Result<Option<FirmwareSpec>, ExitCode> {
    let Some((elf, board, vehicles)) = &a.firmware else {
        return Ok(None);
    };
    let board = Board::parse(board)
        .ok_or_else(|| bad_input(format!("--firmware-board {board}: an386, an500 or an505")))?;
    let why = firmware_world(a, spec).or_else(|| firmware_vehicles(spec, vehicles));
    if let Some(why) = why {
        return Err(bad_input(format!("--firmware: {why}")));
    }
    if !elf.is_file() {
        return Err(bad_input(format!(
            "--firmware {}: no such file",
            elf.display()
        )));
    }
    let qemu = std::process::Command::new("qemu-system-arm")
        .arg("--version")
        .output();
    if !qemu.is_ok_and(|o| o.status.success()) {
        return Err(bad_input(
            "--firmware runs the image in QEMU: qemu-system-arm is not on the path",
        ));
    }
    Ok(Some(FirmwareSpec {
        elf: elf.clone(),
        board,
        vehicles: vehicles.clone(),
    }))
}

/// Why the world cannot have computers in the loop, if it cannot.
fn firmware_world(a: &RunArgs, spec: &WorldSpec) -> Option<String> {
    let net = &spec.network;
    if a.bus != "in-process" {
        Some("computers in the loop run on the in-process bus (drop --bus)".into())
    } else if !net.junctions.is_empty() || net.segments.len() != 1 {
        Some("the firmware drives a road: this scenario has junctions or several segments".into())
    } else if spec.invariant != planner_core::Invariant::Paper {
        Some(
            "the firmware keeps the paper's invariant: add --invariant paper (or \
             invariant = \"paper\" to the scenario)"
                .into(),
        )
    } else if spec.sensing.is_some() || spec.faults != host_sim::bus::faults::Faults::default() {
        Some(
            "the firmware plans from what it hears on a clean bus: no [sensing], no [faults]"
                .into(),
        )
    } else {
        None
    }
}

/// Why `ids` cannot be the computers in the loop, if they cannot.
fn firmware_vehicles(spec: &WorldSpec, ids: &[u16]) -> Option<String> {
    if ids.is_empty() {
        return Some("--firmware-vehicles names no vehicle".into());
    }
    for (i, id) in ids.iter().enumerate() {
        let planner = spec
            .vehicles
            .iter()
            .any(|v| v.id == *id && v.driver == host_sim::world::DriverKind::Planner);
        if !planner {
            return Some(format!(
                "vehicle {id} is not a planner-driven vehicle of the scenario"
            ));
        }
        if ids[..i].contains(id) || *id >= u16::from(can_gateway::wire::CLOCK_ADDRESS) {
            return Some(format!(
                "vehicle {id} named twice, or not a CAN node id (below 240)"
            ));
        }
    }
    None
}

/// Every input checked before any output is staged, and every output staged (so that
/// one that cannot be written is refused) before anything runs; no existing file is
/// touched until the run is complete.
fn prepare(a: &RunArgs) -> Result<(WorldSpec, Sinks), ExitCode> {
    if a.bus != "in-process" {
        super::fleet::check_bus(&a.bus)?;
    }
    if let Some(p) = &a.html {
        if p.extension().and_then(|e| e.to_str()) != Some("html") {
            return Err(bad_input(format!(
                "--html {}: must end in .html",
                p.display()
            )));
        }
    }
    let start = planner_core::Duration::from_secs_real(a.clock_start).ok_or_else(|| {
        bad_input(format!(
            "--clock-start must be in [0, 1e9] s, got {}",
            a.clock_start
        ))
    })?;
    let f32_clarabel = a.precision == host_sim::world::precision::Precision::F32
        && a.solver == SolverChoice::Clarabel;
    if f32_clarabel {
        return Err(bad_input(
            "--precision f32 plans with planner-core's solver, as the MCU does: drop --solver clarabel",
        ));
    }
    let mut spec = host_sim::scenario::load(&a.file).map_err(bad_input)?;
    if let Some(d) = a.duration {
        // Only shorter: arrivals and faults were drawn for the file's duration.
        if !(d > 0.0 && d <= spec.duration_s) {
            return Err(bad_input(format!(
                "--duration must be in (0, {}] s (the scenario's duration_s), got {d}",
                spec.duration_s
            )));
        }
        spec.duration_s = d;
        spec.deadline_s = spec.deadline_s.min(d);
    }
    spec.clock_start = planner_core::Instant::EPOCH.saturating_add(start);
    spec.precision = a.precision;
    if let Some(i) = a.invariant {
        spec.invariant = i;
    }
    if a.bus != "in-process" {
        super::fleet::fits_the_bus(&a.file, &spec)?;
    }
    let plot = match &a.plot {
        Some(p) => Some((PlotData::of(&spec.network), check_plot(p)?)),
        None => None,
    };
    let viewer = match &a.html {
        Some(p) => Some((
            Viewer::new(&spec.network, host_sim::monitor::Limits::table_i().h),
            staged(p, "--html")?,
        )),
        None => None,
    };
    let trace = match &a.trace {
        Some(p) => {
            let mut out = staged(p, "--trace")?;
            let f = out
                .take_file()
                .ok_or_else(|| bad_input(format!("--trace {}", p.display())))?;
            let w = TraceWriter::new(BufWriter::new(f), &spec.network)
                .map_err(|e| bad_input(format!("--trace {}: {e}", p.display())))?;
            Some((w, out))
        }
        None => None,
    };
    Ok((
        spec,
        Sinks {
            trace,
            plot,
            viewer,
        },
    ))
}

/// The link's keys, or why the link flags do not fit the bus.
fn link_keys(a: &RunArgs) -> Result<Option<std::sync::Arc<host_sim::fleet::can::Keys>>, ExitCode> {
    let keys = super::fleet::keys(a.auth, a.keys.as_deref()).map_err(bad_input)?;
    if keys.is_some() && a.bus == "in-process" {
        return Err(bad_input("--auth and --keys authenticate CAN frames: use them with --bus can-hub or an interface"));
    }
    if a.can_fd && a.bus == "in-process" {
        return Err(bad_input(
            "--can-fd puts messages on CAN FD frames: use it with --bus can-hub or an interface",
        ));
    }
    Ok(keys)
}

fn execute(
    a: &RunArgs,
    keys: Option<std::sync::Arc<host_sim::fleet::can::Keys>>,
    (spec, fw): (WorldSpec, Option<FirmwareSpec>),
    mut sinks: Sinks,
) -> ExitCode {
    let name = spec.name.clone();
    let net = spec.network.clone();
    let outcome = if a.bus == "in-process" {
        let setup = (a.solver, a.seed, fw.as_ref());
        match spec.horizon {
            50 => in_process::<50>(spec, setup, &mut sinks),
            _ => in_process::<20>(spec, setup, &mut sinks),
        }
        .map(|s| (s, None))
        .map_err(|e| {
            match e {
                InProcessError::Firmware(e) => {
                    eprintln!("error: --firmware: {e}");
                    return ExitCode::from(EXIT_FIRMWARE);
                }
                // Everything the world could refuse was refused before it started: a
                // failure now is the simulator's, and says so (exit 5, not bad input).
                InProcessError::Bus(e) => eprintln!(
                    "error: internal: the run stopped at an in-process bus error: {e} \
                     (a bug: the scenario passed every check; please report it with the file)"
                ),
            }
            ExitCode::from(EXIT_INTERNAL)
        })
    } else {
        let link = super::fleet::Link { keys, fd: a.can_fd };
        super::fleet::run(&a.bus, spec, (a.solver, a.seed), link, &mut |r| {
            sinks.row(r)
        })
        .map(|f| (f.run.clone(), Some(f)))
        .map_err(|e| {
            eprintln!("error: --bus {}: {e}", a.bus);
            ExitCode::from(EXIT_BUS)
        })
    };
    let (summary, fleet) = match outcome {
        Ok(x) => x,
        Err(code) => return code,
    };
    let written = match write_outputs(sinks, &net, &name) {
        Ok(w) => w,
        Err(code) => return code,
    };
    if let Some(d) = &summary.deadlock {
        eprintln!("{}: {d}", summary.scenario);
    }
    for r in summary.firmware.iter().filter(|r| !r.ok()) {
        eprintln!(
            "{}: the computer of vehicle {} ({}) failed: exit {:?}{} (its log: {})",
            summary.scenario,
            r.vehicle,
            r.board,
            r.exit,
            r.failed
                .as_deref()
                .map(|w| format!(", {w}"))
                .unwrap_or_default(),
            r.log
        );
    }
    if a.json {
        let printed = match &fleet {
            Some(f) => print_json(f),
            None => print_json(&summary),
        };
        if let Err(code) = printed {
            return code;
        }
    } else {
        let mut text = fleet.as_ref().map(|f| f.line() + "\n").unwrap_or_default();
        text += &human(&summary, &written);
        if let Err(code) = super::output::say(&text) {
            return code;
        }
    }
    let verdict = summary.verdict();
    let computers_ok = summary.firmware.iter().all(|r| r.ok());
    if verdict.is_safe() && verdict.live && !computers_ok {
        return ExitCode::from(EXIT_FIRMWARE);
    }
    exit(verdict)
}

/// Finishes every output of a complete run and puts each in place; the paths written.
fn write_outputs(
    sinks: Sinks,
    net: &host_sim::world::network::Network,
    name: &str,
) -> Result<Vec<String>, ExitCode> {
    let mut written = Vec::new();
    if let Some((w, out)) = sinks.trace {
        w.finish().map_err(|e| bad_input(format!("--trace: {e}")))?;
        written.push(out.target().display().to_string());
        commit(out, "--trace")?;
    }
    if let Some((data, out)) = sinks.plot {
        host_sim::output::plot::any(&data, net, name, out.temp_path()).map_err(bad_input)?;
        written.push(out.target().display().to_string());
        commit(out, "--plot")?;
    }
    if let Some((v, mut out)) = sinks.viewer {
        out.write_all(v.page(name).as_bytes())
            .map_err(|e| bad_input(format!("--html {}: {e}", out.target().display())))?;
        written.push(out.target().display().to_string());
        commit(out, "--html")?;
    }
    Ok(written)
}

/// Why a run on the in-process bus stopped.
enum InProcessError {
    /// The bus failed (a bug: the input was checked).
    Bus(host_sim::bus::BusError),
    /// A computer in the loop could not be started.
    Firmware(host_sim::firmware::FirmwareError),
}

/// Runs a world in one task on the in-process bus (with its computers in the loop, if
/// any: their logs in a directory of their own under the system's temporary one).
fn in_process<const N: usize>(
    spec: WorldSpec,
    (solver, seed, fw): (SolverChoice, Option<u64>, Option<&FirmwareSpec>),
    sinks: &mut Sinks,
) -> Result<Summary, InProcessError> {
    let t0 = std::time::Instant::now();
    let mut w = World::<N>::new(spec, solver, seed);
    if let Some(fw) = fw {
        let logs = std::env::temp_dir().join(format!("host-sim-firmware-{}", std::process::id()));
        std::fs::create_dir_all(&logs).map_err(|e| {
            InProcessError::Firmware(host_sim::firmware::FirmwareError::Log(e.to_string()))
        })?;
        w.attach_firmware(fw, &logs)
            .map_err(InProcessError::Firmware)?;
    }
    let bar = progress_bar();
    let total = w.total_steps().max(1);
    let every = (total / 200).max(1);
    while !w.finished() {
        w.step(&mut |r| sinks.row(r)).map_err(InProcessError::Bus)?;
        if w.steps_done().is_multiple_of(every) {
            if let Some(b) = &bar {
                b.set_position(w.steps_done() * 1000 / total);
            }
        }
    }
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let firmware = w.finish_firmware();
    let mut s = w.summary(t0.elapsed().as_secs_f64());
    s.firmware = firmware;
    Ok(s)
}

/// A progress bar on a terminal.
fn progress_bar() -> Option<indicatif::ProgressBar> {
    std::io::stderr().is_terminal().then(|| {
        let b = indicatif::ProgressBar::new(1000);
        b.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {percent:>3}% {elapsed} / ~{eta}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b
    })
}

/// The human summary: what ran, safe or not, goals met, where the outputs went.
pub fn human(s: &Summary, written: &[String]) -> String {
    let safe = if s.unsafe_events() == 0 {
        "SAFE: no collision, no invariant or limit violation".to_string()
    } else {
        format!(
            "UNSAFE: {} collisions, {} invariant violations, {} limit violations, {} road-end \
             overruns, {} entries without permission",
            s.collisions,
            s.invariant_violations,
            s.limit_violations,
            s.road_end_overruns,
            s.unpermitted_entries()
        )
    };
    // An open world ends with vehicles still under way: neither met nor failed, so the
    // line counts them rather than claiming their goals.
    let under_way = match s.under_way {
        0 => String::new(),
        n => format!(", {n} still under way within their time"),
    };
    let live = match (&s.deadlock, s.completed) {
        (Some(d), _) => format!("DEADLOCK at t = {:.2} s (see above)", d.at_s),
        (None, true) if s.under_way == 0 => "every goal met".to_string(),
        (None, true) => format!(
            "every goal due met: {} of {} vehicles done{under_way}",
            s.goals_met, s.goals
        ),
        (None, false) => format!(
            "NOT every goal met: {} of {} vehicles done, {} unfinished{under_way}",
            s.goals_met, s.goals, s.unfinished
        ),
    };
    let mut out = format!(
        "{}: {} vehicles, {:.2} s simulated in {:.2} s\n  {safe}\n  {live}",
        s.scenario, s.vehicles, s.sim_seconds, s.wall_seconds
    );
    if s.lane_changes.changes > 0 {
        out += &format!(
            "\n  lane changes: {} ({} of {} vehicles in their target lane{})",
            s.lane_changes.changes,
            s.lane_changes.in_target_lane,
            s.lane_changes.vehicles,
            if s.lane_changes.in_target_lane < s.lane_changes.vehicles && s.completed {
                ", the others still under way"
            } else {
                ""
            }
        );
    }
    if let Some(c) = &s.crossing {
        out += &format!(
            "\n  crossings ({}): {}, mean {:.1} s from entering A_C to leaving it",
            c.algorithm, c.crossed, c.crossing_time_mean_s
        );
    }
    for w in written {
        out += &format!("\n  wrote {w}");
    }
    out
}
