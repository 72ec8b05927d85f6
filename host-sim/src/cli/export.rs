//! `host-sim export …`: a scenario in another simulator's format.

use super::output::{bad_input, commit, staged};
use host_sim::output::sumo::{export, Control};
use std::path::PathBuf;
use std::process::ExitCode;

/// The formats.
#[derive(clap::Subcommand)]
pub enum Export {
    /// The scenario as SUMO plain XML in OUTDIR (NAME.nod.xml, .edg.xml, .con.xml,
    /// .rou.xml, and NAME.netccfg and NAME.sumocfg to build and run it): the same
    /// network, lane permissions and speeds, its vehicles and its arrivals as Poisson
    /// flows. `netconvert -c OUTDIR/NAME.netccfg` builds NAME.net.xml; `sumo-gui -c
    /// OUTDIR/NAME.sumocfg` shows it.
    Sumo(SumoArgs),
}

/// `host-sim export sumo`.
#[derive(clap::Args)]
pub struct SumoArgs {
    /// The scenario file.
    scenario: PathBuf,
    /// Where the files go (created if missing; files of the same names are replaced).
    outdir: PathBuf,
    /// How SUMO controls every junction.
    #[arg(long, value_enum, default_value = "actuated")]
    control: Control,
}

/// Runs an export.
pub fn run(e: Export) -> ExitCode {
    match e {
        Export::Sumo(a) => sumo(&a).err().unwrap_or(ExitCode::SUCCESS),
    }
}

/// The files' base name: the scenario file's stem, in characters every tool takes.
fn base_name(a: &SumoArgs) -> String {
    let stem = a
        .scenario
        .file_stem()
        .map_or_else(|| "scenario".into(), |s| s.to_string_lossy().into_owned());
    stem.chars()
        .map(|c| match c {
            'a'..='z' | 'A'..='Z' | '0'..='9' | '-' | '_' | '.' => c,
            _ => '_',
        })
        .collect()
}

/// Loads, converts, stages every file (so one that cannot be written is refused before
/// any is replaced), then commits them.
fn sumo(a: &SumoArgs) -> Result<(), ExitCode> {
    let spec = host_sim::scenario::load(&a.scenario).map_err(bad_input)?;
    if a.outdir.exists() && !a.outdir.is_dir() {
        return Err(bad_input(format!(
            "{}: not a directory",
            a.outdir.display()
        )));
    }
    std::fs::create_dir_all(&a.outdir)
        .map_err(|e| bad_input(format!("{}: {e}", a.outdir.display())))?;
    let files = export(&spec, a.control);
    let name = base_name(a);
    let mut outs = Vec::new();
    for (file, text) in files.named(&name) {
        let mut out = staged(&a.outdir.join(&file), "OUTDIR")?;
        out.write_all(text.as_bytes())
            .map_err(|e| bad_input(format!("OUTDIR {file}: {e}")))?;
        outs.push(out);
    }
    for out in outs {
        commit(out, "OUTDIR")?;
    }
    for note in &files.notes {
        eprintln!("note: {note}");
    }
    let dir = a.outdir.display();
    eprintln!("wrote {dir}/{name}.{{nod,edg,con,rou}}.xml; build the network with `netconvert -c {dir}/{name}.netccfg`, run it with `sumo -c {dir}/{name}.sumocfg`");
    Ok(())
}
