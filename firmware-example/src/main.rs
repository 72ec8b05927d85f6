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

mod scenarios;

use core::panic::PanicInfo;
use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use scenarios::StepRecord;

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

/// Ticks elapsed between two SysTick readings (it counts down, 24 bits; the calibration
/// reads it directly).
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

    let mut now = || SYST::get_current().wrapping_neg() & 0x00FF_FFFF;
    // Every command goes out as a `cmd` line (f32 bits in hex), for CI to compare with the
    // host mirror step for step; timed steps go to the statistics (`timed` counts them and
    // is reset between the scenarios).
    let timed = core::cell::Cell::new(0usize);
    let mut emit = |r: &StepRecord| {
        hprintln!(
            "cmd {} {} {:08x} {:08x}",
            r.scenario,
            r.k,
            r.v.to_bits(),
            r.omega.to_bits()
        );
        if r.timed {
            record(timed.get(), r.ticks & 0x00FF_FFFF);
            timed.set(timed.get() + 1);
        }
        if r.scenario == 'A' && r.k.is_multiple_of(100) {
            hprintln!("t={}ms x={} v={}", r.k * 10, r.position, r.v);
        }
    };
    let Some(a) = scenarios::approach::<N>(&mut now, &mut emit) else {
        exit(false)
    };
    hprintln!(
        "done: x={} v={} solved={} standstill={} fallback={}",
        a.x,
        a.v,
        a.solved,
        a.standstill,
        a.fallbacks
    );
    hprintln!("CAN: {} frames received, {} rejected", a.frames, a.rejected);
    let (med, max) = stats(timed.get(), per_tick);
    hprintln!(
        "instructions per single-lane step (N={}): median={} worst={} over {} solved steps",
        N,
        med,
        max,
        timed.get()
    );
    // Success needs a stop behind the obstacle point x̄ = 60 − 4.5 − 0.5 = 55 m with no
    // fallback, every frame accepted.
    let approach_ok = a.fallbacks == 0 && a.v == 0.0 && a.x < 55.0 && a.x > 54.9 && a.rejected == 0;

    timed.set(0);
    let Some(l) = scenarios::lane_change::<N>(&mut now, &mut emit) else {
        exit(false)
    };
    let (lmed, lmax) = stats(timed.get(), per_tick);
    hprintln!(
        "lane change: completed at step {:?}, y={} fallback={}",
        l.completed_at,
        l.y,
        l.fallbacks
    );
    hprintln!(
        "instructions per lane-change step (N={}): median={} worst={} over {} steps",
        N,
        lmed,
        lmax,
        l.changing
    );
    let lane_ok = l.completed_at.is_some() && l.fallbacks == 0;

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
