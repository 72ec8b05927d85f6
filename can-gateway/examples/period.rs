//! A vehicle computer's control period, as firmware runs it, on the host:
//!
//! CAN frames in → [`Reassembler`] → [`WorldView`] → the multi-lane planner (driving) and
//! the single-lane planner (toward a stop line, kept warm) → the applied command → this
//! vehicle's own state message out as frames.
//!
//! Both planners live in static slots, built in place (`planner_core::slot`), both know
//! the bus's resolution, and a step whose input is refused applies the certified
//! fallback (Lemma 2's maximum braking). The ego (id 2) changes from lane 0 to lane 1 on
//! a road with two cars it knows only from their frames, then stops at a stop line 300 m
//! on (an intersection it has no permission for); the example checks that it never came
//! within its safety distance of a car and stopped before the line, and exits 1 if not.
//!
//! `cargo run --release -p can-gateway --example period`

use core::ptr::addr_of_mut;

use can_gateway::wire::{POS_RES, SPEED_RES};
use can_gateway::{encode, Frames, Message, PlainFrame, Reassembler};
use planner_core::heapless::Vec;
use planner_core::safety::max_braking_command;
use planner_core::{
    BrakeLimit, CostWeights, Duration, FallbackReason, Instant, LaneEvent, LaneObservation,
    LanePlannerSlot, Observation, Other, Params, PlannerSlot, Pose, Road, StepStatus, VehicleState,
    WorldView,
};

/// Horizon of both planners.
const N: usize = 20;
/// Vehicles a view holds (the planners' neighbour sets are bounded alike).
const CAP: usize = 8;
/// This vehicle's id and CAN source address.
const EGO: u16 = 2;
/// Where the stop line is (m).
const STOP_LINE: f32 = 300.0;
/// From here on the single-lane planner drives (m): the change is over by then.
const HANDOVER_X: f32 = 180.0;

/// The planners' storage: all zeros until `init`, so it sits in `.bss` — on an MCU, RAM
/// that costs no flash and no stack. Reached once, in `main`, through `addr_of_mut!`
/// (never `&mut SLOTS`, an error in edition 2024), and handed down as `&mut`.
static mut SLOTS: (PlannerSlot<f32, N>, LanePlannerSlot<f32, N>) =
    (PlannerSlot::new(), LanePlannerSlot::new());

/// A scripted car: constant speed in its lane, broadcasting its state each period.
struct Car {
    id: u16,
    lane: u8,
    x: f32,
    v: f32,
}

impl Car {
    fn state(&self, lane_width: f32, stamp: Instant) -> VehicleState<f32> {
        VehicleState {
            id: self.id,
            x: self.x,
            y: (f32::from(self.lane) + 0.5) * lane_width,
            theta: 0.0,
            v: self.v,
            omega: 0.0,
            lane: self.lane,
            alpha: None,
            beta: None,
            stamp,
            cooperative: true,
            brake: BrakeLimit::from_mps2(7.9f32),
            length: None,
        }
    }
}

/// What a run counted.
#[derive(Debug, Default)]
struct Tally {
    frames_in: u32,
    frames_out: u32,
    solved: u32,
    standstill: u32,
    fallbacks: u32,
    changed_at: Option<f32>,
    handover_at: Option<f32>,
    refused: u32,
    closest: f32,
}

fn main() -> std::process::ExitCode {
    let params = Params::<f32>::table_i();
    // The one place the statics are reached.
    let slots = unsafe { &mut *addr_of_mut!(SLOTS) };
    let (Ok(single), Ok(lane)) = (
        slots.0.init(params, CostWeights::default()),
        slots.1.init(params, CostWeights::default(), 0),
    ) else {
        eprintln!("the default configuration is valid");
        return std::process::ExitCode::FAILURE;
    };
    // Positions and speeds arrive rounded to the wire's steps: both planners allow for it.
    let (pos, speed) = (POS_RES as f32, SPEED_RES as f32);
    if single.set_bus_resolution(pos, speed).is_err()
        || lane.set_bus_resolution(pos, speed).is_err()
    {
        return std::process::ExitCode::FAILURE;
    }
    let road = Road {
        lanes: 2,
        lane_width: params.lane_width(),
        end_x: None,
    };
    let mut cars = [
        Car {
            id: 1,
            lane: 0,
            x: 40.0,
            v: 12.0,
        },
        Car {
            id: 3,
            lane: 1,
            x: 70.0,
            v: 14.0,
        },
    ];
    let mut rx = Reassembler::<4>::new();
    let mut view = WorldView::<f32, CAP>::new(EGO);
    let (mut others, mut ahead) = (Vec::<Other<f32>, CAP>::new(), Vec::new());
    let mut pose = Pose {
        x: 0.0f32,
        y: 0.5 * road.lane_width,
        theta: 0.0,
    };
    let (mut v, mut omega, mut ego_lane) = (15.0f32, 0.0f32, 0u8);
    let mut tally = Tally {
        closest: f32::INFINITY,
        ..Tally::default()
    };
    // The clock reads 60 days of uptime: time is integer microseconds, so nothing depends
    // on how long the vehicle has been on.
    let start = Instant::from_secs(60 * 86_400);
    for k in 0..3_000u32 {
        let now = start.saturating_add(Duration::from_millis(10 * u64::from(k)));
        // 1. The bus: each car's state as frames (a controller's receive FIFO on an MCU),
        //    reassembled into messages and taken into the view.
        for car in &cars {
            let msg = Message::State(car.state(road.lane_width, now));
            let Ok(frames): Result<Frames<PlainFrame>, _> =
                encode(&msg, car.id as u8, (k % 16) as u8)
            else {
                return std::process::ExitCode::FAILURE;
            };
            for f in &frames {
                tally.frames_in += 1;
                if let Ok(Some(Message::State(s))) = rx.push::<f32, _>(f, now) {
                    let _ = view.update(&s, now);
                }
            }
        }
        // 2. Both planners, every period: the one that drives, and the one that will
        //    (kept warm, so that the handover starts from a plan, not cold).
        view.others(now, params.length(), &mut others);
        let lane_cmd = lane.step(&LaneObservation {
            pose,
            v_prev: v,
            omega_prev: omega,
            others: &others,
            road,
            target_lane: 1,
            target: 0.0,
            v_ref: 15.0,
        });
        view.lane_vehicles(ego_lane, params.length(), &mut ahead);
        let single_cmd = single.step(&Observation {
            x: pose.x,
            v_prev: v,
            vehicles: &ahead,
            stop_line: Some(STOP_LINE),
            target_x: 0.0,
            v_ref: 15.0,
        });
        // 3. The applied command: the lane planner's on the road, the single-lane
        //    planner's once straight in the target lane near the line; a refused input
        //    brakes as hard as allowed (Lemma 2), never "keeps the last command".
        let driving = pose.x < HANDOVER_X || ego_lane != 1 || pose.theta.abs() > 1e-3;
        let (new_v, new_omega, status) = match (driving, lane_cmd, single_cmd) {
            (true, Ok(c), _) => {
                if c.event == Some(LaneEvent::Completed(1)) {
                    tally.changed_at = Some(pose.x);
                }
                ego_lane = c.lane;
                (c.v, c.omega, Some(c.status))
            }
            (false, _, Ok(c)) => {
                tally.handover_at.get_or_insert(pose.x);
                (c.v, 0.0, Some(c.status))
            }
            _ => (max_braking_command(&params, v), 0.0, None),
        };
        match status {
            Some(StepStatus::Solved { .. }) | Some(StepStatus::Reused { .. }) => tally.solved += 1,
            // Standing at the line: braking is the only answer, not a failure.
            Some(StepStatus::Fallback(FallbackReason::NoRoom)) => tally.standstill += 1,
            Some(_) => tally.fallbacks += 1,
            None => tally.refused += 1,
        }
        // 4. The plant (here: the exact unicycle), and this vehicle's state on the bus.
        pose = planner_core::unicycle::step(pose, new_v, new_omega, params.h());
        (v, omega) = (new_v, new_omega);
        let own = VehicleState {
            id: EGO,
            x: pose.x,
            y: pose.y,
            theta: pose.theta,
            v,
            omega,
            lane: ego_lane,
            alpha: None,
            beta: None,
            stamp: now,
            cooperative: true,
            brake: BrakeLimit::from_mps2(7.9f32),
            length: None,
        };
        match encode::<f32, PlainFrame>(&Message::State(own), EGO as u8, (k % 16) as u8) {
            Ok(frames) => tally.frames_out += frames.len() as u32,
            Err(_) => return std::process::ExitCode::FAILURE,
        }
        for car in cars.iter_mut() {
            car.x += car.v * params.h();
            if car.lane == ego_lane || car.lane == lane_of(pose.y, road.lane_width) {
                let gap = (car.x - pose.x).abs() - params.length();
                tally.closest = tally.closest.min(gap);
            }
        }
    }
    report(&tally, pose.x, v)
}

/// The lane the ego's centre is in.
fn lane_of(y: f32, lane_width: f32) -> u8 {
    (y / lane_width).clamp(0.0, 1.0) as u8
}

fn report(t: &Tally, x: f32, v: f32) -> std::process::ExitCode {
    let limit = STOP_LINE - 0.5 * 4.5;
    println!(
        "3,000 periods: {} frames in, {} out; applied steps solved {}, standing at the \
         line {}, certified fallbacks {}, refused inputs {} (max braking)",
        t.frames_in, t.frames_out, t.solved, t.standstill, t.fallbacks, t.refused
    );
    println!(
        "lane change 0 → 1 completed at x = {:.1} m; the single-lane planner drove from x = {:.1} m",
        t.changed_at.unwrap_or(f32::NAN),
        t.handover_at.unwrap_or(f32::NAN)
    );
    println!(
        "stopped at x = {x:.2} m (v = {v:.2} m/s), the line's rear limit {limit:.2} m; \
         closest bumper gap to a car in the ego's lane {:.2} m",
        t.closest
    );
    let handed_over = t.changed_at.is_some() && t.handover_at.is_some();
    if v == 0.0 && x <= limit && t.closest > 0.0 && handed_over && t.fallbacks == 0 {
        std::process::ExitCode::SUCCESS
    } else {
        eprintln!("FAILED: the ego must stop before the line without touching a car");
        std::process::ExitCode::FAILURE
    }
}
