//! The firmware's two scenarios, written once and compiled both into the firmware and,
//! unchanged, into the host mirror (`cargo run -p workspace-tests --example
//! firmware_mirror`), so that CI can check that the Cortex-M4F plans exactly what the
//! host plans in the same precision from the same inputs, step for step.
//!
//! Each scenario is a control loop: read the neighbours' CAN frames, run the planner,
//! hand the command to `emit`. `now` reads a monotonic tick counter (SysTick on the MCU,
//! nothing on the host); `emit` applies the command and, on the MCU, waits out the rest of
//! the 10 ms period (embedded-hal `DelayNs`), so the loop runs at h.

use can_gateway::wire::{POS_RES, SPEED_RES};
use can_gateway::{encode, Frames, Message, PlainFrame, Reassembler};
use embedded_can::{nb::Can, ErrorKind};
use planner_core::planner::Vehicle;
use planner_core::{
    BodyLength, BrakeLimit, Duration, FallbackReason, Instant, LaneEvent, LaneObservation,
    LanePlanner, Observation, Other, Planner, Pose, Road, StepStatus, VehicleState, WorldView,
};

/// What the firmware's clock reads at power-up: 60 days of uptime, so that every run
/// shows that stamps, ages and the wire's wrapping milliseconds do not depend on how
/// long the vehicle has been on (`planner_core::time`).
pub const CLOCK_START: Instant = Instant::from_secs(60 * 86_400);

/// This vehicle's id (and CAN source address).
pub const EGO: u16 = 2;
/// Where the single-lane planner's stop line lies during the lane change (m).
pub const STOP_LINE_X: f32 = 400.0;

/// Steps of the approach.
pub const APPROACH_STEPS: u32 = 1000;
/// Most steps the lane change may take.
pub const LANE_CHANGE_STEPS: u32 = 1000;

/// One planned step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepRecord {
    /// 'A' (approach), 'L' (lane change) or 'S' (the single-lane planner's command in a
    /// lane-change period: planned, not applied; it does not end the period).
    pub scenario: char,
    /// Step index.
    pub k: u32,
    /// Commanded speed.
    pub v: f32,
    /// Commanded yaw rate.
    pub omega: f32,
    /// Ticks of the tick counter spent in the planner's `step`.
    pub ticks: u32,
    /// Whether this step counts in the instruction statistics: the approach's solving
    /// steps (standstill steps skip the solver), the lane change's steps under way.
    pub timed: bool,
    /// Position after the step (x for the approach, y for the lane change).
    pub position: f32,
    /// What the planner reported (`None`: it rejected the input and max braking was applied).
    pub status: Option<StepStatus<f32>>,
    /// The lane-change event of this step, if any.
    pub event: Option<LaneEvent>,
}

/// What the approach ended with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Approach {
    /// Final x.
    pub x: f32,
    /// Final v.
    pub v: f32,
    /// Solved steps.
    pub solved: u32,
    /// Standstill steps.
    pub standstill: u32,
    /// Fallback steps.
    pub fallbacks: u32,
    /// CAN frames received.
    pub frames: u32,
    /// Frames or messages rejected.
    pub rejected: u32,
}

/// What the lane change ended with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaneChange {
    /// Step at which the change completed.
    pub completed_at: Option<u32>,
    /// Final y.
    pub y: f32,
    /// Steps that did not solve.
    pub fallbacks: u32,
    /// Steps with the change under way.
    pub changing: u32,
    /// Steps of the single-lane planner, planned beside the lane planner, that did not
    /// solve.
    pub single_fallbacks: u32,
}

/// A CAN controller in loopback mode, as drivers offer for self-test: every frame it
/// transmits arrives in its own receive FIFO (32 frames deep).
pub struct LoopbackCan {
    fifo: heapless::Deque<PlainFrame, 32>,
}

impl Can for LoopbackCan {
    type Frame = PlainFrame;
    type Error = ErrorKind;

    fn transmit(&mut self, frame: &PlainFrame) -> nb::Result<Option<PlainFrame>, ErrorKind> {
        self.fifo
            .push_back(*frame)
            .map_err(|_| nb::Error::WouldBlock)?;
        Ok(None)
    }

    fn receive(&mut self) -> nb::Result<PlainFrame, ErrorKind> {
        self.fifo.pop_front().ok_or(nb::Error::WouldBlock)
    }
}

/// The node's CAN side and what its planners read from it, all `const`, so that a
/// `static` holds it (on the MCU in `.bss`, off the stack): the controller, the
/// reassembler, the world view and the planners' neighbour buffers.
pub struct Node {
    can: LoopbackCan,
    rx: Reassembler<4>,
    view: WorldView<f32, 4>,
    others: heapless::Vec<Other<f32>, 4>,
    ahead: heapless::Vec<Vehicle<f32>, 4>,
    /// CAN frames received.
    pub frames: u32,
    /// Frames or messages rejected.
    pub rejected: u32,
}

impl Node {
    /// A node for vehicle [`EGO`] that has heard nothing.
    pub const fn new() -> Self {
        Self {
            can: LoopbackCan {
                fifo: heapless::Deque::new(),
            },
            rx: Reassembler::new(),
            view: WorldView::new(EGO),
            others: heapless::Vec::new(),
            ahead: heapless::Vec::new(),
            frames: 0,
            rejected: 0,
        }
    }

    /// Forgets everything heard (between scenarios).
    pub fn clear(&mut self) {
        self.rx = Reassembler::new();
        self.view = WorldView::new(EGO);
        (self.frames, self.rejected) = (0, 0);
    }

    /// One period of the bus: each of `states` goes out as frames (looped back by the
    /// controller) and what comes in is reassembled into the view at `now`.
    fn exchange(&mut self, states: &[VehicleState<f32>], counter: u8, now: Instant) -> Option<()> {
        for st in states {
            let frames: Frames<PlainFrame> =
                encode(&Message::State(*st), st.id as u8, counter).ok()?;
            for f in &frames {
                self.can.transmit(f).ok()?;
            }
            while let Ok(f) = self.can.receive() {
                self.frames += 1;
                match self.rx.push::<f32, _>(&f, now) {
                    Ok(Some(Message::State(s))) => {
                        if self.view.update(&s, now).is_err() {
                            self.rejected += 1;
                        }
                    }
                    Ok(_) => {}
                    Err(_) => self.rejected += 1,
                }
            }
        }
        Some(())
    }
}

impl Default for Node {
    fn default() -> Self {
        Self::new()
    }
}

/// The planners' allowance for the wire's rounding (can-gateway's 0.01 m, 0.02 m/s).
pub const RESOLUTION: (f32, f32) = (POS_RES as f32, SPEED_RES as f32);

/// (1) A stopped car (id 1) 60 m ahead broadcasts its state every period over CAN; the
/// ego ([`EGO`]) starts at 15 m/s and knows it only from the frames its node receives.
/// Both clocks read `start` at the first period.
#[inline(never)]
pub fn approach<const N: usize>(
    planner: &mut Planner<f32, N>,
    node: &mut Node,
    start: Instant,
    now: &mut impl FnMut() -> u32,
    emit: &mut impl FnMut(&StepRecord),
) -> Option<Approach> {
    let params = *planner.params();
    planner
        .set_bus_resolution(RESOLUTION.0, RESOLUTION.1)
        .ok()?;
    // A period has a deadline: after a fallback, solve cold (Planner::set_warm_from_fallback).
    planner.set_warm_from_fallback(false);
    node.clear();
    let mut out = Approach {
        x: 0.0,
        v: 15.0,
        solved: 0,
        standstill: 0,
        fallbacks: 0,
        frames: 0,
        rejected: 0,
    };
    for step in 0..APPROACH_STEPS {
        let t = start.saturating_add(Duration::from_millis(10 * u64::from(step)));
        let leader = VehicleState {
            id: 1,
            x: 60.0f32,
            y: 1.8,
            theta: 0.0,
            v: 0.0,
            omega: 0.0,
            lane: 0,
            alpha: None,
            beta: None,
            stamp: t,
            // A stopped car: whatever drives it, it is not a planner that yields.
            cooperative: false,
            brake: None,
            length: None,
        };
        node.exchange(&[leader], (step % 16) as u8, t)?;
        node.view.lane_vehicles(0, 4.5, &mut node.ahead);
        let obs = Observation {
            x: out.x,
            v_prev: out.v,
            vehicles: &node.ahead,
            stop_line: None,
            target_x: 0.0,
            v_ref: params.v_max(),
        };
        let t0 = now();
        let result = planner.step(&obs);
        let ticks = now().wrapping_sub(t0);
        let mut solved = false;
        let status = result.as_ref().ok().map(|c| c.status);
        match result {
            Ok(cmd) => {
                match cmd.status {
                    StepStatus::Solved { .. } => {
                        out.solved += 1;
                        solved = true;
                    }
                    // The firmware's planners set no reuse policy: they solve every step.
                    StepStatus::Reused { .. } => out.solved += 1,
                    StepStatus::Fallback(FallbackReason::NoRoom) => out.standstill += 1,
                    // A fallback, or a status this firmware does not know: not a solve.
                    _ => out.fallbacks += 1,
                }
                out.v = cmd.v;
            }
            Err(_) => out.v = planner_core::safety::max_braking_command(&params, out.v),
        }
        out.x += out.v * params.h();
        emit(&StepRecord {
            scenario: 'A',
            k: step,
            v: out.v,
            omega: 0.0,
            ticks,
            timed: solved,
            position: out.x,
            status,
            event: None,
        });
    }
    (out.frames, out.rejected) = (node.frames, node.rejected);
    Some(out)
}

/// (2) A lane change from lane 0 to lane 1 at 15 m/s on a two-lane road, a car (id 3)
/// 40 m ahead in lane 1 at 15 m/s that the ego knows only from its CAN frames. Each
/// period runs both planners, as a vehicle nearing an intersection does: the lane
/// planner drives; the single-lane planner plans toward a stop line [`STOP_LINE_X`] on
/// in the ego's lane, kept warm for the handover — its command is recorded ('S'), not
/// applied.
#[inline(never)]
pub fn lane_change<const N: usize>(
    lp: &mut LanePlanner<f32, N>,
    single: &mut Planner<f32, N>,
    node: &mut Node,
    start: Instant,
    now: &mut impl FnMut() -> u32,
    emit: &mut impl FnMut(&StepRecord),
) -> Option<LaneChange> {
    let params = *lp.params();
    lp.set_bus_resolution(RESOLUTION.0, RESOLUTION.1).ok()?;
    single.set_bus_resolution(RESOLUTION.0, RESOLUTION.1).ok()?;
    lp.set_warm_from_fallback(false);
    single.set_warm_from_fallback(false);
    // A new road: the single-lane planner starts cold, as after a handover.
    single.reset();
    node.clear();
    let road = Road {
        lanes: 2,
        lane_width: 3.6,
        end_x: None,
    };
    let (mut q, mut v, mut w) = (
        Pose {
            x: 0.0f32,
            y: 1.8,
            theta: 0.0,
        },
        15.0f32,
        0.0f32,
    );
    let mut out = LaneChange {
        completed_at: None,
        y: q.y,
        fallbacks: 0,
        changing: 0,
        single_fallbacks: 0,
    };
    for step in 0..LANE_CHANGE_STEPS {
        let t = start.saturating_add(Duration::from_millis(10 * u64::from(step)));
        let car = VehicleState {
            id: 3,
            x: 40.0 + 15.0 * 0.01 * step as f32,
            y: 5.4,
            theta: 0.0,
            v: 15.0,
            omega: 0.0,
            lane: 1,
            alpha: None,
            beta: None,
            stamp: t,
            cooperative: true,
            brake: BrakeLimit::from_mps2(7.9f32),
            length: BodyLength::from_m(4.5f32),
        };
        node.exchange(&[car], (step % 16) as u8, t)?;
        node.view.others(t, params.length(), &mut node.others);
        let obs = LaneObservation {
            pose: q,
            v_prev: v,
            omega_prev: w,
            others: &node.others,
            road,
            target_lane: 1,
            target: 0.0,
            v_ref: 15.0,
        };
        let t0 = now();
        let result = lp.step(&obs);
        let ticks = now().wrapping_sub(t0);
        let cmd = result.ok()?;
        let solved = matches!(cmd.status, StepStatus::Solved { .. });
        if !solved {
            out.fallbacks += 1;
        }
        if cmd.alpha.is_some() {
            out.changing += 1;
        }
        // The single-lane planner in the same period, from the same view.
        node.view
            .lane_vehicles(cmd.lane, params.length(), &mut node.ahead);
        let shadow = Observation {
            x: q.x,
            v_prev: v,
            vehicles: &node.ahead,
            stop_line: Some(STOP_LINE_X),
            target_x: 0.0,
            v_ref: 15.0,
        };
        let t1 = now();
        let planned = single.step(&shadow);
        let single_ticks = now().wrapping_sub(t1);
        let sc = planned.ok()?;
        if !matches!(sc.status, StepStatus::Solved { .. }) {
            out.single_fallbacks += 1;
        }
        emit(&StepRecord {
            scenario: 'S',
            k: step,
            v: sc.v,
            omega: 0.0,
            ticks: single_ticks,
            timed: false,
            position: q.x,
            status: Some(sc.status),
            event: None,
        });
        q = planner_core::unicycle::step(q, cmd.v, cmd.omega, params.h());
        v = cmd.v;
        w = cmd.omega;
        emit(&StepRecord {
            scenario: 'L',
            k: step,
            v: cmd.v,
            omega: cmd.omega,
            ticks,
            timed: cmd.alpha.is_some(),
            position: q.y,
            status: Some(cmd.status),
            event: cmd.event,
        });
        if cmd.event == Some(LaneEvent::Completed(1)) {
            out.completed_at = Some(step);
            break;
        }
    }
    out.y = q.y;
    Some(out)
}
