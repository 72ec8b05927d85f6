//! planner-core on a Cortex-M4F, in f32 at h = 10 ms, printed over semihosting:
//! (1) a single-lane approach to a stopped vehicle that the ego knows only from its V2V
//! state messages, received as CAN frames through can-gateway from an `embedded-can`
//! controller (in loopback mode: what it transmits for the leader comes back in its
//! receive FIFO); (2) a lane change on a two-lane road.
//! It also measures what the planner costs here: flash and static RAM (from the linker's
//! symbols), peak stack (stack painting), and instructions per planner step (SysTick
//! under QEMU's `-icount shift=0`, where one instruction is one nanosecond of virtual time;
//! the ticks-to-instructions factor is calibrated on a loop of known length).
//! Build with `--features n50` for a horizon of 50.
#![no_std]
#![no_main]

use can_gateway::{encode, Frames, Message, PlainFrame, Reassembler};
use core::panic::PanicInfo;
use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use embedded_can::{nb::Can, ErrorKind};
use planner_core::{
    CostWeights, FallbackReason, LaneEvent, LaneObservation, LanePlanner, Observation, Params,
    Planner, Pose, Road, StepStatus, VehicleState, WorldView,
};

/// A CAN controller in loopback mode, as drivers offer for self-test: every frame it
/// transmits arrives in its own receive FIFO (32 frames deep).
struct LoopbackCan {
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

#[cfg(not(feature = "n50"))]
const N: usize = 20;
#[cfg(feature = "n50")]
const N: usize = 50;

/// Iterations of the calibration loop (two instructions each).
const CALIBRATION_ITERATIONS: u32 = 1_000_000;
/// Word painted over the free stack before the run.
const PAINT: u32 = 0xDEAD_BEEF;
const STEPS: usize = 1000;

/// Per-step tick counts (a measurement buffer, not part of the planner's footprint).
static mut SAMPLES: [u32; STEPS] = [0; STEPS];

extern "C" {
    static __sdata: u32;
    static __edata: u32;
    static __sbss: u32;
    static __ebss: u32;
    static __erodata: u32;
    static _stack_start: u32;
}

fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::wfi();
    }
}

/// Paints the free stack from the end of static RAM up to 256 bytes below the current
/// stack pointer.
fn paint_stack() {
    let bottom = unsafe { &__ebss as *const u32 as usize };
    let sp = cortex_m::register::msp::read() as usize - 256;
    let mut a = (bottom + 3) & !3;
    while a < sp {
        unsafe { core::ptr::write_volatile(a as *mut u32, PAINT) };
        a += 4;
    }
}

/// Bytes of stack ever used: from the top down to the lowest word no longer painted.
fn peak_stack() -> usize {
    let bottom = unsafe { &__ebss as *const u32 as usize };
    let top = unsafe { &_stack_start as *const u32 as usize };
    let mut a = (bottom + 3) & !3;
    while a < top && unsafe { core::ptr::read_volatile(a as *const u32) } == PAINT {
        a += 4;
    }
    top - a
}

/// Ticks elapsed between two SysTick readings (it counts down, 24 bits).
fn elapsed(start: u32, end: u32) -> u32 {
    start.wrapping_sub(end) & 0x00FF_FFFF
}

/// Instructions per SysTick tick, measured: a loop of exactly 2 instructions per iteration
/// (`subs`, `bne`) timed by SysTick. Under `-icount shift=0` this is 40 (1 ns per
/// instruction, 25 MHz SysTick); without `-icount` it is meaningless, and so are the
/// instruction counts.
fn calibrate() -> u32 {
    let t0 = SYST::get_current();
    let mut n = CALIBRATION_ITERATIONS;
    // SAFETY: a register-only countdown loop.
    unsafe {
        core::arch::asm!("1:", "subs {0}, {0}, #1", "bne 1b", inout(reg) n, options(nomem, nostack));
    }
    let _ = n;
    let ticks = elapsed(t0, SYST::get_current()).max(1);
    (2 * CALIBRATION_ITERATIONS + ticks / 2) / ticks
}

/// Median and maximum of the first `n` samples, in instructions.
fn stats(n: usize, instr_per_tick: u32) -> (u32, u32) {
    let s = unsafe { &mut *core::ptr::addr_of_mut!(SAMPLES) };
    let s = &mut s[..n.min(STEPS)];
    s.sort_unstable();
    let med = s.get(s.len() / 2).copied().unwrap_or(0);
    let max = s.last().copied().unwrap_or(0);
    (med * instr_per_tick, max * instr_per_tick)
}

fn record(i: usize, ticks: u32) {
    let s = unsafe { &mut *core::ptr::addr_of_mut!(SAMPLES) };
    if let Some(slot) = s.get_mut(i) {
        *slot = ticks;
    }
}

#[entry]
fn main() -> ! {
    paint_stack();
    let mut cp = match cortex_m::Peripherals::take() {
        Some(cp) => cp,
        None => exit(false),
    };
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(0x00FF_FFFF);
    cp.SYST.clear_current();
    cp.SYST.enable_counter();
    let per_tick = calibrate();
    hprintln!("calibration: {} instructions per SysTick tick", per_tick);

    let params = Params::<f32>::table_i();
    let Ok(mut planner) = Planner::<f32, N>::new(params, CostWeights::default()) else {
        exit(false)
    };
    // (1) A stopped car (id 1) 60 m ahead broadcasts its state every period; we (id 2)
    // start at 15 m/s and know it only from the frames we receive.
    let mut can = LoopbackCan {
        fifo: heapless::Deque::new(),
    };
    let mut rx = Reassembler::<4>::new();
    let mut world = WorldView::<f32, 4>::new(2);
    let mut lane_buf = heapless::Vec::new();
    let (mut x, mut v) = (0.0f32, 15.0f32);
    let (mut solved, mut standstill, mut fallbacks) = (0u32, 0u32, 0u32);
    let (mut timed, mut frames_in, mut rejected) = (0usize, 0u32, 0u32);
    for step in 0..STEPS as u32 {
        let now = step as f32 * params.h();
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
            stamp: now,
        };
        let Ok(out): Result<Frames<PlainFrame>, _> =
            encode(&Message::State(leader), 1, (step % 16) as u8)
        else {
            exit(false)
        };
        for f in &out {
            if can.transmit(f).is_err() {
                exit(false);
            }
        }
        while let Ok(f) = can.receive() {
            frames_in += 1;
            match rx.push::<f32, _>(&f) {
                Ok(Some(Message::State(s))) => {
                    if world.update(&s, now).is_err() {
                        rejected += 1;
                    }
                }
                Ok(_) => {}
                Err(_) => rejected += 1,
            }
        }
        world.lane_vehicles(0, 4.5, &mut lane_buf);
        let obs = Observation {
            x,
            v_prev: v,
            vehicles: &lane_buf,
            stop_line: None,
            target_x: 0.0,
            v_ref: params.v_max(),
        };
        let t0 = SYST::get_current();
        let result = planner.step(&obs);
        let dt = elapsed(t0, SYST::get_current());
        match result {
            Ok(cmd) => {
                match cmd.status {
                    StepStatus::Solved { .. } => {
                        solved += 1;
                        // Time the steps that solve (standstill steps skip the solver).
                        record(timed, dt);
                        timed += 1;
                    }
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
    hprintln!("CAN: {} frames received, {} rejected", frames_in, rejected);
    let (med, max) = stats(timed, per_tick);
    hprintln!(
        "instructions per single-lane step (N={}): median={} worst={} over {} solved steps",
        N,
        med,
        max,
        timed
    );
    // Success needs a stop behind the obstacle point x̄ = 60 − 4.5 − 0.5 = 55 m with no
    // fallback.
    let approach_ok = fallbacks == 0 && v == 0.0 && x < 55.0 && x > 54.9 && rejected == 0;

    // (2) A lane change from lane 0 to lane 1 at 15 m/s on an empty two-lane road.
    let Ok(mut lp) = LanePlanner::<f32, N>::new(params, CostWeights::default(), 0) else {
        exit(false)
    };
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
    let (mut changing, mut completed_at, mut lane_fallbacks) = (0usize, None, 0u32);
    for step in 0..STEPS {
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
        let t0 = SYST::get_current();
        let result = lp.step(&obs);
        let dt = elapsed(t0, SYST::get_current());
        let Ok(cmd) = result else { exit(false) };
        if !matches!(cmd.status, StepStatus::Solved { .. }) {
            lane_fallbacks += 1;
        }
        if cmd.alpha.is_some() {
            record(changing, dt);
            changing += 1;
        }
        if cmd.event == Some(LaneEvent::Completed(1)) {
            completed_at = Some(step);
            break;
        }
        q = planner_core::unicycle::step(q, cmd.v, cmd.omega, params.h());
        v = cmd.v;
        w = cmd.omega;
    }
    let (lmed, lmax) = stats(changing, per_tick);
    hprintln!(
        "lane change: completed at step {:?}, y={} fallback={}",
        completed_at,
        q.y,
        lane_fallbacks
    );
    hprintln!(
        "instructions per lane-change step (N={}): median={} worst={} over {} steps",
        N,
        lmed,
        lmax,
        changing
    );
    let lane_ok = completed_at.is_some() && lane_fallbacks == 0;

    // Footprint, from the linker's symbols (vector table and code start at 0).
    let (flash, ram) = unsafe {
        let addr = |s: &u32| s as *const u32 as usize;
        let data = addr(&__edata) - addr(&__sdata);
        let bss = addr(&__ebss) - addr(&__sbss);
        (addr(&__erodata) + data, data + bss)
    };
    let samples = core::mem::size_of::<[u32; STEPS]>();
    hprintln!(
        "footprint (N={}): flash={} B, static RAM={} B (of which {} B measurement buffer), peak stack={} B",
        N,
        flash,
        ram,
        samples,
        peak_stack()
    );
    exit(approach_ok && lane_ok)
}

#[panic_handler]
fn panic(_: &PanicInfo) -> ! {
    exit(false)
}
