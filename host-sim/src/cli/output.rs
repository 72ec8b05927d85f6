//! How the CLI answers: one JSON object (`--json`) or a short human summary, and an exit
//! code — 0 ok, 1 unsafe (a collision or a violation), 2 bad input, 3 a liveness goal
//! missed (or a deadlock), 4 a CAN bus failure.

use host_sim::output::staged::Staged;
use host_sim::verdict::{Judged, Verdict};
use std::process::ExitCode;
use std::sync::Mutex;

/// A collision or a safety or limit violation was seen.
pub const EXIT_UNSAFE: u8 = 1;
/// Bad input: arguments, a scenario file, an output file (checked before anything runs).
pub const EXIT_BAD_INPUT: u8 = 2;
/// A liveness goal was missed, or the run deadlocked.
pub const EXIT_NOT_LIVE: u8 = 3;
/// The CAN bus failed (`--bus`).
pub const EXIT_BUS: u8 = 4;
/// A run that started failed inside the simulator: a bug, never the input's fault (the
/// input was checked before anything ran), reported with what failed.
pub const EXIT_INTERNAL: u8 = 5;
/// A vehicle computer in the loop (`run --firmware`) failed: its image did not answer,
/// or exited with its figures out of bounds (a period over h, a refused frame, its
/// stack) — on a run that was otherwise safe and live.
pub const EXIT_FIRMWARE: u8 = 6;

/// Prints `value` as one line of JSON, its floats rounded to 12 significant digits (a sum
/// of 0.01 s steps is 19.84, not 19.840000000000302).
pub fn print_json<T: serde::Serialize>(value: &T) -> Result<(), ExitCode> {
    match serde_json::to_value(value) {
        Ok(mut v) => {
            tidy(&mut v);
            say(&v.to_string())
        }
        Err(e) => {
            eprintln!("error: {e}");
            Err(ExitCode::from(EXIT_BAD_INPUT))
        }
    }
}

/// Rounds every float in `v` to 12 significant digits.
pub fn tidy(v: &mut serde_json::Value) {
    use serde_json::Value;
    match v {
        Value::Number(n) if n.is_f64() => {
            if let Some(x) = n.as_f64() {
                let r: f64 = format!("{x:.11e}").parse().unwrap_or(x);
                if let Some(m) = serde_json::Number::from_f64(r) {
                    *n = m;
                }
            }
        }
        Value::Array(a) => a.iter_mut().for_each(tidy),
        Value::Object(o) => o.values_mut().for_each(tidy),
        _ => {}
    }
}

/// `println!` through [`say`]: to stdout, or into the `--output` buffer.
macro_rules! out {
    ($($arg:tt)*) => {
        let _ = $crate::cli::output::say(&format!($($arg)*));
    };
}
pub(crate) use out;

/// What `--output FILE` collects instead of printing: `None` prints to stdout.
static CAPTURED: Mutex<Option<String>> = Mutex::new(None);

/// From now on, what the command would print goes into a buffer ([`take_captured`]).
pub fn capture_stdout() {
    if let Ok(mut c) = CAPTURED.lock() {
        *c = Some(String::new());
    }
}

/// What was captured since [`capture_stdout`].
pub fn take_captured() -> Option<String> {
    CAPTURED.lock().ok().and_then(|mut c| c.take())
}

/// Prints `text` and a newline to stdout (or into the `--output` buffer); a reader that
/// went away (`| head`) ends the output quietly instead of a panic.
pub fn say(text: &str) -> Result<(), ExitCode> {
    use std::io::Write;
    if let Ok(mut c) = CAPTURED.lock() {
        if let Some(buf) = c.as_mut() {
            buf.push_str(text);
            buf.push('\n');
            return Ok(());
        }
    }
    let mut out = std::io::stdout().lock();
    match writeln!(out, "{text}").and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(ExitCode::SUCCESS),
        Err(e) => {
            eprintln!("error: stdout: {e}");
            Err(ExitCode::from(EXIT_BAD_INPUT))
        }
    }
}

/// Exit 2 with `msg` on stderr.
pub fn bad_input(msg: impl std::fmt::Display) -> ExitCode {
    eprintln!("error: {msg}");
    ExitCode::from(EXIT_BAD_INPUT)
}

/// The exit code of a verdict: unsafe before not live before fine.
pub fn exit(v: Verdict) -> ExitCode {
    if !v.is_safe() {
        ExitCode::from(EXIT_UNSAFE)
    } else if !v.live {
        ExitCode::from(EXIT_NOT_LIVE)
    } else {
        ExitCode::SUCCESS
    }
}

/// Prints a result (one JSON object, or its human summary) and exits by its verdict.
pub fn finish<T: serde::Serialize + std::fmt::Display + Judged>(r: &T, json: bool) -> ExitCode {
    let printed = if json {
        print_json(r)
    } else {
        say(&r.to_string())
    };
    match printed {
        Ok(()) => exit(r.verdict()),
        Err(code) => code,
    }
}

/// A `--plot` path must end in .png or .svg and be writable now (so that a long run is
/// not wasted on an output it cannot write): its staged file, to draw into and commit.
pub fn check_plot(path: &std::path::Path) -> Result<Staged, ExitCode> {
    if !matches!(
        path.extension().and_then(|e| e.to_str()),
        Some("png" | "svg")
    ) {
        return Err(bad_input(format!(
            "--plot {}: must end in .png or .svg",
            path.display()
        )));
    }
    staged(path, "--plot")
}

/// The staged output for `path` (see [`Staged`]: the target is only replaced when the
/// output is complete), or exit 2 naming `flag`.
pub fn staged(path: &std::path::Path, flag: &str) -> Result<Staged, ExitCode> {
    Staged::create(path).map_err(|e| bad_input(format!("{flag} {}: {e}", path.display())))
}

/// Commits a complete output, or exit 2 naming `flag`.
pub fn commit(out: Staged, flag: &str) -> Result<(), ExitCode> {
    let shown = out.target().display().to_string();
    out.commit()
        .map_err(|e| bad_input(format!("{flag} {shown}: {e}")))
}

/// The staged `--plot` output, if asked for (checked now, before anything runs).
pub fn plot_output(plot: Option<&std::path::Path>) -> Result<Option<Staged>, ExitCode> {
    plot.map(check_plot).transpose()
}

/// Draws a complete result with `draw` into the staged plot, and puts it in place.
pub fn draw_plot<E: std::fmt::Display>(
    out: Staged,
    draw: impl FnOnce(&std::path::Path) -> Result<(), E>,
) -> Result<(), ExitCode> {
    draw(out.temp_path()).map_err(bad_input)?;
    commit(out, "--plot")
}
