//! `--trace out.csv`: one row per vehicle per step.
//!
//! Columns: `t,id,x,y,theta,v,omega,lane,target_lane,mode` — the state at time t (s;
//! x, y in m; theta in rad, relative to the road), the speed v (m/s) and yaw rate omega
//! (rad/s) commanded for [t, t+h), the lane and target lane (0 = rightmost), and the mode
//! (cruise, lane_change, yield, fallback, waiting, crossing, done).

use crate::sim::TraceRow;
use std::io::{self, Write};

/// The CSV header.
pub const HEADER: &str = "t,id,x,y,theta,v,omega,lane,target_lane,mode";

/// Writes trace rows as CSV.
pub struct TraceWriter<W: Write> {
    out: W,
    /// First write error, reported at the end (rows after it are dropped).
    error: Option<io::Error>,
}

impl<W: Write> TraceWriter<W> {
    /// Writes the header.
    pub fn new(mut out: W) -> io::Result<Self> {
        writeln!(out, "{HEADER}")?;
        Ok(Self { out, error: None })
    }

    /// Appends one row.
    pub fn row(&mut self, r: &TraceRow) {
        if self.error.is_some() {
            return;
        }
        if let Err(e) = writeln!(
            self.out,
            "{:.2},{},{:.6},{:.6},{:.6},{:.6},{:.6},{},{},{}",
            r.t,
            r.id,
            r.x,
            r.y,
            r.theta,
            r.v,
            r.omega,
            r.lane,
            r.target_lane,
            r.mode.as_str()
        ) {
            self.error = Some(e);
        }
    }

    /// Flushes and reports the first error, if any.
    pub fn finish(mut self) -> io::Result<()> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        self.out.flush()
    }
}
