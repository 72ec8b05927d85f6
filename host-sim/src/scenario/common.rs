//! What every scenario format shares: its duration and seed, the faults its bus injects,
//! the vehicles' onboard sensors, the deadlock window, and the ranges every value must
//! keep.

use super::error::Errors;
use super::ScenarioError;
use crate::bus::Faults;
use crate::monitor::liveness::DEADLOCK_WINDOW_S;
use planner_core::{Invariant, Params, Real, Sensing};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use toml::Spanned;

/// Longest scenario (s).
pub const MAX_DURATION_S: f64 = 86_400.0;
/// Largest coordinate, length or goal (m): planner-core's f64 range (`Real::MAX_COORD_M`,
/// 1,000 km), within which one ulp of a position is below 1.2e-10 m — far below every
/// safety margin. Beyond it the spacing of positions alone can break the invariant
/// (x ≈ 5.6e14 m, where f64 positions are 6 cm apart).
pub const MAX_COORD_M: f64 = <f64 as Real>::MAX_COORD_M;

/// The `[sensing]` table: every planner-driven vehicle's onboard range sensors.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SensingToml {
    /// On or off (default: on when the scenario has `[faults]`, off otherwise — the
    /// paper's world, where every vehicle is known from V2V alone).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub enabled: Option<bool>,
    /// Forward range (m).
    #[serde(default = "radar_ahead")]
    pub ahead_m: f64,
    /// Rear and side range (m).
    #[serde(default = "radar_behind")]
    pub behind_m: f64,
    /// Position error bound (m).
    #[serde(default = "radar_error")]
    pub position_error_m: f64,
    /// Speed error bound (m/s).
    #[serde(default = "radar_error")]
    pub speed_error_mps: f64,
}

impl SensingToml {
    /// The table that says exactly `sensing`: on with its figures, or off — always
    /// written, since a file without it gets the default, which depends on its faults.
    pub fn of(sensing: Option<Sensing<f64>>) -> Self {
        let s = sensing.unwrap_or_else(Sensing::radar);
        Self {
            enabled: Some(sensing.is_some()),
            ahead_m: s.ahead_m,
            behind_m: s.behind_m,
            position_error_m: s.position_error_m,
            speed_error_mps: s.speed_error_mps,
        }
    }
}

fn radar_ahead() -> f64 {
    Sensing::<f64>::radar().ahead_m
}
fn radar_behind() -> f64 {
    Sensing::<f64>::radar().behind_m
}
fn radar_error() -> f64 {
    Sensing::<f64>::radar().position_error_m
}

/// The header fields every format has, as written.
#[derive(Debug, Clone, Default)]
pub struct RawHeader {
    /// `duration_s`.
    pub duration_s: Option<Spanned<f64>>,
    /// `horizon`.
    pub horizon: Option<Spanned<usize>>,
    /// `deadline_s`.
    pub deadline_s: Option<Spanned<f64>>,
    /// `[faults]`.
    pub faults: Option<Spanned<Faults>>,
    /// `[sensing]`.
    pub sensing: Option<Spanned<SensingToml>>,
    /// `deadlock_s`.
    pub deadlock_s: Option<Spanned<f64>>,
    /// `invariant`.
    pub invariant: Option<Spanned<String>>,
}

/// The header, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// Simulated time (s).
    pub duration_s: f64,
    /// MPC horizon N (20 or 50).
    pub horizon: usize,
    /// Liveness deadline of road goals (s).
    pub deadline_s: f64,
    /// Faults the bus injects.
    pub faults: Faults,
    /// Onboard sensors, if on.
    pub sensing: Option<Sensing<f64>>,
    /// No vehicle moving this long while goals remain is a deadlock (s).
    pub deadlock_window_s: f64,
    /// The invariant kept toward the vehicle ahead.
    pub invariant: Invariant,
}

fn span<T>(s: &Option<Spanned<T>>) -> Option<Range<usize>> {
    s.as_ref().map(Spanned::span)
}

impl RawHeader {
    /// Validates: duration in (0, 86,400] s; horizon 20 or 50; deadline in (0, duration];
    /// faults valid; sensing valid (ranges at least `Sensing::min_range`); a lossy or
    /// silent bus only with sensors (without them the paper's world rests on every
    /// message arriving: safety then needs a bound on consecutive losses that no loss
    /// rate guarantees); deadlock window positive.
    pub fn validate(&self, e: &Errors<'_>) -> Result<Header, ScenarioError> {
        let duration_s = self.duration_s.as_ref().map_or(0.0, |d| *d.get_ref());
        if !(duration_s > 0.0 && duration_s <= MAX_DURATION_S) {
            return Err(e.at(
                span(&self.duration_s),
                format!("duration_s must be in (0, {MAX_DURATION_S}], got {duration_s}"),
            ));
        }
        let horizon = match &self.horizon {
            None => 20,
            Some(h) if matches!(*h.get_ref(), 20 | 50) => *h.get_ref(),
            Some(h) => {
                return Err(e.at(
                    Some(h.span()),
                    format!("horizon must be 20 or 50, got {}", h.get_ref()),
                ))
            }
        };
        let deadline_s = match &self.deadline_s {
            None => duration_s,
            Some(d) if *d.get_ref() > 0.0 && *d.get_ref() <= duration_s => *d.get_ref(),
            Some(d) => {
                return Err(e.at(
                    Some(d.span()),
                    format!("deadline_s must be in (0, duration_s], got {}", d.get_ref()),
                ))
            }
        };
        let faults = match &self.faults {
            None => Faults::NONE,
            Some(f) => {
                f.get_ref()
                    .validate()
                    .map_err(|m| e.at(Some(f.span()), m))?;
                *f.get_ref()
            }
        };
        let sensing = self.sensing(e, &faults)?;
        let deadlock_window_s = match &self.deadlock_s {
            None => DEADLOCK_WINDOW_S,
            Some(d) if *d.get_ref() > 0.0 && d.get_ref().is_finite() => *d.get_ref(),
            Some(d) => {
                return Err(e.at(
                    Some(d.span()),
                    format!("deadlock_s must be positive, got {}", d.get_ref()),
                ))
            }
        };
        let invariant = match &self.invariant {
            None => crate::world::DEFAULT_INVARIANT,
            Some(i) => parse_invariant(i.get_ref()).map_err(|m| e.at(Some(i.span()), m))?,
        };
        Ok(Header {
            duration_s,
            horizon,
            deadline_s,
            faults,
            sensing,
            deadlock_window_s,
            invariant,
        })
    }

    fn sensing(
        &self,
        e: &Errors<'_>,
        faults: &Faults,
    ) -> Result<Option<Sensing<f64>>, ScenarioError> {
        let table = self.sensing.as_ref().map(|s| *s.get_ref());
        let on = table.and_then(|t| t.enabled).unwrap_or(!faults.is_none());
        if !on {
            if faults.loss > 0.0 || faults.silent.is_some() {
                let at = span(&self.sensing).or(span(&self.faults));
                return Err(e.at(
                    at,
                    "a bus that loses messages or a silent vehicle needs sensing: without \
                     sensors, safety rests on every message arriving (remove \
                     `enabled = false` from [sensing])",
                ));
            }
            return Ok(None);
        }
        let t = table.unwrap_or(SensingToml {
            enabled: Some(true),
            ahead_m: radar_ahead(),
            behind_m: radar_behind(),
            position_error_m: radar_error(),
            speed_error_mps: radar_error(),
        });
        let s = Sensing {
            ahead_m: t.ahead_m,
            behind_m: t.behind_m,
            position_error_m: t.position_error_m,
            speed_error_mps: t.speed_error_mps,
        };
        let p = Params::<f64>::table_i();
        s.validate(&p).map_err(|_| {
            e.at(
                span(&self.sensing),
                format!(
                    "sensing: ranges must be at least {:.1} m (dS(vmax) + d0 + one period at \
                     vmax + 1 m) and error bounds in [0, 1)",
                    Sensing::min_range(&p)
                ),
            )
        })?;
        Ok(Some(s))
    }
}

/// `[arrivals]`: an open system.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ArrivalsToml {
    /// Poisson arrivals per entry lane (vehicles per hour).
    pub rate_vph: f64,
    /// Percent of the arrivals that are trucks (16.5 m, braking at 4.5 m/s²), each drawn
    /// at random.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub trucks: u8,
}

fn is_zero(x: &u8) -> bool {
    *x == 0
}

impl ArrivalsToml {
    /// `[arrivals]`, if given, checked: 0 to 3,600 vehicles per hour per lane, 0 to 100 %
    /// trucks.
    pub fn checked(
        a: Option<&Spanned<ArrivalsToml>>,
        e: &Errors,
    ) -> Result<Option<ArrivalsToml>, ScenarioError> {
        let Some(a) = a else {
            return Ok(None);
        };
        let got = *a.get_ref();
        if !(0.0..=3600.0).contains(&got.rate_vph) {
            return Err(e.at(
                Some(a.span()),
                "arrivals.rate_vph must be in [0, 3600] vehicles per hour per lane",
            ));
        }
        if got.trucks > 100 {
            return Err(e.at(Some(a.span()), "arrivals.trucks is a percentage: 0 to 100"));
        }
        Ok(Some(got))
    }

    /// Cars at `rate_vph`.
    pub fn cars(rate_vph: f64) -> Self {
        Self {
            rate_vph,
            trucks: 0,
        }
    }
}

/// The invariant named `name` (`"paper"` or `"leader-aware"`), or why not.
pub fn parse_invariant(name: &str) -> Result<Invariant, String> {
    crate::world::invariant_named(name)
}

/// `true` if `x` is a usable coordinate (finite, within ±[`MAX_COORD_M`]).
pub fn coord_ok(x: f64) -> bool {
    x.is_finite() && x.abs() <= MAX_COORD_M
}
