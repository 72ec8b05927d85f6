//! `--precision f32`: every vehicle's planners and every junction's manager in `f32`, as
//! on the microcontroller, behind the `f64` interface the rest of the world speaks.
//!
//! The world's ground truth, its monitors and its bus stay in `f64`; what a planner is
//! given is rounded to `f32` on the way in (as an MCU's sensors and codec would deliver
//! it) and what it answers is widened back exactly. A junction's layout is the `f64`
//! layout's numbers rounded to `f32` with its conflict table as computed (what an MCU
//! would be flashed with). On a CAN bus the codec runs in `f32` too
//! ([`crate::fleet::can::CanNode::with_precision`]).

use planner_core::crossing::{CrossingPlanner, CrossingReport, Manager, ManagerError, PathVehicle};
use planner_core::intersection::{Layout, LayoutSpec, Path, Route, Segment};
use planner_core::lane_change::StartBlock;
use planner_core::{
    Command, InputError, Instant, LaneCommand, LaneInputError, LaneObservation, LanePlanner, Other,
    Pose, Road, Sensing, StepStatus,
};
use serde::{Deserialize, Serialize};

/// Horizon of the crossing planners (both precisions).
pub const CROSS_HORIZON: usize = 20;

/// The precision of the planners, the managers and the codec.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// `f64`, as on a host.
    #[default]
    F64,
    /// `f32`, as on the Cortex-M4F.
    F32,
}

impl Precision {
    /// Its name on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F64 => "f64",
            Precision::F32 => "f32",
        }
    }
}

/// A vehicle on the path in `f32`.
fn path_vehicle32(v: &PathVehicle<f64>) -> PathVehicle<f32> {
    PathVehicle {
        s: r(v.s),
        length: r(v.length),
    }
}

/// `x` rounded to `f32`.
fn r(x: f64) -> f32 {
    x as f32
}

/// `x` widened to `f64` (exact).
fn w(x: f32) -> f64 {
    f64::from(x)
}

fn pose32(p: Pose<f64>) -> Pose<f32> {
    Pose {
        x: r(p.x),
        y: r(p.y),
        theta: r(p.theta),
    }
}

fn segment32(s: Segment<f64>) -> Segment<f32> {
    match s {
        Segment::Line { start, length } => Segment::Line {
            start: pose32(start),
            length: r(length),
        },
        Segment::Arc {
            cx,
            cy,
            radius,
            start_angle,
            sweep,
        } => Segment::Arc {
            cx: r(cx),
            cy: r(cy),
            radius: r(radius),
            start_angle: r(start_angle),
            sweep: r(sweep),
        },
    }
}

/// `l` with every length, position and angle rounded to `f32`; the routes' conflicts as
/// `l` has them.
pub fn layout32(l: &Layout<f64>) -> Layout<f32> {
    let s = l.spec;
    let mut routes = heapless::Vec::new();
    for route in &l.routes {
        let _ = routes.push(Route {
            inlet: route.inlet,
            outlet: route.outlet,
            movement: route.movement,
            path: Path {
                pieces: route.path.pieces.map(segment32),
            },
        });
    }
    Layout {
        spec: LayoutSpec {
            half_size: r(s.half_size),
            comm_margin: r(s.comm_margin),
            inlet_length: r(s.inlet_length),
            outlet_length: r(s.outlet_length),
            lane_width: r(s.lane_width),
            v_limit: r(s.v_limit),
            lanes: s.lanes,
            turn_inset: r(s.turn_inset),
        },
        routes,
        conflicts: l.conflicts,
        zone_end: l.zone_end.map(|row| row.map(r)),
        trails: l.trails,
        trail_length: r(l.trail_length),
    }
}

/// The f32 planners' parameters: Table I with `v_max` and `body`'s length and limit.
pub fn params32(v_max: f64, body: super::Body) -> planner_core::Params<f32> {
    let spec = planner_core::ParamsSpec {
        v_max: r(v_max),
        length: r(body.length),
        a_min: -r(body.brake),
        ..planner_core::ParamsSpec::table_i()
    };
    planner_core::Params::new(spec).unwrap_or_else(|_| planner_core::Params::table_i())
}

/// Sensors in `f32`.
pub fn sensing32(s: Sensing<f64>) -> Sensing<f32> {
    Sensing {
        ahead_m: r(s.ahead_m),
        behind_m: r(s.behind_m),
        position_error_m: r(s.position_error_m),
        speed_error_mps: r(s.speed_error_mps),
    }
}

fn other32(o: &Other<f64>) -> Other<f32> {
    Other {
        x: r(o.x),
        v: r(o.v),
        length: r(o.length),
        age: r(o.age),
        id: o.id,
        lane: o.lane,
        alpha: o.alpha,
        beta: o.beta,
        cooperative: o.cooperative,
        brake: o.brake,
        sensed: o.sensed,
    }
}

/// A step's status widened to `f64`.
pub fn status64(s: StepStatus<f32>) -> StepStatus<f64> {
    s.map(w)
}

/// The observation in `f32`, its others written into `buf`.
fn observation32<'a>(
    o: &LaneObservation<'_, f64>,
    buf: &'a mut heapless::Vec<Other<f32>, { super::heard::VIEW_CAP }>,
) -> LaneObservation<'a, f32> {
    buf.clear();
    for x in o.others {
        // `buf` holds as many as a view.
        let _ = buf.push(other32(x));
    }
    LaneObservation {
        pose: pose32(o.pose),
        v_prev: r(o.v_prev),
        omega_prev: r(o.omega_prev),
        others: buf,
        road: Road {
            lanes: o.road.lanes,
            lane_width: r(o.road.lane_width),
            end_x: o.road.end_x.map(r),
        },
        target_lane: o.target_lane,
        target: r(o.target),
        v_ref: r(o.v_ref),
    }
}

/// A multi-lane planner in `f32` behind an `f64` interface.
pub struct LaneF32<const N: usize> {
    planner: LanePlanner<f32, N>,
    buf: Box<heapless::Vec<Other<f32>, { super::heard::VIEW_CAP }>>,
}

impl<const N: usize> LaneF32<N> {
    /// Wraps `planner`.
    pub fn new(planner: LanePlanner<f32, N>) -> Self {
        Self {
            planner,
            buf: Box::new(heapless::Vec::new()),
        }
    }

    /// One step on `obs`, rounded to `f32`; the command widened back.
    pub fn step(
        &mut self,
        obs: &LaneObservation<'_, f64>,
    ) -> Result<LaneCommand<f64>, LaneInputError> {
        let o = observation32(obs, &mut self.buf);
        let c = self.planner.step(&o)?;
        Ok(LaneCommand {
            v: w(c.v),
            omega: w(c.omega),
            status: status64(c.status),
            lane: c.lane,
            alpha: c.alpha,
            beta: c.beta,
            event: c.event,
            gap: w(c.gap),
            lateral_iterations: c.lateral_iterations,
        })
    }

    /// The intended lane β.
    pub fn beta(&self) -> Option<u8> {
        self.planner.beta()
    }

    /// Whether a change into `m` may start on `obs`.
    pub fn start_check(&mut self, obs: &LaneObservation<'_, f64>, m: u8) -> Result<(), StartBlock> {
        let o = observation32(obs, &mut self.buf);
        self.planner.start_check(&o, m)
    }

    /// The certified fallback's command.
    pub fn braking_command(&self, theta: f64, v_prev: f64) -> (f64, f64) {
        let (v, om) = self.planner.braking_command(r(theta), r(v_prev));
        (w(v), w(om))
    }
}

/// A crossing planner in `f32` (with its junction's layout in `f32`) behind an `f64`
/// interface.
pub struct CrossingF32 {
    planner: CrossingPlanner<f32, CROSS_HORIZON, { super::heard::VIEW_CAP }>,
    layout: Box<Layout<f32>>,
    buf: Vec<PathVehicle<f32>>,
}

impl CrossingF32 {
    /// Wraps `planner`, which plans on `layout` rounded to `f32`.
    pub fn new(
        planner: CrossingPlanner<f32, CROSS_HORIZON, { super::heard::VIEW_CAP }>,
        layout: &Layout<f64>,
    ) -> Self {
        Self {
            planner,
            layout: Box::new(layout32(layout)),
            buf: Vec::new(),
        }
    }

    /// Forgets every report.
    pub fn clear_reports(&mut self) {
        self.planner.clear_reports();
    }

    /// Takes a report stamped `stamp`.
    pub fn hear_report(
        &mut self,
        rep: &CrossingReport<f64>,
        stamp: Instant,
    ) -> Result<(), ManagerError> {
        self.planner.hear_report(&report32(rep), stamp)
    }

    /// This step's sensor returns along its path.
    pub fn hear_sensed(&mut self, vs: &[PathVehicle<f64>]) -> Result<(), ManagerError> {
        self.buf.clear();
        self.buf.extend(vs.iter().map(path_vehicle32));
        self.planner.hear_sensed(&self.buf)
    }

    /// This step's vehicles heard of in other frames, along its path.
    pub fn hear_mapped(&mut self, vs: &[PathVehicle<f64>]) -> Result<(), ManagerError> {
        self.buf.clear();
        self.buf.extend(vs.iter().map(path_vehicle32));
        self.planner.hear_mapped(&self.buf)
    }

    /// A lease heard.
    pub fn hear_grant(&mut self, id: u16, until: Instant) {
        self.planner.hear_grant(id, until);
    }

    /// Whether it may be in A_S at `now` at path position `s`.
    pub fn permitted(&self, s: f64, now: Instant) -> bool {
        self.planner.permitted(&self.layout, r(s), now)
    }

    /// One step at path position `s`, v_{t−h} = `v_prev`; the command widened back.
    pub fn step(&mut self, s: f64, v_prev: f64, now: Instant) -> Result<Command<f64>, InputError> {
        let c = self.planner.step(&self.layout, r(s), r(v_prev), now)?;
        Ok(Command {
            v: w(c.v),
            status: status64(c.status),
            gap: w(c.gap),
        })
    }
}

/// A report in `f32`.
pub fn report32(rep: &CrossingReport<f64>) -> CrossingReport<f32> {
    CrossingReport {
        id: rep.id,
        route: rep.route,
        s: r(rep.s),
        v: r(rep.v),
        length: r(rep.length),
        brake: rep.brake,
    }
}

/// (id, route) of the entries that hold their zones.
fn holders_of<F>(entries: &[planner_core::crossing::Entry<F>]) -> Vec<(u16, u8)> {
    entries
        .iter()
        .filter(|e| e.holds())
        .map(|e| (e.id, e.route))
        .collect()
}

/// The ids of the entries permitted.
fn granted_of<F>(entries: &[planner_core::crossing::Entry<F>]) -> Vec<u16> {
    entries
        .iter()
        .filter(|e| e.permitted)
        .map(|e| e.id)
        .collect()
}

/// A junction's manager in either precision.
#[derive(Debug, Clone)]
pub enum AnyManager<const CAP: usize> {
    /// In `f64`.
    F64(Box<Manager<f64, CAP>>),
    /// In `f32`, on the layout rounded to `f32`.
    F32(Box<Manager<f32, CAP>>),
}

impl<const CAP: usize> AnyManager<CAP> {
    /// A manager for `layout` running `algorithm` in `precision`.
    pub fn new(
        layout: &Layout<f64>,
        algorithm: planner_core::crossing::Algorithm,
        precision: Precision,
    ) -> Self {
        match precision {
            Precision::F64 => Self::F64(Box::new(Manager::new(layout.clone(), algorithm))),
            Precision::F32 => Self::F32(Box::new(Manager::new(layout32(layout), algorithm))),
        }
    }

    /// See planner-core's `Manager::set_position_resolution` and `set_speed_resolution`.
    pub fn set_resolution(
        &mut self,
        (position, speed): (f64, f64),
    ) -> Result<(), planner_core::ConfigError> {
        match self {
            Self::F64(m) => m
                .set_position_resolution(position)
                .and(m.set_speed_resolution(speed)),
            Self::F32(m) => m
                .set_position_resolution(r(position))
                .and(m.set_speed_resolution(r(speed))),
        }
    }

    /// See planner-core's `Manager::set_lease`.
    pub fn set_lease(
        &mut self,
        lease: planner_core::crossing::Lease,
    ) -> Result<(), planner_core::ConfigError> {
        match self {
            Self::F64(m) => m.set_lease(lease),
            Self::F32(m) => m.set_lease(lease),
        }
    }

    /// See planner-core's `Manager::set_roadside_sensor`.
    pub fn set_roadside_sensor(
        &mut self,
        error: Option<f64>,
    ) -> Result<(), planner_core::ConfigError> {
        match self {
            Self::F64(m) => m.set_roadside_sensor(error),
            Self::F32(m) => m.set_roadside_sensor(error.map(r)),
        }
    }

    /// See planner-core's `Manager::measure`.
    pub fn measure(&mut self, id: u16, s: f64) -> Result<(), ManagerError> {
        match self {
            Self::F64(m) => m.measure(id, s),
            Self::F32(m) => m.measure(id, r(s)),
        }
    }

    /// Its lease terms.
    pub fn lease(&self) -> planner_core::crossing::Lease {
        match self {
            Self::F64(m) => m.lease(),
            Self::F32(m) => m.lease(),
        }
    }

    /// Its algorithm.
    pub fn algorithm(&self) -> planner_core::crossing::Algorithm {
        match self {
            Self::F64(m) => m.algorithm(),
            Self::F32(m) => m.algorithm(),
        }
    }

    /// Its precision.
    pub fn precision(&self) -> Precision {
        match self {
            Self::F64(_) => Precision::F64,
            Self::F32(_) => Precision::F32,
        }
    }

    /// Takes a report heard at `now`.
    pub fn observe(&mut self, rep: &CrossingReport<f64>, now: Instant) -> Result<(), ManagerError> {
        match self {
            Self::F64(m) => m.observe(rep, now),
            Self::F32(m) => m.observe(&report32(rep), now),
        }
    }

    /// Forgets vehicle `id`.
    pub fn forget(&mut self, id: u16) {
        match self {
            Self::F64(m) => m.forget(id),
            Self::F32(m) => m.forget(id),
        }
    }

    /// Decides at `now`.
    pub fn update(&mut self, now: Instant) {
        match self {
            Self::F64(m) => m.update(now),
            Self::F32(m) => m.update(now),
        }
    }

    /// The vehicles holding their routes' conflict zones (permitted, or committed), with
    /// their routes, in its order.
    pub fn holders(&self) -> Vec<(u16, u8)> {
        match self {
            Self::F64(m) => holders_of(m.entries()),
            Self::F32(m) => holders_of(m.entries()),
        }
    }

    /// The vehicles it grants a permission: each is sent a lease.
    pub fn granted(&self) -> Vec<u16> {
        match self {
            Self::F64(m) => granted_of(m.entries()),
            Self::F32(m) => granted_of(m.entries()),
        }
    }

    /// The end of a lease sent at `now`.
    pub fn lease_until(&self, now: Instant) -> Instant {
        match self {
            Self::F64(m) => m.lease_until(now),
            Self::F32(m) => m.lease_until(now),
        }
    }
}
