//! `--trace out.csv`: one row per vehicle per step, for every kind of world.
//!
//! Columns: `t,id,x,y,theta,v,omega,lane,target_lane,mode,place,length,width,brake,invariant`
//! — the state at time t
//! (s; x, y in m in the world — a straight road's own frame; theta in rad, relative to
//! the road on a segment, in the world at an intersection), the speed v (m/s) and yaw
//! rate omega (rad/s) commanded for [t, t+h), the lane and target lane (on a segment
//! 0 = rightmost; at an intersection its inlet lane, 0 = inner), the mode (cruise,
//! lane_change, yield, fallback, waiting, crossing, done), and where it is: `s<id>` on
//! segment id (a straight road is `s0`), `j<id>` at intersection id; then what an outside
//! checker needs to judge mixed vehicles: the vehicle's length and width (m), its braking
//! limit (m/s²), and the invariant it keeps (`paper`, `leader-aware`, or `none` for a
//! scripted or random driver, which keeps none and which no follower credits).
//!
//! **Toward whom.** On a segment a vehicle keeping an invariant claims it toward the next
//! vehicle ahead in every lane its rectangle overlaps (lane j spans y ∈ [j Wl, (j+1) Wl]
//! in the segment's frame) and toward the segment's dead end; under `leader-aware` it
//! credits that vehicle with the least distance it still travels braking at the larger of
//! the two `brake` limits unless the vehicle ahead is `none`, and under `paper` it credits
//! nothing — exactly the pairs and rule of [`crate::monitor::road`], so the trace alone
//! lets an outside checker judge every pair (`host-sim/tools/check_trace.py` does, for a
//! straight road).

use crate::world::network::{Network, Place};
use crate::world::TraceRow;
use std::io::{self, Write};

/// The CSV header.
pub const HEADER: &str =
    "t,id,x,y,theta,v,omega,lane,target_lane,mode,place,length,width,brake,invariant";

/// The `place` column of a place in `net`.
pub fn place_name(net: &Network, p: Place) -> String {
    match p {
        Place::Segment(k) => format!("s{}", net.segments.get(k).map_or(0, |s| s.id)),
        Place::Junction(j) => format!("j{}", net.junctions.get(j).map_or(0, |j| j.id)),
    }
}

/// Writes trace rows as CSV.
pub struct TraceWriter<W: Write> {
    out: W,
    /// Names of the places, by segment and junction index.
    segments: Vec<String>,
    junctions: Vec<String>,
    /// First write error, reported at the end (rows after it are dropped).
    error: Option<io::Error>,
}

impl<W: Write> TraceWriter<W> {
    /// Writes the header; places are named after `net`'s ids.
    pub fn new(mut out: W, net: &Network) -> io::Result<Self> {
        writeln!(out, "{HEADER}")?;
        Ok(Self {
            out,
            segments: (0..net.segments.len())
                .map(|k| place_name(net, Place::Segment(k)))
                .collect(),
            junctions: (0..net.junctions.len())
                .map(|j| place_name(net, Place::Junction(j)))
                .collect(),
            error: None,
        })
    }

    /// Appends one row.
    pub fn row(&mut self, r: &TraceRow) {
        if self.error.is_some() {
            return;
        }
        let place = match r.place {
            Place::Segment(k) => self.segments.get(k),
            Place::Junction(j) => self.junctions.get(j),
        }
        .map_or("?", String::as_str);
        if let Err(e) = writeln!(
            self.out,
            "{:.2},{},{:.6},{:.6},{:.6},{:.6},{:.6},{},{},{},{},{},{},{},{}",
            r.t,
            r.id,
            r.x,
            r.y,
            r.theta,
            r.v,
            r.omega,
            r.lane,
            r.target_lane,
            r.mode.as_str(),
            place,
            r.length,
            r.width,
            r.brake,
            r.invariant.map_or("none", crate::world::invariant_name),
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
