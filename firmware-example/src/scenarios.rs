//! The firmware's two scenarios, written once and compiled both into the firmware and,
//! unchanged, into the host mirror (`cargo run -p workspace-tests --example
//! firmware_mirror`), so that CI can check that the Cortex-M4F plans exactly what the
//! host plans in the same precision from the same inputs, step for step.
//!
//! Each scenario is a control loop: read the neighbours' CAN frames, run the planner,
//! hand the command to `emit`. `now` reads a monotonic tick counter (SysTick on the MCU,
//! nothing on the host); `emit` applies the command and, on the MCU, waits out the rest of
//! the 10 ms period (embedded-hal `DelayNs`), so the loop runs at h.

use can_gateway::{encode, Frames, Message, PlainFrame, Reassembler};
use embedded_can::{nb::Can, ErrorKind};
use planner_core::{
    Duration, FallbackReason, Instant, LaneEvent, LaneObservation, LanePlanner, Observation,
    Planner, Pose, Road, StepStatus, VehicleState, WorldView,
};

/// What the firmware's clock reads at power-up: 60 days of uptime, so that every run
/// shows that stamps, ages and the wire's wrapping milliseconds do not depend on how
/// long the vehicle has been on (`planner_core::time`).
pub const CLOCK_START: Instant = Instant::from_secs(60 * 86_400);

/// Steps of the approach.
pub const APPROACH_STEPS: u32 = 1000;
/// Most steps the lane change may take.
pub const LANE_CHANGE_STEPS: u32 = 1000;

/// One planned step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepRecord {
    /// 'A' (approach) or 'L' (lane change).
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

/// (1) A stopped car (id 1) 60 m ahead broadcasts its state every period over CAN; the
/// ego (id 2) starts at 15 m/s and knows it only from the frames it receives. Both
/// clocks read `start` at the first period.
#[inline(never)]
pub fn approach<const N: usize>(
    planner: &mut Planner<f32, N>,
    start: Instant,
    now: &mut impl FnMut() -> u32,
    emit: &mut impl FnMut(&StepRecord),
) -> Option<Approach> {
    let params = *planner.params();
    let mut can = LoopbackCan {
        fifo: heapless::Deque::new(),
    };
    let mut rx = Reassembler::<4>::new();
    let mut world = WorldView::<f32, 4>::new(2);
    let mut lane_buf = heapless::Vec::new();
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
        };
        let frames: Frames<PlainFrame> =
            encode(&Message::State(leader), 1, (step % 16) as u8).ok()?;
        for f in &frames {
            can.transmit(f).ok()?;
        }
        while let Ok(f) = can.receive() {
            out.frames += 1;
            match rx.push::<f32, _>(&f, t) {
                Ok(Some(Message::State(s))) => {
                    if world.update(&s, t).is_err() {
                        out.rejected += 1;
                    }
                }
                Ok(_) => {}
                Err(_) => out.rejected += 1,
            }
        }
        world.lane_vehicles(0, 4.5, &mut lane_buf);
        let obs = Observation {
            x: out.x,
            v_prev: out.v,
            vehicles: &lane_buf,
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
                    StepStatus::Fallback(_) => out.fallbacks += 1,
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
    Some(out)
}

/// (2) A lane change from lane 0 to lane 1 at 15 m/s on an empty two-lane road.
#[inline(never)]
pub fn lane_change<const N: usize>(
    lp: &mut LanePlanner<f32, N>,
    now: &mut impl FnMut() -> u32,
    emit: &mut impl FnMut(&StepRecord),
) -> Option<LaneChange> {
    let params = *lp.params();
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
    };
    for step in 0..LANE_CHANGE_STEPS {
        let obs = LaneObservation {
            pose: q,
            v_prev: v,
            omega_prev: w,
            others: &[],
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
