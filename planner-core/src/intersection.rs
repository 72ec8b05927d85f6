//! Intersections (Sec. VI, SPEC §7): the layout (A_S, A_C, inlet and outlet tracks,
//! routes as lines and arcs), route conflicts from the area a vehicle sweeps, the
//! Spaciousness Assumption (27), and the intersection manager with its crossing
//! algorithms: FIFO, Concurrent Crossing (Steps 1–5), a starvation-free variant, the
//! All-Way STOP baseline, and a less conservative pipelined algorithm.
//!
//! Geometry (SPEC §8's choice): four roads meet at the origin; A_S is the square
//! |x|, |y| ≤ a; A_C is A_S grown by `comm_margin`. Right-hand traffic, n inlet and n
//! outlet lanes per road (2 by default, SPEC §8; 1 to [`MAX_LANES`] when configured, SPEC
//! §10); lane 0 is the inner one. Inlets are numbered by the heading of travel d (0 east,
//! 1 north, 2 west, 3 south): inlet (d, l) comes from the side opposite d. The inner lane
//! goes straight or turns left into the inner outlet lane; the outer lane goes straight
//! or turns right into the outer outlet lane; lanes between go straight into the outlet
//! lane of the same index (a single lane does all three): 16 routes for n = 2, 4(n + 2)
//! for n ≥ 2. Everything is built for d = 0 and rotated by d · 90°.

use crate::params::Params;
use crate::real::Real;
use crate::safety;
use crate::unicycle::Pose;
use heapless::Vec;

/// Routes of the SPEC §8 layout (two lanes per approach).
pub const ROUTES: usize = 16;
/// Most lanes per approach.
pub const MAX_LANES: u8 = 4;
/// Most routes of any layout: 4 (n + 2) for n = [`MAX_LANES`]; route sets are bit masks
/// of a `u32`.
pub const MAX_ROUTES: usize = 24;
/// Spacing (m) of the poses sampled along a route to compute conflicts: 0.25 m is a
/// fraction of the vehicle width, so no overlap of swept areas falls between samples
/// by more than the margin below.
pub const CONFLICT_SAMPLE_M: f64 = 0.25;
/// Margin (m) added around the vehicle rectangle when computing conflicts, covering
/// the sampling (a chord error below 0.25²/(8·6.6) m) with room to spare.
pub const CONFLICT_MARGIN_M: f64 = 0.1;

/// A manoeuvre through A_S.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Movement {
    /// Straight on, same lane.
    Straight,
    /// Left turn, inner lane to inner lane.
    Left,
    /// Right turn, outer lane to outer lane.
    Right,
}

/// A track: heading of travel d (0 east, 1 north, 2 west, 3 south) and lane (0 inner).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Track {
    /// Heading of travel, 0..4.
    pub heading: u8,
    /// Lane, 0 (inner) or 1 (outer).
    pub lane: u8,
}

/// A path piece.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Segment<F> {
    /// From `start` along `heading` for `length`.
    Line {
        /// Start pose (x, y, heading).
        start: Pose<F>,
        /// Length (m).
        length: F,
    },
    /// Circular arc: centre, radius, start angle of the radius vector, signed sweep
    /// (positive = counter-clockwise).
    Arc {
        /// Centre x (m).
        cx: F,
        /// Centre y (m).
        cy: F,
        /// Radius (m).
        radius: F,
        /// Angle of the start point seen from the centre (rad).
        start_angle: F,
        /// Signed sweep (rad).
        sweep: F,
    },
}

impl<F: Real> Segment<F> {
    /// Length (m).
    pub fn length(&self) -> F {
        match *self {
            Segment::Line { length, .. } => length,
            Segment::Arc { radius, sweep, .. } => radius * sweep.abs(),
        }
    }

    /// Pose at distance `s` from its start (clamped to the piece).
    pub fn pose_at(&self, s: F) -> Pose<F> {
        let s = s.max(F::ZERO).min(self.length());
        match *self {
            Segment::Line { start, .. } => Pose {
                x: start.x + s * start.theta.cos(),
                y: start.y + s * start.theta.sin(),
                theta: start.theta,
            },
            Segment::Arc {
                cx,
                cy,
                radius,
                start_angle,
                sweep,
            } => {
                let dir = if sweep >= F::ZERO { F::ONE } else { -F::ONE };
                let ang = start_angle + dir * s / radius;
                Pose {
                    x: cx + radius * ang.cos(),
                    y: cy + radius * ang.sin(),
                    theta: ang + dir * F::FRAC_PI_2,
                }
            }
        }
    }
}

/// A vehicle's whole path: inlet track, route through A_S, outlet track.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Path<F> {
    /// The five pieces: the inlet track; inside A_S, the straight run before the turn
    /// ([`LayoutSpec::turn_inset`]; of length 0 without one), the manoeuvre and the
    /// straight run after it; the outlet track.
    pub pieces: [Segment<F>; 5],
}

impl<F: Real> Path<F> {
    fn piece_length(&self, i: usize) -> F {
        self.pieces.get(i).map_or(F::ZERO, Segment::length)
    }
    /// Distance from the path start to A_S (the stop line).
    pub fn entry(&self) -> F {
        self.piece_length(0)
    }
    /// Distance from the path start to where A_S ends (start of the outlet track).
    pub fn exit(&self) -> F {
        self.piece_length(0) + self.piece_length(1) + self.piece_length(2) + self.piece_length(3)
    }
    /// Total length.
    pub fn length(&self) -> F {
        self.exit() + self.piece_length(4)
    }
    /// Pose at `s` along the path (clamped).
    pub fn pose_at(&self, s: F) -> Pose<F> {
        let mut rest = s;
        let last = self.pieces.len() - 1;
        for (i, piece) in self.pieces.iter().enumerate() {
            let l = piece.length();
            if rest <= l || i == last {
                return piece.pose_at(rest);
            }
            rest -= l;
        }
        Pose::default()
    }
}

/// A route through A_S.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Route<F> {
    /// Inlet track.
    pub inlet: Track,
    /// Outlet track.
    pub outlet: Track,
    /// Manoeuvre.
    pub movement: Movement,
    /// Inlet, route and outlet as one path.
    pub path: Path<F>,
}

/// What a layout is built from.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LayoutSpec<F> {
    /// Half-size a of the square A_S (m).
    pub half_size: F,
    /// A_C = A_S grown by this (m).
    pub comm_margin: F,
    /// Inlet track length before the stop line (m).
    pub inlet_length: F,
    /// Outlet track length past A_S (m).
    pub outlet_length: F,
    /// Lane width (m).
    pub lane_width: F,
    /// Speed limit inside the intersection scenario vImax (m/s).
    pub v_limit: F,
    /// Inlet (and outlet) lanes per approach, 1 to [`MAX_LANES`].
    pub lanes: u8,
    /// How far inside A_S the turns begin and end (m; 0 in SPEC §8): the turns are the
    /// quarter circles of a square of half-size a − inset, each run straight for `inset`
    /// from the stop line and to the outlet. A larger A_S around the same turns keeps a
    /// long vehicle's swing inside it: a 16.5 m rectangle turning right on SPEC §8's
    /// 6.6 m radius swings its rear 4 m sideways, into the next inlet lane, where
    /// vehicles wait ([`LayoutError::SweepLeavesItsLanes`]).
    pub turn_inset: F,
}

impl<F: Real> LayoutSpec<F> {
    /// SPEC §8: a = 12 m, A_C 50 m around A_S, inlets 100 m, outlets 60 m, vImax = vmax/2.
    pub fn spec8(p: &Params<F>) -> Self {
        Self {
            half_size: F::from_f64(12.0),
            comm_margin: F::from_f64(50.0),
            inlet_length: F::from_f64(100.0),
            outlet_length: F::from_f64(60.0),
            lane_width: p.spec().lane_width,
            v_limit: F::HALF * p.v_max(),
            lanes: 2,
            turn_inset: F::ZERO,
        }
    }
}

/// Why a layout is rejected.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum LayoutError<F> {
    /// A value is NaN, infinite or not positive.
    NotPositive,
    /// The n inlet lanes (n Wl) do not fit in the half-size a, or n is not 1 to
    /// [`MAX_LANES`].
    LanesDoNotFit,
    /// A turn's radius would be below ρmin (the right turn has radius a − (n − ½) Wl).
    TurnTooTight {
        /// The radius the layout gives (m).
        radius: F,
    },
    /// The Spaciousness Assumption (27) fails: ∂A_C is `margin` from A_S but must be at
    /// least dS(vImax) + vImax h = `needed`.
    NotSpacious {
        /// The layout's margin (m).
        margin: F,
        /// dS(vImax) + vImax h (m).
        needed: F,
    },
    /// The inlet track does not reach back to ∂A_C (vehicles must arrive through A_C).
    InletShorterThanCommRegion,
    /// The outlet track does not reach a vehicle length beyond ∂A_C: a vehicle leaves the
    /// intersection (C^I_t (25)) once it is on its outlet outside A_C, so every outlet must
    /// take it there; a shorter one ends inside A_C, where vehicles could only pile up
    /// (40 m outlets, 4,864 collisions).
    OutletShorterThanCommRegion {
        /// The outlet length (m).
        length: F,
        /// comm_margin + L (m).
        needed: F,
    },
    /// The turn inset is negative or not finite, or leaves the lanes no room (n Wl must
    /// fit in a − inset).
    BadTurnInset,
    /// A vehicle of the layout's length and width, its centre anywhere on `route`
    /// between the stop line and the outlet, is partly outside both A_S and its own inlet
    /// and outlet lanes (by up to `by` m): its swing reaches a lane where others wait or
    /// drive, or the kerb. A larger A_S around the same turns
    /// ([`LayoutSpec::turn_inset`]) keeps it inside.
    SweepLeavesItsLanes {
        /// The route (index).
        route: usize,
        /// How far outside (m).
        by: F,
    },
}

/// The first sentence of each variant's documentation (and its data).
impl<F: core::fmt::Debug> core::fmt::Display for LayoutError<F> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotPositive => f.write_str("a value is NaN, infinite or not positive"),
            Self::LanesDoNotFit => f.write_str("the n inlet lanes (n Wl) do not fit in the half-size a, or n is not 1 to MAX_LANES"),
            Self::TurnTooTight { .. } => write!(f, "a turn's radius would be below ρmin (the right turn has radius a − (n − ½) Wl) ({self:?})"),
            Self::NotSpacious { .. } => write!(f, "the Spaciousness Assumption (27) fails: ∂A_C is margin from A_S but must be at least dS(vImax) + vImax h = needed ({self:?})"),
            Self::InletShorterThanCommRegion => f.write_str("the inlet track does not reach back to ∂A_C (vehicles must arrive through A_C)"),
            Self::OutletShorterThanCommRegion { .. } => write!(f, "the outlet track does not reach a vehicle length beyond ∂A_C: a vehicle leaves the intersection (C^I_t (25)) once it is on its outlet outside A_C, so every outlet must take it there; a shorter one ends inside A_C, where vehicles could only pile up ({self:?})"),
            Self::BadTurnInset => f.write_str("the turn inset is negative or not finite, or leaves the lanes no room (n Wl must fit in a − inset)"),
            Self::SweepLeavesItsLanes { .. } => write!(f, "a vehicle of the layout's length and width, its centre anywhere on route between the stop line and the outlet, is partly outside both A_S and its own inlet and outlet lanes (by up to by m) ({self:?})"),
        }
    }
}

impl<F: core::fmt::Debug> core::error::Error for LayoutError<F> {}

/// The intersection: geometry, routes and their conflicts.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout<F> {
    /// The spec it was built from.
    pub spec: LayoutSpec<F>,
    /// The routes, indexed by [`Layout::route_index`]; the index is also the fixed
    /// route order Ψ of the FIFO tie-break.
    pub routes: Vec<Route<F>, MAX_ROUTES>,
    /// `conflicts[i]` bit j: γ_i ⊗ γ_j.
    pub conflicts: [u32; MAX_ROUTES],
    /// `zone_end[i][j]`: along route i (distance from its A_S entry), where the part of its
    /// path whose footprint meets route j's swept area ends; NEG if none.
    pub zone_end: [[F; MAX_ROUTES]; MAX_ROUTES],
    /// `trails[i]` bit j: a vehicle on route j may follow one on route i (i ≠ j, the same
    /// inlet lane) into A_S while the leader is still in its conflict zone with j, when
    /// both are of the layout's length L: at L + d0 or more apart along their common arc
    /// length (what the invariant keeps between a follower and the wall it keeps on its
    /// leader, [`crate::crossing::CrossingPlanner::step`]), their L × W footprints plus
    /// margin do not meet at any sampled pair of positions while the leader's centre is
    /// within `zone_end[i][j]` (plus one sample) of its A_S entry
    /// (checked in `Layout::new`). A route trails itself (Theorem 1).
    pub trails: [u32; MAX_ROUTES],
    /// The vehicle length L (m) the trails were checked for: a pair of other lengths
    /// stands closer or sweeps otherwise, and is not covered.
    pub trail_length: F,
}

/// The manoeuvres inlet lane `lane` of `n` serves, in route order (SPEC §10): the inner
/// lane (0) straight and left, the outer (n − 1) straight and right, the others straight;
/// a single lane all three.
pub fn lane_movements(lane: u8, n: u8) -> &'static [Movement] {
    match (lane, n) {
        (0, 1) => &[Movement::Straight, Movement::Left, Movement::Right],
        (0, _) => &[Movement::Straight, Movement::Left],
        (l, n) if l + 1 == n => &[Movement::Straight, Movement::Right],
        _ => &[Movement::Straight],
    }
}

fn rotate<F: Real>(p: Pose<F>, quarter_turns: u8) -> Pose<F> {
    let (mut x, mut y) = (p.x, p.y);
    for _ in 0..quarter_turns % 4 {
        let t = x;
        x = -y;
        y = t;
    }
    Pose {
        x,
        y,
        theta: p.theta + F::from_usize(usize::from(quarter_turns % 4)) * F::FRAC_PI_2,
    }
}

fn rotate_segment<F: Real>(s: Segment<F>, q: u8) -> Segment<F> {
    match s {
        Segment::Line { start, length } => Segment::Line {
            start: rotate(start, q),
            length,
        },
        Segment::Arc {
            cx,
            cy,
            radius,
            start_angle,
            sweep,
        } => {
            let c = rotate(
                Pose {
                    x: cx,
                    y: cy,
                    theta: F::ZERO,
                },
                q,
            );
            Segment::Arc {
                cx: c.x,
                cy: c.y,
                radius,
                start_angle: start_angle + F::from_usize(usize::from(q % 4)) * F::FRAC_PI_2,
                sweep,
            }
        }
    }
}

/// Corners of an L × W rectangle (inflated by `m`) at a pose.
fn corners<F: Real>(q: Pose<F>, hl: F, hw: F) -> [(F, F); 4] {
    Footprint::of(q).corners(hl, hw)
}

/// A rectangle's centre with its heading's sine and cosine, taken once. The
/// separating-axis test needs them for the corners and again for the axes, and the
/// layout's checks ([`Layout::compute_conflicts`], [`Layout::compute_trails`]) test each
/// sampled pose against hundreds of others: computed per test, the sines and cosines
/// were most of a layout's 40 ms. The same values enter the same arithmetic, so every
/// answer is the same, bit for bit.
#[derive(Debug, Clone, Copy)]
struct Footprint<F> {
    x: F,
    y: F,
    sin: F,
    cos: F,
}

impl<F: Real> Footprint<F> {
    fn of(q: Pose<F>) -> Self {
        Self {
            x: q.x,
            y: q.y,
            sin: q.theta.sin(),
            cos: q.theta.cos(),
        }
    }

    fn corners(self, hl: F, hw: F) -> [(F, F); 4] {
        let (s, c) = (self.sin, self.cos);
        [(hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw)]
            .map(|(u, w)| (self.x + u * c - w * s, self.y + u * s + w * c))
    }
}

/// How far (m) a rectangle of half-length `hl` and half-width `hw`, its centre at any
/// point of `path` between the stop line and the outlet, reaches outside both A_S (the
/// square of half-size `a`) and its own inlet and outlet lanes (`wl` wide), less a
/// micrometre of rounding (a straight run's corners sit inside their lane only to float
/// error); 0 if nowhere. The centre is taken at [`SWEEP_PATH_SAMPLES`] + 1 points
/// spread evenly over the path through A_S (0.16 m apart on a 40 m path), each
/// rectangle at [`SWEEP_EDGE_SAMPLES`] + 1 points along each edge.
fn sweep_outside<F: Real>(path: &Path<F>, a: F, wl: F, (hl, hw): (F, F)) -> F {
    let (entry, exit) = (path.entry(), path.exit());
    let lanes = (
        Footprint::of(path.pose_at(entry)),
        Footprint::of(path.pose_at(exit)),
    );
    let outside = |p: (F, F)| outside_lanes(p, a, wl, lanes);
    let (n_path, n_edge) = (
        F::from_usize(SWEEP_PATH_SAMPLES),
        F::from_usize(SWEEP_EDGE_SAMPLES),
    );
    let mut worst = F::ZERO;
    for k in 0..=SWEEP_PATH_SAMPLES {
        let s = entry + (exit - entry) * F::from_usize(k) / n_path;
        let c = corners(path.pose_at(s), hl, hw);
        for (&(x0, y0), &(x1, y1)) in c.iter().zip(c.iter().cycle().skip(1)) {
            for i in 0..=SWEEP_EDGE_SAMPLES {
                let t = F::from_usize(i) / n_edge;
                worst = worst.max(outside((x0 + t * (x1 - x0), y0 + t * (y1 - y0))));
            }
        }
    }
    (worst - F::from_f64(1e-6)).max(F::ZERO)
}

/// How far (m) point `(x, y)` is outside A_S (the square of half-size `a`) and both lane
/// strips `wl` wide — the inlet's behind the stop line at `inlet_end`, the outlet's past
/// its start at `outlet_start` — at its nearest; negative inside one of them.
fn outside_lanes<F: Real>(
    (x, y): (F, F),
    a: F,
    wl: F,
    (inlet_end, outlet_start): (Footprint<F>, Footprint<F>),
) -> F {
    let in_square = (x.abs() - a).max(y.abs() - a);
    // Signed distance outside a lane strip: behind the line (`ahead` −1) or past the
    // outlet's start (+1), within half a lane of its centre line. The strips' headings'
    // cosines and sines come with them: this runs for 66,820 points of every route.
    let strip = |q: Footprint<F>, ahead: F| {
        let (c, s) = (q.cos, q.sin);
        let (dx, dy) = (x - q.x, y - q.y);
        let along = ahead * (dx * c + dy * s);
        let across = (dy * c - dx * s).abs() - F::HALF * wl;
        across.max(-along)
    };
    in_square
        .min(strip(inlet_end, -F::ONE))
        .min(strip(outlet_start, F::ONE))
}

/// Centre positions along a path through A_S in [`sweep_outside`], less one.
const SWEEP_PATH_SAMPLES: usize = 256;
/// Points along each edge of a rectangle in [`sweep_outside`], less one (0.26 m apart on
/// a truck's 16.5 m side).
const SWEEP_EDGE_SAMPLES: usize = 64;

/// The most samples [`Layout::compute_trails`] takes along one stretch.
const TRAIL_SAMPLES: usize = 512;

/// How many samples `step` apart cover `[0, length]`, both ends included; `None` past
/// [`TRAIL_SAMPLES`] (or for a length that is not finite).
fn samples_in<F: Real>(length: F, step: F) -> Option<usize> {
    let mut n = 1;
    while F::from_usize(n - 1) * step < length {
        if n >= TRAIL_SAMPLES {
            return None;
        }
        n += 1;
    }
    length.is_finite().then_some(n)
}

/// Separating-axis test of two oriented rectangles (touching counts as overlap).
pub fn rectangles_meet<F: Real>(a: Pose<F>, b: Pose<F>, hl: F, hw: F) -> bool {
    footprints_meet(Footprint::of(a), Footprint::of(b), hl, hw)
}

/// [`rectangles_meet`] of two footprints.
fn footprints_meet<F: Real>(a: Footprint<F>, b: Footprint<F>, hl: F, hw: F) -> bool {
    // Each rectangle lies in the circle of its half-diagonal around its centre, so
    // centres farther apart than two of those cannot meet; the centimetre keeps a
    // touching pair (the test's `true`) clear of rounding. Most sampled pairs of a
    // layout's checks end here.
    let (dx, dy) = (a.x - b.x, a.y - b.y);
    let reach = F::TWO * (hl * hl + hw * hw).sqrt() + F::from_f64(0.01);
    if dx * dx + dy * dy > reach * reach {
        return false;
    }
    let (ca, cb) = (a.corners(hl, hw), b.corners(hl, hw));
    for q in [a, b] {
        let (s, c) = (q.sin, q.cos);
        for (ax, ay) in [(c, s), (-s, c)] {
            let proj = |cs: &[(F, F); 4]| {
                cs.iter().fold(
                    (F::from_f64(1e30), F::from_f64(-1e30)),
                    |(lo, hi), &(x, y)| {
                        let p = x * ax + y * ay;
                        (lo.min(p), hi.max(p))
                    },
                )
            };
            let (a0, a1) = proj(&ca);
            let (b0, b1) = proj(&cb);
            if a1 < b0 || b1 < a0 {
                return false;
            }
        }
    }
    true
}

impl<F: Real> Layout<F> {
    /// Routes per heading: every lane's movements ([`lane_movements`]).
    pub fn routes_per_heading(&self) -> usize {
        (0..self.spec.lanes)
            .map(|l| lane_movements(l, self.spec.lanes).len())
            .sum()
    }

    /// Route index of (inlet heading, lane, movement), if that lane serves that movement:
    /// by heading, then lane, then the lane's movements in [`lane_movements`] order (for
    /// the SPEC §8 layout: 4 per heading, inner straight, inner left, outer straight,
    /// outer right).
    pub fn route_index(&self, heading: u8, lane: u8, movement: Movement) -> Option<usize> {
        let n = self.spec.lanes;
        if heading > 3 || lane >= n {
            return None;
        }
        let before: usize = (0..lane).map(|l| lane_movements(l, n).len()).sum();
        let k = lane_movements(lane, n)
            .iter()
            .position(|&m| m == movement)?;
        Some(usize::from(heading) * self.routes_per_heading() + before + k)
    }

    /// The index of inlet track `t` among all inlets (heading-major, Ψ's order).
    pub fn inlet_index(&self, t: Track) -> usize {
        usize::from(t.heading) * usize::from(self.spec.lanes) + usize::from(t.lane)
    }

    /// Builds and checks a layout.
    pub fn new(p: &Params<F>, spec: LayoutSpec<F>) -> Result<Self, LayoutError<F>> {
        let vals = [
            spec.half_size,
            spec.comm_margin,
            spec.inlet_length,
            spec.outlet_length,
            spec.lane_width,
            spec.v_limit,
        ];
        if !vals.iter().all(|v| v.is_finite() && *v > F::ZERO) {
            return Err(LayoutError::NotPositive);
        }
        let (a, wl) = (spec.half_size, spec.lane_width);
        let n = F::from_usize(usize::from(spec.lanes));
        if !(1..=MAX_LANES).contains(&spec.lanes) || !(n * wl <= a) {
            return Err(LayoutError::LanesDoNotFit);
        }
        let inset = spec.turn_inset;
        if !(inset.is_finite() && inset >= F::ZERO && n * wl <= a - inset) {
            return Err(LayoutError::BadTurnInset);
        }
        let r_right = a - inset - (n - F::HALF) * wl;
        if !(r_right >= p.rho_min()) {
            return Err(LayoutError::TurnTooTight { radius: r_right });
        }
        let needed = safety::d_s(p, spec.v_limit) + spec.v_limit * p.h();
        if !(spec.comm_margin >= needed) {
            return Err(LayoutError::NotSpacious {
                margin: spec.comm_margin,
                needed,
            });
        }
        if !(spec.inlet_length >= spec.comm_margin) {
            return Err(LayoutError::InletShorterThanCommRegion);
        }
        let needed = spec.comm_margin + p.length();
        if !(spec.outlet_length >= needed) {
            return Err(LayoutError::OutletShorterThanCommRegion {
                length: spec.outlet_length,
                needed,
            });
        }
        let (hl, hw) = (F::HALF * p.length(), F::HALF * p.width());
        let mut routes: Vec<Route<F>, MAX_ROUTES> = Vec::new();
        for d in 0..4u8 {
            for lane in 0..spec.lanes {
                for &movement in lane_movements(lane, spec.lanes) {
                    let (path, out_heading) = Self::path_from_west(&spec, lane, movement);
                    let by = sweep_outside(&path, a, wl, (hl, hw));
                    if by > F::ZERO {
                        return Err(LayoutError::SweepLeavesItsLanes {
                            route: routes.len(),
                            by,
                        });
                    }
                    let _ = routes.push(Route {
                        inlet: Track { heading: d, lane },
                        outlet: Track {
                            heading: (d + out_heading) % 4,
                            lane,
                        },
                        movement,
                        path: Path {
                            pieces: path.pieces.map(|s| rotate_segment(s, d)),
                        },
                    });
                }
            }
        }
        let mut layout = Self {
            spec,
            routes,
            conflicts: [0; MAX_ROUTES],
            zone_end: [[F::from_f64(-1.0); MAX_ROUTES]; MAX_ROUTES],
            trails: [0; MAX_ROUTES],
            trail_length: p.length(),
        };
        layout.compute_conflicts(p);
        layout.compute_trails(p);
        Ok(layout)
    }

    /// The path of `movement` from inlet lane `lane` of the approach from the west
    /// (heading east; the other approaches are its rotations), and the outlet's heading
    /// relative to the inlet's. A turn runs straight for the turn inset after the stop
    /// line, turns on the quarter circle of the inner square (half-size a − inset), and
    /// runs straight for the inset again to the edge of A_S; straight on crosses A_S.
    fn path_from_west(spec: &LayoutSpec<F>, lane: u8, movement: Movement) -> (Path<F>, u8) {
        let (a, wl, inset) = (spec.half_size, spec.lane_width, spec.turn_inset);
        let y = -(F::from_usize(usize::from(lane)) + F::HALF) * wl;
        let line = |start: Pose<F>, length: F| Segment::Line { start, length };
        let inlet = line(
            Pose {
                x: -a - spec.inlet_length,
                y,
                theta: F::ZERO,
            },
            spec.inlet_length,
        );
        let at_stop_line = Pose {
            x: -a,
            y,
            theta: F::ZERO,
        };
        let (before, route, out_heading, end, after) = if movement == Movement::Straight {
            let (route, h, end) = Self::turn(a, y, movement);
            (
                line(at_stop_line, F::ZERO),
                route,
                h,
                end,
                line(end, F::ZERO),
            )
        } else {
            // The turn of the inner square, entered after the straight run.
            let (route, h, turned) = Self::turn(a - inset, y, movement);
            let after = line(turned, inset);
            let end = after.pose_at(inset);
            (line(at_stop_line, inset), route, h, end, after)
        };
        let outlet = line(end, spec.outlet_length);
        (
            Path {
                pieces: [inlet, before, route, after, outlet],
            },
            out_heading,
        )
    }

    /// The piece through A_S of a manoeuvre entering at (−a, y) heading east: the piece,
    /// the outlet's heading relative to the inlet's, and the pose where it ends.
    fn turn(a: F, y: F, movement: Movement) -> (Segment<F>, u8, Pose<F>) {
        let half_pi = F::FRAC_PI_2;
        match movement {
            Movement::Straight => (
                Segment::Line {
                    start: Pose {
                        x: -a,
                        y,
                        theta: F::ZERO,
                    },
                    length: F::TWO * a,
                },
                0u8,
                Pose {
                    x: a,
                    y,
                    theta: F::ZERO,
                },
            ),
            Movement::Left => {
                // Quarter circle about (−a, a), radius a − y (a + Wl/2 from the inner lane).
                let r = a - y;
                (
                    Segment::Arc {
                        cx: -a,
                        cy: a,
                        radius: r,
                        start_angle: -half_pi,
                        sweep: half_pi,
                    },
                    1,
                    Pose {
                        x: -a + r,
                        y: a,
                        theta: half_pi,
                    },
                )
            }
            Movement::Right => {
                // Quarter circle about (−a, −a), radius a + y (a − (n − ½) Wl from the outer
                // lane).
                let r = a + y;
                (
                    Segment::Arc {
                        cx: -a,
                        cy: -a,
                        radius: r,
                        start_angle: half_pi,
                        sweep: -half_pi,
                    },
                    3,
                    Pose {
                        x: -a + r,
                        y: -a,
                        theta: -half_pi,
                    },
                )
            }
        }
    }

    /// γ_i ⊗ γ_j from the swept areas (sampled L × W rectangles plus a margin), plus
    /// SPEC's rule: a route conflicts with itself and with routes sharing its inlet or
    /// outlet. Also where, along each route, its conflict zone with each other ends.
    fn compute_conflicts(&mut self, p: &Params<F>) {
        let m = F::from_f64(CONFLICT_MARGIN_M);
        let (hl, hw) = (F::HALF * p.length() + m, F::HALF * p.width() + m);
        let step = F::from_f64(CONFLICT_SAMPLE_M);
        let samples = |r: &Route<F>| {
            let mut out: Vec<(F, Footprint<F>), 256> = Vec::new();
            let (s0, s1) = (r.path.entry(), r.path.exit());
            let mut s = s0;
            while s <= s1 && out.len() < 255 {
                let _ = out.push((s - s0, Footprint::of(r.path.pose_at(s))));
                s += step;
            }
            let _ = out.push((s1 - s0, Footprint::of(r.path.pose_at(s1))));
            out
        };
        let n = self.routes.len();
        for i in 0..n {
            let Some(ri) = self.routes.get(i) else {
                continue;
            };
            let si = samples(ri);
            for j in 0..n {
                let Some(rj) = self.routes.get(j) else {
                    continue;
                };
                let shared = i == j || ri.inlet == rj.inlet || ri.outlet == rj.outlet;
                let sj = samples(rj);
                let mut end: Option<F> = None;
                for &(s, q) in si.iter() {
                    if sj.iter().any(|&(_, b)| footprints_meet(q, b, hl, hw)) {
                        end = Some(s);
                    }
                }
                if shared || end.is_some() {
                    if let Some(c) = self.conflicts.get_mut(i) {
                        *c |= 1 << j;
                    }
                }
                if let (Some(row), Some(e)) = (self.zone_end.get_mut(i), end) {
                    if let Some(z) = row.get_mut(j) {
                        *z = e;
                    }
                }
            }
        }
    }

    /// Which routes may follow which into A_S ([`Layout::trails`]): two routes from one
    /// inlet lane share their path up to the stop line and part from there, so a
    /// follower one invariant spacing (L + d0, centre to centre along the common arc
    /// length) behind its leader may still meet it where the paths part — the chord of
    /// a turn is shorter than its arc and a turning rectangle's corners swing out. The
    /// pair trails if, for every leader position from the A_S entry to one sample past
    /// its conflict zone with the follower's route (where the leader stops blocking that
    /// route, [`Layout::zone_end`]), and every follower position from L + d0 behind it
    /// back 2 (L + W) further (beyond that their centres are too far apart for two
    /// rectangles to meet), the footprints (L × W plus [`CONFLICT_MARGIN_M`] each way)
    /// do not meet, sampled every [`CONFLICT_SAMPLE_M`] as the conflicts are.
    fn compute_trails(&mut self, p: &Params<F>) {
        let m = F::from_f64(CONFLICT_MARGIN_M);
        let (hl, hw) = (F::HALF * p.length() + m, F::HALF * p.width() + m);
        let step = F::from_f64(CONFLICT_SAMPLE_M);
        let gap = p.length() + p.d0();
        let back = F::TWO * (p.length() + p.width());
        let n = self.routes.len();
        for i in 0..n {
            if let Some(t) = self.trails.get_mut(i) {
                *t |= 1 << i;
            }
            for j in 0..n {
                let (Some(ri), Some(rj)) = (self.routes.get(i), self.routes.get(j)) else {
                    continue;
                };
                let zone = self.zone_end.get(i).and_then(|r| r.get(j)).copied();
                let Some(zone) = zone.filter(|_| i != j && ri.inlet == rj.inlet) else {
                    continue;
                };
                // Counted loops, at most TRAIL_SAMPLES each: a pair whose zone or spacing
                // needs more is not checked, so it does not trail.
                let (leaders, followers) = (samples_in(zone + step, step), samples_in(back, step));
                let mut ok = leaders.is_some() && followers.is_some();
                for a in 0..leaders.unwrap_or(0) {
                    let sl = ri.path.entry() + F::from_usize(a) * step;
                    let leader = Footprint::of(ri.path.pose_at(sl));
                    for b in 0..followers.unwrap_or(0) {
                        let sf = sl - gap - F::from_usize(b) * step;
                        ok = ok
                            && !footprints_meet(leader, Footprint::of(rj.path.pose_at(sf)), hl, hw);
                    }
                }
                if ok {
                    if let Some(t) = self.trails.get_mut(i) {
                        *t |= 1 << j;
                    }
                }
            }
        }
    }

    /// `true` if a vehicle on route `j` may follow one on route `i` into A_S
    /// ([`Layout::trails`]).
    pub fn may_trail(&self, i: usize, j: usize) -> bool {
        j < MAX_ROUTES && self.trails.get(i).is_some_and(|t| t >> j & 1 == 1)
    }

    /// `true` if routes i and j conflict.
    pub fn conflict(&self, i: usize, j: usize) -> bool {
        j < MAX_ROUTES && self.conflicts.get(i).is_some_and(|c| c >> j & 1 == 1)
    }

    /// The route with index `i`.
    pub fn route(&self, i: usize) -> Option<&Route<F>> {
        self.routes.get(i)
    }

    /// `true` if `pose` is inside A_C (the square of half-size a + comm_margin).
    pub fn in_comm_region(&self, x: F, y: F) -> bool {
        let r = self.spec.half_size + self.spec.comm_margin;
        x.abs() <= r && y.abs() <= r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec8_layout_conflicts_and_geometry() {
        let p = Params::<f64>::table_i();
        let l = Layout::new(&p, LayoutSpec::spec8(&p)).unwrap();
        let idx = |h, lane, m| l.route_index(h, lane, m).unwrap();
        assert_eq!(l.routes.len(), ROUTES);
        let ws = idx(0, 0, Movement::Straight); // from the west, straight, inner
        let es = idx(2, 0, Movement::Straight); // from the east, straight, inner
        let wl = idx(0, 0, Movement::Left);
        let el = idx(2, 0, Movement::Left);
        let wr = idx(0, 1, Movement::Right);
        let ns = idx(3, 0, Movement::Straight); // from the north, heading south
                                                // Opposite straights and opposite lefts (right-hand traffic) do not meet; crossing
                                                // straights do; a route meets itself and its inlet's other route.
        assert!(!l.conflict(ws, es));
        assert!(!l.conflict(wl, el));
        assert!(l.conflict(ws, ns));
        assert!(l.conflict(ws, ws) && l.conflict(ws, wl));
        assert!(
            l.conflict(wl, es),
            "a left turn crosses the opposing straight"
        );
        // The right turn from the west meets only what shares its lanes or pieces of road.
        assert!(!l.conflict(wr, es));
        for i in 0..ROUTES {
            for j in 0..MAX_ROUTES {
                assert_eq!(l.conflict(i, j), l.conflict(j, i), "symmetric {i} {j}");
            }
        }
        // Path geometry: the left turn from the west ends heading north at (1.8, 12).
        let r = l.route(wl).unwrap();
        let end = r.path.pose_at(r.path.exit());
        assert!((end.x - 1.8).abs() < 1e-9 && (end.y - 12.0).abs() < 1e-9);
        assert!((end.theta - core::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(
            (r.path.exit() - r.path.entry() - 13.8 * core::f64::consts::FRAC_PI_2).abs() < 1e-9
        );
        // The north inlet (heading south) drives on the west half (x = −1.8 inner).
        let n = l.route(ns).unwrap().path.pose_at(50.0);
        assert!((n.x + 1.8).abs() < 1e-9 && n.y > 12.0);
    }

    /// The trails of the SPEC §8 layout: on every approach the inner lane's straight and
    /// left turn trail each other, the outer lane's right turn trails its straight, not
    /// the other way round, and nothing trails across lanes. Re-checked every 5 cm with
    /// the bare rectangles (no margin): no trailing pair meets at the invariant's spacing
    /// or more while the leader is in its zone. And the check bites: with d0 = 0 (a
    /// follower L behind touches with the margin) no two routes trail.
    #[test]
    fn trails_of_the_spec8_layout_and_a_finer_recheck() {
        let p = Params::<f64>::table_i();
        let l = Layout::new(&p, LayoutSpec::spec8(&p)).unwrap();
        let mut pairs = 0;
        for h in 0..4u8 {
            let idx = |lane, m| l.route_index(h, lane, m).unwrap();
            let (s, left) = (idx(0, Movement::Straight), idx(0, Movement::Left));
            let (os, or) = (idx(1, Movement::Straight), idx(1, Movement::Right));
            assert!(l.may_trail(s, left) && l.may_trail(left, s));
            assert!(l.may_trail(os, or) && !l.may_trail(or, os));
            for (i, j) in [(s, os), (os, s), (left, or), (or, left)] {
                assert!(!l.may_trail(i, j), "across lanes {i} {j}");
            }
        }
        let (hl, hw) = (0.5 * p.length(), 0.5 * p.width());
        for i in 0..ROUTES {
            for j in 0..ROUTES {
                if i == j || !l.may_trail(i, j) {
                    continue;
                }
                pairs += 1;
                let (ri, rj) = (l.route(i).unwrap(), l.route(j).unwrap());
                let last = l.zone_end[i][j] + CONFLICT_SAMPLE_M;
                for a in 0..=((last / 0.05) as usize) {
                    let sl = ri.path.entry() + a as f64 * 0.05;
                    for b in 0..=((2.0 * (p.length() + p.width()) / 0.05) as usize) {
                        let sf = sl - p.length() - p.d0() - b as f64 * 0.05;
                        assert!(
                            !rectangles_meet(ri.path.pose_at(sl), rj.path.pose_at(sf), hl, hw),
                            "{i} -> {j}: leader at {sl}, follower at {sf}"
                        );
                    }
                }
            }
        }
        assert_eq!(pairs, 12, "3 pairs on each of 4 approaches");
        let mut tight = *p.spec();
        tight.d0 = 0.0;
        let pt = Params::new(tight).unwrap();
        let l = Layout::new(&pt, LayoutSpec::spec8(&pt)).unwrap();
        for i in 0..ROUTES {
            for j in 0..ROUTES {
                assert_eq!(l.may_trail(i, j), i == j, "d0 = 0: {i} -> {j}");
            }
        }
    }

    /// SPEC §10: three lanes per approach: inner straight + left, middle straight,
    /// outer straight + right; 20 routes; the right turn from the outer lane has radius
    /// a − 2.5 Wl, so a must be at least 2.5 Wl + ρmin.
    #[test]
    fn three_lane_layout() {
        let p = Params::<f64>::table_i();
        let mut spec = LayoutSpec::spec8(&p);
        spec.lanes = 3;
        assert!(matches!(
            Layout::new(&p, spec),
            Err(LayoutError::TurnTooTight { .. })
        ));
        spec.half_size = 15.0;
        let l = Layout::new(&p, spec).unwrap();
        assert_eq!((l.routes_per_heading(), l.routes.len()), (5, 20));
        assert_eq!(l.route_index(1, 1, Movement::Left), None);
        assert_eq!(l.route_index(1, 2, Movement::Left), None);
        let mid = l.route_index(1, 1, Movement::Straight).unwrap();
        assert_eq!(mid, 5 + 2);
        let r = l.route(mid).unwrap();
        assert_eq!(
            (r.inlet, r.outlet),
            (
                Track {
                    heading: 1,
                    lane: 1
                },
                Track {
                    heading: 1,
                    lane: 1
                }
            )
        );
        let right = l.route_index(0, 2, Movement::Right).unwrap();
        let rr = l.route(right).unwrap();
        assert!(
            (rr.path.exit() - rr.path.entry() - (15.0 - 2.5 * 3.6) * core::f64::consts::FRAC_PI_2)
                .abs()
                < 1e-9
        );
        assert_eq!(l.inlet_index(rr.inlet), 2);
        for i in 0..20 {
            assert!(l.conflict(i, i));
        }
    }

    #[test]
    fn layouts_that_break_assumptions_are_rejected() {
        let p = Params::<f64>::table_i();
        let mut s = LayoutSpec::spec8(&p);
        s.comm_margin = 10.0;
        assert!(matches!(
            Layout::new(&p, s),
            Err(LayoutError::NotSpacious { .. })
        ));
        let mut s = LayoutSpec::spec8(&p);
        s.half_size = 10.0;
        assert!(matches!(
            Layout::new(&p, s),
            Err(LayoutError::TurnTooTight { .. })
        ));
        let mut s = LayoutSpec::spec8(&p);
        s.half_size = f64::NAN;
        assert_eq!(Layout::new(&p, s), Err(LayoutError::NotPositive));
        let mut s = LayoutSpec::spec8(&p);
        s.inlet_length = 30.0;
        assert_eq!(
            Layout::new(&p, s),
            Err(LayoutError::InletShorterThanCommRegion)
        );
        let mut s = LayoutSpec::spec8(&p);
        s.outlet_length = 54.4;
        assert!(matches!(
            Layout::new(&p, s),
            Err(LayoutError::OutletShorterThanCommRegion { needed, .. }) if (needed - 54.5).abs() < 1e-12
        ));
        s.outlet_length = 54.5;
        assert!(Layout::new(&p, s).is_ok());
    }

    fn truck() -> Params<f64> {
        let spec = crate::ParamsSpec {
            length: 16.5,
            a_min: -4.5,
            ..crate::ParamsSpec::table_i()
        };
        Params::new(spec).expect("a truck's parameters are valid")
    }

    /// SPEC §8's right turn (6.6 m radius) swings a 16.5 m rectangle's rear into the next
    /// inlet lane; A_S 8 m larger all round, around the same turns, keeps it inside.
    #[test]
    fn a_truck_needs_room_around_the_turns_a_car_does_not() {
        let car = Params::<f64>::table_i();
        assert!(Layout::new(&car, LayoutSpec::spec8(&car)).is_ok());
        let t = truck();
        let mut s = LayoutSpec::spec8(&t);
        s.outlet_length = 70.0;
        // The first route refused is the left turn from the inner lane (route 1, radius
        // 13.8 m): its rear swings √(13.8² + 8.25²) − 13.8 = 2.28 m out, to the right, and
        // its corner 1.17 m past the outer inlet lane's edge (the right turn's 4 m swing
        // comes later, route 3).
        let Err(LayoutError::SweepLeavesItsLanes { route, by }) = Layout::new(&t, s) else {
            panic!("refused");
        };
        assert_eq!(route, 1);
        assert!((by - 1.170_771_665).abs() < 1e-6, "{by}");
        s.half_size = 20.0;
        s.turn_inset = 8.0;
        let l = Layout::new(&t, s).expect("room for the swing");
        let right = l
            .route(l.route_index(0, 1, Movement::Right).expect("right"))
            .expect("r");
        let Segment::Arc { radius, .. } = right.path.pieces[2] else {
            panic!("a right turn turns");
        };
        assert!((radius - 6.6).abs() < 1e-12, "SPEC §8's turn: {radius}");
        // Straight 8 m from the stop line, then the turn; the path reaches the outlet at
        // A_S's edge.
        let entry = right.path.pose_at(right.path.entry());
        let turn = right.path.pose_at(right.path.entry() + 8.0);
        let out = right.path.pose_at(right.path.exit());
        assert!((entry.x + 20.0).abs() < 1e-9 && (turn.x + 12.0).abs() < 1e-9);
        assert!((out.y + 20.0).abs() < 1e-9, "{out:?}");
        // Its whole length: the inlet, 8 m, the quarter circle, 8 m, the outlet.
        let quarter = 6.6 * core::f64::consts::FRAC_PI_2;
        let whole = 100.0 + 8.0 + quarter + 8.0 + 70.0;
        assert!(
            (right.path.length() - whole).abs() < 1e-9,
            "{}",
            right.path.length()
        );
        assert!((right.path.exit() - (whole - 70.0)).abs() < 1e-9);
        // The same box without the inset turns too tightly for the truck's swing.
        s.turn_inset = 0.0;
        assert!(matches!(
            Layout::new(&t, s),
            Err(LayoutError::SweepLeavesItsLanes { .. })
        ));
    }

    /// Distances outside A_S and the lane strips, at points whose answers are known: in
    /// the inlet lane behind the line, in its band's extension beyond A_S (outside: the
    /// strip ends at the line), in the next lane, inside A_S, in an oblique outlet lane.
    #[test]
    fn points_outside_a_s_and_the_lanes_are_measured() {
        let east = |x: f64, y: f64, theta: f64| Footprint::of(Pose { x, y, theta });
        let lanes = (
            east(-12.0, -1.8, 0.0),
            east(-1.8, -12.0, -core::f64::consts::FRAC_PI_2),
        );
        let at = |x, y| outside_lanes((x, y), 12.0, 3.6, lanes);
        let close = |got: f64, want: f64| (got - want).abs() < 1e-12;
        assert!(close(at(-22.0, -1.8), -1.8), "{}", at(-22.0, -1.8));
        assert!(close(at(-22.0, -3.0), -0.6));
        assert!(
            close(at(-22.0, -5.4), 1.8),
            "the next lane: {}",
            at(-22.0, -5.4)
        );
        assert!(
            close(at(22.0, -1.8), 10.0),
            "beyond A_S: {}",
            at(22.0, -1.8)
        );
        assert!(close(at(0.0, 0.0), -12.0), "inside A_S");
        assert!(close(at(-1.8, -20.0), -1.8), "in the outlet lane");
        assert!(
            close(at(-1.8, 20.0), 8.0),
            "behind the outlet's start: {}",
            at(-1.8, 20.0)
        );
        // An oblique lane (θ = 0.3): across its centre line by 2 m.
        let oblique = (east(-12.0, -1.8, 0.3), east(-12.0, -1.8, 0.3));
        let (s, c) = 0.3f64.sin_cos();
        let p = (-12.0 - 5.0 * c - 2.0 * s, -1.8 - 5.0 * s + 2.0 * c);
        let got = outside_lanes(p, 12.0, 3.6, oblique);
        assert!(close(got, 0.2), "{got}");
    }

    /// Each refusal says what is wrong, in the words of its documentation.
    #[test]
    fn refusals_say_why() {
        use core::fmt::Write;
        let text = |e: LayoutError<f64>| {
            let mut s: heapless::String<512> = heapless::String::new();
            write!(s, "{e}").expect("fits");
            s
        };
        let sweep = text(LayoutError::SweepLeavesItsLanes { route: 3, by: 4.0 });
        assert!(
            sweep.starts_with("a vehicle of the layout's length and width"),
            "{sweep}"
        );
        assert!(
            sweep.contains("route: 3") && sweep.contains("by: 4.0"),
            "{sweep}"
        );
        let inset = text(LayoutError::BadTurnInset);
        assert!(inset.starts_with("the turn inset is negative"), "{inset}");
    }

    #[test]
    fn a_turn_inset_must_leave_the_lanes_room() {
        let p = Params::<f64>::table_i();
        for inset in [-0.5, f64::NAN, f64::INFINITY, 4.9] {
            let mut s = LayoutSpec::spec8(&p);
            s.turn_inset = inset;
            assert_eq!(
                Layout::new(&p, s),
                Err(LayoutError::BadTurnInset),
                "{inset}"
            );
        }
    }
}
