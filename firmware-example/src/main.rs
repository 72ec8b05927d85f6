//! planner-core on a Cortex-M4F: a single-lane approach to a stopped vehicle, planned in
//! f32 at h = 10 ms, printed over semihosting. (CAN input through can-gateway, defmt
//! logging and the step-for-step comparison with the host come with the firmware issue.)
#![no_std]
#![no_main]

use core::panic::PanicInfo;
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use planner_core::{
    CostWeights, FallbackReason, Observation, Params, Planner, StepStatus, Vehicle,
};

const N: usize = 20;

#[entry]
fn main() -> ! {
    let params = Params::<f32>::table_i();
    let Ok(mut planner) = Planner::<f32, N>::new(params, CostWeights::default()) else {
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    };
    // A stopped car 60 m ahead; we start at 15 m/s.
    let leader = [Vehicle {
        x: 60.0f32,
        length: 4.5,
    }];
    let (mut x, mut v) = (0.0f32, 15.0f32);
    let mut solved = 0u32;
    let mut standstill = 0u32;
    let mut fallbacks = 0u32;
    for step in 0..1000u32 {
        let obs = Observation {
            x,
            v_prev: v,
            vehicles: &leader,
            stop_line: None,
            target_x: 0.0,
            v_ref: params.v_max(),
        };
        match planner.step(&obs) {
            Ok(cmd) => {
                match cmd.status {
                    StepStatus::Solved { .. } => solved += 1,
                    StepStatus::Fallback(FallbackReason::NoRoom) => standstill += 1,
                    StepStatus::Fallback(_) => fallbacks += 1,
                }
                v = cmd.v;
            }
            Err(_) => v = planner_core::safety::max_braking_command(&params, v),
        }
        x += v * params.h();
        if step % 100 == 0 {
            hprintln!("t={}ms x={} v={}", step * 10, x, v);
        }
    }
    hprintln!(
        "done: x={} v={} solved={} standstill={} fallback={}",
        x,
        v,
        solved,
        standstill,
        fallbacks
    );
    // Success only if it stopped behind the obstacle point x̄ = 60 − 4.5 − 0.5 = 55 m
    // without ever needing a fallback.
    if fallbacks == 0 && v == 0.0 && x < 55.0 && x > 54.9 {
        debug::exit(debug::EXIT_SUCCESS);
    } else {
        debug::exit(debug::EXIT_FAILURE);
    }
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(_: &PanicInfo) -> ! {
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}
