//! `run --html`: one self-contained page that plays a run — no network, the data and the
//! script inline. Roads, lanes, stop lines, A_S and A_C are drawn from the network; every
//! vehicle is an L × W rectangle at its heading, coloured by its mode, with play/pause,
//! speed, a time slider, and its id, speed, lanes, mode and grant on hover or click.
//!
//! Size: the run is kept at [`SAMPLE_S`] steps, 16 bytes per vehicle and sample (position
//! in cm, heading in 10⁻⁴ rad, speed in cm/s, mode, lane, target, grant), base64 in the
//! page; a run with more than [`MAX_SAMPLES`] is thinned at write time to fit (the page
//! interpolates between samples). 100 vehicles × 60 s on four lanes weigh 1.3 MB; in
//! headless chromium here the page loads in about 0.5 s and draws a frame in 1.5 ms.

use crate::world::network::{End, Network};
use crate::world::{Mode, TraceRow, LANE_WIDTH_M, LENGTH_M, WIDTH_M};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io;
use std::path::Path;

/// Period at which rows are kept (s).
pub const SAMPLE_S: f64 = 0.1;
/// Most samples a page holds (each 16 bytes).
pub const MAX_SAMPLES: usize = 400_000;

/// One kept row.
#[derive(Debug, Clone, Copy)]
struct Sample {
    x: i32,
    y: i32,
    theta: i16,
    v: u16,
    mode: u8,
    lane: u8,
    target: u8,
    granted: u8,
}

/// A vehicle's samples from sample index `k0`, one per sample period without a gap.
#[derive(Debug, Clone)]
struct Track {
    id: u16,
    /// Its vehicle's length (m): a truck is drawn as long as it is.
    length: f64,
    k0: u64,
    samples: Vec<Sample>,
}

/// Collects a run's rows for its page.
#[derive(Debug, Clone)]
pub struct Viewer {
    net: Network,
    h: f64,
    every: u64,
    tracks: BTreeMap<u16, Vec<Track>>,
    bounds: Bounds,
    last_k: u64,
}

/// The world box that holds every row.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Bounds {
    fn add(&mut self, x: f64, y: f64) {
        self.x0 = self.x0.min(x);
        self.y0 = self.y0.min(y);
        self.x1 = self.x1.max(x);
        self.y1 = self.y1.max(y);
    }
}

fn mode_code(m: Mode) -> u8 {
    match m {
        Mode::Cruise => 0,
        Mode::LaneChange => 1,
        Mode::Yield => 2,
        Mode::Waiting => 3,
        Mode::Crossing => 4,
        Mode::Fallback => 5,
        Mode::Done => 6,
    }
}

impl Viewer {
    /// A viewer of a run on `net` with period `h` (s).
    pub fn new(net: &Network, h: f64) -> Self {
        Self {
            net: net.clone(),
            h,
            every: ((SAMPLE_S / h).round() as u64).max(1),
            tracks: BTreeMap::new(),
            bounds: Bounds {
                x0: f64::INFINITY,
                y0: f64::INFINITY,
                x1: f64::NEG_INFINITY,
                y1: f64::NEG_INFINITY,
            },
            last_k: 0,
        }
    }

    /// Takes one trace row (every [`SAMPLE_S`] of a vehicle's rows are kept).
    pub fn add(&mut self, r: &TraceRow) {
        let step = (r.t / self.h).round() as u64;
        if !(step.is_multiple_of(self.every) && r.x.is_finite() && r.y.is_finite()) {
            return;
        }
        let k = step / self.every;
        self.last_k = self.last_k.max(k);
        self.bounds.add(r.x, r.y);
        let theta = (r.theta + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        let s = Sample {
            x: (r.x * 100.0).round() as i32,
            y: (r.y * 100.0).round() as i32,
            theta: (theta * 1e4).round() as i16,
            v: (r.v.max(0.0) * 100.0).round().min(65535.0) as u16,
            mode: mode_code(r.mode),
            lane: r.lane,
            target: r.target_lane,
            granted: match r.granted {
                None => 0,
                Some(false) => 1,
                Some(true) => 2,
            },
        };
        let tracks = self.tracks.entry(r.id).or_default();
        match tracks.last_mut() {
            Some(t) if t.k0 + t.samples.len() as u64 == k => t.samples.push(s),
            _ => tracks.push(Track {
                id: r.id,
                length: r.length,
                k0: k,
                samples: vec![s],
            }),
        }
    }

    /// Samples kept so far.
    pub fn samples(&self) -> usize {
        self.tracks
            .values()
            .flat_map(|v| v.iter().map(|t| t.samples.len()))
            .sum()
    }

    /// Writes the page for a run named `title` to `path`.
    pub fn write(&self, title: &str, path: &Path) -> io::Result<()> {
        std::fs::write(path, self.page(title))
    }

    /// The page.
    pub fn page(&self, title: &str) -> String {
        // Thin to fit: keep every `thin`-th sample.
        let thin = self.samples().div_ceil(MAX_SAMPLES).max(1) as u64;
        let mut bytes = Vec::new();
        let mut meta = String::from("[");
        for t in self.tracks.values().flatten() {
            let first = t.k0.div_ceil(thin) * thin;
            let kept: Vec<&Sample> = t
                .samples
                .iter()
                .enumerate()
                .filter(|(i, _)| (t.k0 + *i as u64).is_multiple_of(thin))
                .map(|(_, s)| s)
                .collect();
            if kept.is_empty() {
                continue;
            }
            let _ = write!(
                meta,
                "{}[{},{},{},{},{}]",
                if meta.len() > 1 { "," } else { "" },
                t.id,
                first / thin,
                kept.len(),
                bytes.len() / 16,
                finite(t.length)
            );
            for s in kept {
                bytes.extend_from_slice(&s.x.to_le_bytes());
                bytes.extend_from_slice(&s.y.to_le_bytes());
                bytes.extend_from_slice(&s.theta.to_le_bytes());
                bytes.extend_from_slice(&s.v.to_le_bytes());
                bytes.extend_from_slice(&[s.mode, s.lane, s.target, s.granted]);
            }
        }
        meta.push(']');
        let data = format!(
            "{{\"title\":{},\"dt\":{},\"end\":{},\"L\":{},\"W\":{},\"laneW\":{},\"tracks\":{},\"net\":{},\"bounds\":[{},{},{},{}]}}",
            json_string(title),
            SAMPLE_S * thin as f64,
            self.last_k as f64 * SAMPLE_S,
            LENGTH_M,
            WIDTH_M,
            LANE_WIDTH_M,
            meta,
            self.geometry(),
            finite(self.bounds.x0),
            finite(self.bounds.y0),
            finite(self.bounds.x1),
            finite(self.bounds.y1),
        );
        TEMPLATE
            .replace("__TITLE__", &html_escape(title))
            .replace("__DATA__", &data)
            .replace("__SAMPLES__", &base64(&bytes))
    }

    /// Roads and junctions as JSON for the page.
    fn geometry(&self) -> String {
        let right = finite(self.bounds.x1) + 50.0;
        let segs: Vec<String> = self
            .net
            .segments
            .iter()
            .map(|s| {
                let (kind, end) = match s.end {
                    End::Open => ("open", right.max(100.0)),
                    End::DeadEnd(x) => ("dead", x),
                    End::Exit(x) => ("exit", x),
                    End::Junction(_, x) => ("stop", x),
                };
                format!(
                    "{{\"o\":[{},{}],\"h\":{},\"len\":{},\"lanes\":{},\"end\":\"{kind}\",\"start\":{}}}",
                    s.origin.0,
                    s.origin.1,
                    s.heading,
                    end,
                    s.lanes,
                    if s.from.is_none() && matches!(s.end, End::Open | End::DeadEnd(_)) {
                        finite(self.bounds.x0).min(0.0) - 50.0
                    } else {
                        0.0
                    }
                )
            })
            .collect();
        let juncs: Vec<String> = self
            .net
            .junctions
            .iter()
            .map(|j| {
                let sp = &j.layout.spec;
                let stub = |h: usize| j.inlets[h].is_none() && j.outlets[(h + 2) % 4].is_none();
                format!(
                    "{{\"c\":[{},{}],\"a\":{},\"m\":{},\"lanes\":{},\"arm\":{},\"stubs\":[{},{},{},{}]}}",
                    j.centre.0,
                    j.centre.1,
                    sp.half_size,
                    sp.comm_margin,
                    sp.lanes,
                    sp.inlet_length.max(sp.outlet_length),
                    stub(0),
                    stub(1),
                    stub(2),
                    stub(3)
                )
            })
            .collect();
        format!(
            "{{\"segments\":[{}],\"junctions\":[{}]}}",
            segs.join(","),
            juncs.join(",")
        )
    }
}

/// `x`, or 0 if it is not finite (an empty run).
fn finite(x: f64) -> f64 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

fn json_string(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into())
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Standard base64 (RFC 4648) with padding.
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(c.get(1).copied().unwrap_or(0)) << 8)
            | u32::from(c.get(2).copied().unwrap_or(0));
        for i in 0..4 {
            if i <= c.len() {
                out.push(char::from(A[((n >> (18 - 6 * i)) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// The page: HTML, CSS and the player script; `__DATA__` and `__SAMPLES__` are filled in.
const TEMPLATE: &str = include_str!("viewer.html");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(i.as_bytes()), o);
        }
    }
}
