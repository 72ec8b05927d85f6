//! `host-sim layouts`: random network files, degenerate ones among them, each either
//! refused by the loader with its file and line, or run safely to its end.
//!
//! Half the cases are grids (1 × 1 to 4 × 4 intersections, 1 to 4 lanes, blocks from 60
//! to 800 m, boundary segments from 1 m to 600 m), half explicit networks of 1 to 4
//! intersections placed on a 150 m lattice — two at one place, or closer than their
//! communication regions allow, now and then — each with its own lanes (not always
//! matching its neighbours'), speed limit (1 to 27.8 m/s) and communication margin
//! (0.2 to 80 m), joined by the segments their alignment allows, with entry and exit
//! roads of 1 m to 2,000 km and, sometimes, none. Every case has open arrivals (100 to
//! 1,500 vehicles per hour per entry lane) and runs 40 s.
//!
//! A case passes when the loader refuses it with a message that names the file and a
//! line (`layout.toml:N:`), or when it runs to its end with no collision, no violation, no
//! unpermitted entry, no deadlock and no internal error. The report counts refusals by
//! reason, so that a sweep shows what the loader guards against.

use super::experiment::{Experiment, RunError};
use super::shard::{combine_all, MergeError};
use super::sweep::{case_seed, keep_failing, CasesUnder, Failing};
use crate::reference::instances::rng;
use crate::scenario::network::NetworkScenario;
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::{SolverChoice, World};
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// `host-sim layouts`: cases, seed and invariant (each case is a network file of its own,
/// which names the invariant: the sweep's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct Layouts {
    /// Cases, seed, invariant.
    #[command(flatten)]
    #[serde(flatten)]
    pub sweep: CasesUnder,
    /// Percent of the arrivals that are trucks (16.5 m, braking at 4.5 m/s²); every
    /// intersection then gets a turn inset, mostly one that holds a truck's swing and now
    /// and then one too small (which the loader must refuse at its line). 0 gives the
    /// cases as they always were.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100))]
    #[serde(default, skip_serializing_if = "super::flags::is_zero")]
    pub trucks: u8,
}

impl Experiment for Layouts {
    const NAME: &'static str = "layouts";
    type Part = LayoutsReport;
    type Report = LayoutsReport;

    fn cases(&self) -> u64 {
        self.sweep.sweep.cases
    }

    fn run(&self, (first, end): (u64, u64), threads: usize) -> Result<LayoutsReport, RunError> {
        let s = &self.sweep;
        Ok(sweep_with(
            end - first,
            first,
            (s.sweep.seed, self.trucks),
            threads,
            s.invariant,
        ))
    }

    fn report(&self, parts: Vec<LayoutsReport>) -> Result<LayoutsReport, MergeError> {
        combine_all(parts)
    }
}

impl Judged for LayoutsReport {
    /// The runs' findings; live when every refusal named its line and no run deadlocked
    /// or failed inside ([`LayoutsReport::clean`]).
    fn verdict(&self) -> Verdict {
        let safety = Safety::of(
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            self.unpermitted_entries,
        );
        let live = self.refused_without_line + self.deadlocks + self.internal_errors == 0;
        Verdict::new(safety, live)
    }
}

impl core::fmt::Display for LayoutsReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let text = super::sweep::text("layouts", self.cases, self, "", &self.failing);
        f.write_str(&text)
    }
}

/// The `layouts` result.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LayoutsReport {
    /// Cases drawn.
    pub cases: u64,
    /// Refused by the loader (with file and line).
    pub refused: u64,
    /// Refused without naming a line (a failure).
    pub refused_without_line: u64,
    /// Accepted and run.
    pub ran: u64,
    /// Vehicles over the runs.
    pub vehicles: u64,
    /// Collisions (pairs × steps).
    pub collisions: u64,
    /// Invariant violations (pairs × steps).
    pub invariant_violations: u64,
    /// Limit violations, road-end overruns and departures from the road.
    pub limit_violations: u64,
    /// Steps × vehicles inside A_S without a permission.
    pub unpermitted_entries: u64,
    /// Runs that deadlocked.
    pub deadlocks: u64,
    /// Runs that stopped on an internal error.
    pub internal_errors: u64,
    /// Refusals by reason (the loader's message with numbers taken out).
    pub refusals: BTreeMap<String, u64>,
    /// The sweep's seed.
    pub seed: u64,
    /// Failing cases (at most 20), each as its file.
    pub failing: Vec<Failing>,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

impl LayoutsReport {
    /// Every case refused with its line, or run safely and live.
    pub fn clean(&self) -> bool {
        self.refused_without_line
            + self.collisions
            + self.invariant_violations
            + self.limit_violations
            + self.unpermitted_entries
            + self.deadlocks
            + self.internal_errors
            == 0
    }
}

/// Case `index` of the sweep seeded `seed`: a network file.
pub fn case(seed: u64, index: u64) -> String {
    case_with((seed, 0), index)
}

/// The turn insets of a case with trucks, from a stream of their own (so that trucks
/// move no other draw): none without trucks.
struct Insets(Option<rand_chacha::ChaCha8Rng>);

impl Insets {
    /// A `turn_inset` line for the next intersection or grid: mostly the 8 m a 16.5 m
    /// truck's swing needs at SPEC §8's turns, one in ten from 0 to 8 m (too small for
    /// some layouts: the loader refuses those at their line).
    fn line(&mut self) -> String {
        self.0.as_mut().map_or_else(String::new, |r| {
            let inset = if r.random_bool(0.9) {
                super::crossings::TRUCK_TURN_INSET_M
            } else {
                r.random_range(0.0..super::crossings::TRUCK_TURN_INSET_M)
            };
            format!("turn_inset = {inset:.1}\n")
        })
    }
}

/// Case `index` of the sweep seeded `seed` with `trucks_percent` of the arrivals trucks:
/// with 0, [`case()`]'s file; else the same layout with a turn inset at every
/// intersection and `trucks` in its arrivals.
pub fn case_with((seed, trucks_percent): (u64, u8), index: u64) -> String {
    let mut r = rng(case_seed(seed, index));
    let mut insets =
        Insets((trucks_percent > 0).then(|| rng(case_seed(seed ^ 0x007a_0cc5, index))));
    let mut f = format!(
        "name = \"layout-{seed}-{index}\"\nduration_s = 40.0\nseed = {}\nalgorithm = \"{}\"\n",
        case_seed(seed, index),
        ["pipelined", "concurrent_fair", "fifo", "stop"][r.random_range(0..4)]
    );
    if r.random_bool(0.5) {
        grid(&mut r, &mut f, &mut insets);
    } else {
        explicit(&mut r, &mut f, &mut insets);
    }
    let _ = write!(
        f,
        "\n[arrivals]\nrate_vph = {:.0}\n",
        r.random_range(100.0..1500.0)
    );
    if trucks_percent > 0 {
        let _ = writeln!(f, "trucks = {trucks_percent}");
    }
    f
}

fn grid(r: &mut impl Rng, f: &mut String, insets: &mut Insets) {
    let rows: u8 = r.random_range(1..=4);
    let cols: u8 = r.random_range(1..=4);
    let lanes: u8 = r.random_range(1..=4);
    let block: f64 = if r.random_bool(0.3) {
        r.random_range(60.0..300.0)
    } else {
        r.random_range(300.0..900.0)
    };
    let _ = write!(
        f,
        "\n[grid]\nrows = {rows}\ncols = {cols}\nblock_m = {block:.1}\nlanes = {lanes}\n{}",
        insets.line()
    );
    if r.random_bool(0.6) {
        let boundary = if r.random_bool(0.4) {
            r.random_range(1.0..80.0)
        } else {
            r.random_range(60.0..600.0)
        };
        let _ = writeln!(f, "boundary_m = {boundary:.1}");
    }
}

/// A random length for an open road: now and then tiny or absurdly long.
fn road_length(r: &mut impl Rng) -> f64 {
    match r.random_range(0..10) {
        0 => r.random_range(1.0..60.0),
        1 => r.random_range(1e5..2e6),
        _ => r.random_range(60.0..600.0),
    }
}

fn explicit(r: &mut impl Rng, f: &mut String, insets: &mut Insets) {
    const HEADINGS: [&str; 4] = ["east", "north", "west", "south"];
    let n: usize = r.random_range(1..=4);
    let lanes0: u8 = r.random_range(1..=3);
    // The lattice the intersections sit on: mostly roomy, now and then tight.
    let spacing = if r.random_bool(0.1) { 150.0 } else { 500.0 };
    let mut at: Vec<(i64, i64)> = Vec::new();
    for i in 0..n {
        let p = if i > 0 && r.random_bool(0.05) {
            at[r.random_range(0..at.len())]
        } else {
            (r.random_range(-2..=2), r.random_range(-2..=2))
        };
        at.push(p);
        let lanes = if r.random_bool(0.85) {
            lanes0
        } else {
            r.random_range(1..=4)
        };
        let v_limit = match r.random_range(0..10) {
            0 => 1.0,
            1 => 27.8,
            _ => r.random_range(5.0..20.0),
        };
        let margin = if r.random_bool(0.15) {
            r.random_range(0.2..20.0)
        } else {
            r.random_range(40.0..80.0)
        };
        let _ = write!(
            f,
            "\n[[intersection]]\nid = {}\nx = {:.1}\ny = {:.1}\nlanes = {lanes}\n\
             v_limit = {v_limit:.2}\ncomm_margin = {margin:.2}\n{}",
            i + 1,
            spacing * p.0 as f64,
            spacing * p.1 as f64,
            insets.line()
        );
    }
    let mut sid = 100;
    // Segments between aligned intersections, both ways, now and then one way only.
    for a in 0..n {
        for b in 0..n {
            if a == b || at[a] == at[b] || !(at[a].0 == at[b].0 || at[a].1 == at[b].1) {
                continue;
            }
            if r.random_bool(0.7) {
                sid += 1;
                let _ = write!(
                    f,
                    "\n[[segment]]\nid = {sid}\nfrom = {}\nto = {}\n",
                    a + 1,
                    b + 1
                );
            }
        }
    }
    // Entries and exits, on the sides that have no road to a neighbour (on any side now
    // and then).
    for (i, p) in at.iter().enumerate() {
        for (d, h) in HEADINGS.iter().enumerate() {
            // Heading d enters from the side opposite d.
            let side = [(-1, 0), (0, -1), (1, 0), (0, 1)][d];
            let neighbour = at.iter().any(|q| {
                q != p
                    && (q.0 - p.0).signum() == side.0
                    && (q.1 - p.1).signum() == side.1
                    && (q.0 == p.0 || q.1 == p.1)
            });
            if neighbour && !r.random_bool(0.1) {
                continue;
            }
            if r.random_bool(0.6) {
                sid += 1;
                let _ = write!(
                    f,
                    "\n[[segment]]\nid = {sid}\nto = {}\nheading = \"{h}\"\nlength = {:.1}\n",
                    i + 1,
                    road_length(r)
                );
            }
            if r.random_bool(0.6) {
                sid += 1;
                let out = HEADINGS[(d + 2) % 4];
                let _ = write!(
                    f,
                    "\n[[segment]]\nid = {sid}\nfrom = {}\nheading = \"{out}\"\nlength = {:.1}\n",
                    i + 1,
                    road_length(r)
                );
            }
        }
    }
}

/// The loader's message with its numbers and ids taken out: a refusal's kind.
fn kind_of(message: &str) -> String {
    let after_line = message
        .split_once(".toml:")
        .map_or(message, |(_, rest)| rest);
    let mut out = String::new();
    let mut last_digit = false;
    for ch in after_line.chars() {
        if ch.is_ascii_digit() || ch == '.' && last_digit {
            if !last_digit {
                out.push('#');
            }
            last_digit = true;
        } else {
            out.push(ch);
            last_digit = false;
        }
    }
    out.trim_start_matches(['#', ':', ' '])
        .chars()
        .take(90)
        .collect()
}

/// What one case gave.
enum Outcome {
    Refused { message: String },
    Ran(Box<crate::world::summary::Summary>),
    Internal(String),
}

fn run_case(text: &str) -> Outcome {
    let sc = match NetworkScenario::parse(text, Path::new("layout.toml")) {
        Ok(s) => s,
        Err(e) => {
            return Outcome::Refused {
                message: e.to_string(),
            }
        }
    };
    let t0 = std::time::Instant::now();
    let mut w = World::<20>::new(sc.world(), SolverChoice::Ours, None);
    while !w.finished() {
        if let Err(e) = w.step(&mut |_| {}) {
            return Outcome::Internal(e.to_string());
        }
    }
    Outcome::Ran(Box::new(w.summary(t0.elapsed().as_secs_f64())))
}

/// Runs `cases` cases from index `first` of the sweep seeded `seed` on `threads` threads,
/// every file under the default invariant.
pub fn sweep(cases: u64, first: u64, seed: u64, threads: usize) -> LayoutsReport {
    sweep_with(
        cases,
        first,
        (seed, 0),
        threads,
        crate::world::DEFAULT_INVARIANT,
    )
}

/// [`sweep()`] with `trucks` percent of the arrivals trucks ([`case_with`]) and every
/// file naming `invariant` (after what its seed draws, so the layouts are the same under
/// either).
pub fn sweep_with(
    cases: u64,
    first: u64,
    (seed, trucks): (u64, u8),
    threads: usize,
    invariant: planner_core::Invariant,
) -> LayoutsReport {
    let t0 = std::time::Instant::now();
    let named = format!(
        "invariant = \"{}\"\n",
        crate::world::invariant_name(invariant)
    );
    let outcomes = super::par::map_indexed(cases as usize, threads, |i| {
        let index = first + i as u64;
        // The key goes first: top-level keys before any table.
        let text = format!("{named}{}", case_with((seed, trucks), index));
        (index, run_case(&text), text)
    });
    let mut r = LayoutsReport {
        cases,
        refused: 0,
        refused_without_line: 0,
        ran: 0,
        vehicles: 0,
        collisions: 0,
        invariant_violations: 0,
        limit_violations: 0,
        unpermitted_entries: 0,
        deadlocks: 0,
        internal_errors: 0,
        refusals: BTreeMap::new(),
        seed,
        failing: Vec::new(),
        wall_seconds: 0.0,
    };
    for (index, outcome, text) in outcomes {
        let why = match outcome {
            Outcome::Refused { message } => {
                r.refused += 1;
                *r.refusals.entry(kind_of(&message)).or_default() += 1;
                let has_line = message
                    .split_once("layout.toml:")
                    .is_some_and(|(_, rest)| rest.starts_with(|c: char| c.is_ascii_digit()));
                if has_line {
                    None
                } else {
                    r.refused_without_line += 1;
                    Some(format!("refused without a line: {message}"))
                }
            }
            Outcome::Internal(e) => {
                r.internal_errors += 1;
                Some(format!("internal error mid-run: {e}"))
            }
            Outcome::Ran(s) => {
                r.ran += 1;
                r.vehicles += s.vehicles as u64;
                r.collisions += s.collisions;
                r.invariant_violations += s.invariant_violations;
                r.limit_violations += s.limit_violations + s.road_end_overruns + s.off_road;
                r.unpermitted_entries += s.unpermitted_entries();
                r.deadlocks += u64::from(s.deadlock.is_some());
                let bad = s.unsafe_events() > 0 || s.deadlock.is_some();
                bad.then(|| {
                    let mut why = format!(
                        "{} collisions, {} invariant violations, {} limit violations, {} unpermitted entries",
                        s.collisions, s.invariant_violations, s.limit_violations, s.unpermitted_entries()
                    );
                    if let Some(d) = &s.deadlock {
                        let _ = write!(why, ", deadlock at {:.1} s", d.at_s);
                    }
                    why
                })
            }
        };
        if let Some(reason) = why {
            keep_failing(&mut r.failing, || Failing {
                case: index,
                label: "layout".into(),
                reason,
                scenario: text,
            });
        }
    }
    r.wall_seconds = t0.elapsed().as_secs_f64();
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusal_kinds_take_the_numbers_out() {
        assert_eq!(
            kind_of("layout.toml:12: segment 104: length must be positive, got 0.5 m"),
            "segment #: length must be positive, got # m"
        );
    }

    #[test]
    fn cases_are_files_of_both_kinds() {
        let texts: Vec<String> = (0..40).map(|i| case(9, i)).collect();
        assert!(texts.iter().any(|t| t.contains("[grid]")));
        assert!(texts.iter().any(|t| t.contains("[[intersection]]")));
        assert_eq!(case(9, 3), case(9, 3));
    }

    /// With trucks, the same layouts (the insets draw from their own stream), every
    /// intersection with a turn inset and trucks among the arrivals.
    #[test]
    fn cases_with_trucks_are_the_same_layouts_built_for_them() {
        for i in 0..40 {
            let (cars, trucks) = (case(9, i), case_with((9, 30), i));
            let without: String = trucks
                .lines()
                .filter(|l| !l.starts_with("turn_inset = ") && !l.starts_with("trucks = "))
                .map(|l| format!("{l}\n"))
                .collect();
            assert_eq!(without, cars);
            let junctions =
                cars.matches("[[intersection]]").count() + cars.matches("[grid]").count();
            assert_eq!(
                trucks.matches("turn_inset = ").count(),
                junctions,
                "{trucks}"
            );
            assert!(trucks.ends_with("trucks = 30\n"), "{trucks}");
        }
    }
}
