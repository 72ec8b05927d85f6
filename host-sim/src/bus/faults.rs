//! Faults the in-process bus injects (scenario `[faults]`, experiment flags).

use super::Message;
use serde::{Deserialize, Serialize};

/// Faults the in-process bus injects, per message and receiver (scenario `[faults]`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Faults {
    /// Probability that a receiver loses a message.
    pub loss: f64,
    /// Delivery delay (s).
    pub delay_s: f64,
    /// Extra delay drawn uniformly from [0, jitter_s] (s).
    pub jitter_s: f64,
    /// Probability that a receiver gets a message twice (the copy up to `jitter_s` + one
    /// period later).
    pub duplicate: f64,
    /// Probability that a message is held back by `reorder_s`, so later ones overtake it.
    pub reorder: f64,
    /// How long a reordered message is held back (s).
    pub reorder_s: f64,
    /// A vehicle whose transmitter goes silent from a time on (it still receives).
    pub silent: Option<Silent>,
    /// A vehicle that lies about its position from a time on.
    pub liar: Option<Liar>,
    /// A junction's manager that stops, then restarts with nothing remembered.
    pub manager_down: Option<ManagerDown>,
}

/// Junction `junction`'s manager stops at `from_s` (it hears and sends nothing; the
/// leases it gave run out) and restarts at `until_s` as a new manager, its state rebuilt
/// from the reports it hears from then on.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ManagerDown {
    /// The junction's id (as the network file names it; 0 for a scenario's single
    /// intersection).
    pub junction: u16,
    /// When it stops (s).
    pub from_s: f64,
    /// When it restarts (s).
    pub until_s: f64,
}

impl Faults {
    /// `true` while the manager of the junction with id `junction` is down at `t`.
    pub fn manager_down_at(&self, junction: u16, t: f64) -> bool {
        self.manager_down
            .is_some_and(|d| d.junction == junction && d.is_down(t))
    }
}

impl ManagerDown {
    /// `true` while the manager is down.
    pub fn is_down(&self, t: f64) -> bool {
        self.from_s <= t && t < self.until_s
    }
}

/// A vehicle going silent.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Silent {
    /// The vehicle.
    pub id: u16,
    /// From when (s).
    pub from_s: f64,
}

/// A vehicle that, from `from_s` on, broadcasts its position `offset_m` further along
/// its road (or its route at a junction) than it is; it drives by the truth. Receivers
/// refuse the jump as implausible and stop taking its word (`world::plausible`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Liar {
    /// The vehicle.
    pub id: u16,
    /// From when (s).
    pub from_s: f64,
    /// How much further on it claims to be (m; negative: further back).
    pub offset_m: f64,
}

impl Liar {
    /// `true` if `msg` is one of its lies (a state or report it sent from `from_s` on,
    /// by the world's `clock`).
    pub fn lied(&self, msg: &Message, clock: &super::Clock) -> bool {
        let lying = |id: u16, stamp| id == self.id && clock.world_secs(stamp) >= self.from_s;
        match *msg {
            Message::State { state, .. } => lying(state.id, state.stamp),
            Message::Crossing { report, stamp, .. } => lying(report.id, stamp),
            _ => false,
        }
    }

    /// `msg` as the liar sends it at `t`: its position moved by the offset once lying.
    pub fn told(&self, from: u16, msg: Message, t: f64) -> Message {
        if from != self.id || t < self.from_s {
            return msg;
        }
        match msg {
            Message::State { mut state, segment } => {
                state.x += self.offset_m;
                Message::State { state, segment }
            }
            Message::Crossing {
                mut report,
                stamp,
                junction,
            } => {
                report.s += self.offset_m;
                Message::Crossing {
                    report,
                    stamp,
                    junction,
                }
            }
            other => other,
        }
    }
}

impl Default for Faults {
    fn default() -> Self {
        Self::NONE
    }
}

impl Faults {
    /// A perfect bus.
    pub const NONE: Faults = Faults {
        loss: 0.0,
        delay_s: 0.0,
        jitter_s: 0.0,
        duplicate: 0.0,
        reorder: 0.0,
        reorder_s: 0.02,
        silent: None,
        liar: None,
        manager_down: None,
    };

    /// Checks the values: probabilities in [0, 1) (a bus that loses everything carries
    /// nothing), times in [0, [`MAX_FAULT_TIME_S`]] s. No protocol needs a tighter bound:
    /// the planners are safe at any loss and delay (stale data never loosens a
    /// constraint); the bound only keeps a run's event queues finite and meaningful.
    pub fn validate(&self) -> Result<(), String> {
        for (name, p) in [
            ("loss", self.loss),
            ("duplicate", self.duplicate),
            ("reorder", self.reorder),
        ] {
            if !(0.0..1.0).contains(&p) {
                return Err(format!("faults.{name} = {p}: must be in [0, 1)"));
            }
        }
        for (name, t) in [
            ("delay_s", self.delay_s),
            ("jitter_s", self.jitter_s),
            ("reorder_s", self.reorder_s),
        ] {
            if !(0.0..=MAX_FAULT_TIME_S).contains(&t) {
                return Err(format!(
                    "faults.{name} = {t}: must be in [0, {MAX_FAULT_TIME_S}] s"
                ));
            }
        }
        if let Some(s) = self.silent {
            start_ok("silent", s.from_s)?;
        }
        if let Some(l) = self.liar {
            start_ok("liar", l.from_s)?;
            if !(l.offset_m.is_finite() && l.offset_m.abs() <= MAX_LIE_M) {
                return Err(format!(
                    "faults.liar.offset_m = {}: must be within ±{MAX_LIE_M} m",
                    l.offset_m
                ));
            }
        }
        if let Some(d) = self.manager_down {
            if !(d.from_s.is_finite()
                && d.from_s >= 0.0
                && d.until_s.is_finite()
                && d.until_s > d.from_s)
            {
                return Err(format!(
                    "faults.manager_down: from_s = {}, until_s = {}: need 0 ≤ from_s < until_s",
                    d.from_s, d.until_s
                ));
            }
        }
        Ok(())
    }

    /// `true` when nothing is injected.
    pub fn is_none(&self) -> bool {
        self.loss == 0.0
            && self.delay_s == 0.0
            && self.jitter_s == 0.0
            && self.duplicate == 0.0
            && self.reorder == 0.0
            && self.silent.is_none()
            && self.liar.is_none()
            && self.manager_down.is_none()
    }

    /// `msg` as vehicle `from` puts it on the bus at `t` (a liar's lie, if any).
    pub fn told(&self, from: u16, msg: Message, t: f64) -> Message {
        self.liar.map_or(msg, |l| l.told(from, msg, t))
    }

    /// A bound on the time until a receiver has a message sent now, given period `h`:
    /// delay, jitter and reordering, plus `LOSS_PERIODS` periods of consecutive losses
    /// (the sender repeats its state every period). The lane-change protocol waits this
    /// long after declaring β and inflates (17) by it.
    pub fn notify_bound(&self, h: f64) -> f64 {
        let lost = if self.loss > 0.0 {
            LOSS_PERIODS as f64 * h
        } else {
            0.0
        };
        let held = if self.reorder > 0.0 {
            self.reorder_s
        } else {
            0.0
        };
        h + self.delay_s + self.jitter_s + held + lost
    }
}

/// A fault's start time `from_s` (of `[faults.<what>]`): finite and ≥ 0.
fn start_ok(what: &str, from_s: f64) -> Result<(), String> {
    if from_s.is_finite() && from_s >= 0.0 {
        Ok(())
    } else {
        Err(format!("faults.{what}.from_s = {from_s}: must be ≥ 0"))
    }
}

/// The largest lie a scenario may script (m): beyond any road's frame it means nothing.
pub const MAX_LIE_M: f64 = 100.0;

/// The longest delay, jitter or hold-back a bus may be given (s).
pub const MAX_FAULT_TIME_S: f64 = 10.0;

/// Consecutive losses of a repeated message the notification bound covers: at 20 % loss,
/// 12 in a row has probability 0.2^12 ≈ 4·10⁻⁹ per message and receiver.
pub const LOSS_PERIODS: u32 = 12;

/// What the injected faults did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FaultStats {
    /// Deliveries lost.
    pub lost: u64,
    /// Messages a silent vehicle did not send.
    pub silenced: u64,
    /// Extra copies delivered.
    pub duplicated: u64,
    /// Deliveries held back for reordering.
    pub reordered: u64,
    /// Deliveries dropped by receivers as duplicate or overtaken.
    pub dropped_old: u64,
}
