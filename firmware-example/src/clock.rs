//! Time for the control loop: SysTick as a 1 kHz interrupt plus its down-counter gives a
//! monotonic clock in core-clock ticks, and an embedded-hal 1.0 [`DelayNs`] that sleeps
//! (`wfi`) through whole milliseconds, so the 10 ms loop idles instead of spinning. The
//! node's time for the planners ([`Clock::instant`], a `planner_core::Instant`) is that
//! count from what the clock read at start — 60 days here, as after a long uptime.
//!
//! Under QEMU with `-icount shift=3,sleep=off` one instruction is 8 ns of virtual time (a
//! 125 MHz core, below the 168 MHz of common M4F parts) and a sleeping core jumps straight
//! to the next timer deadline: timing is deterministic and idling costs no emulation time.
//! SysTick's rate is the board's ([`crate::board::SYSTICK_HZ`]).

use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::{syst::SystClkSource, SCB, SYST};
use cortex_m_rt::exception;
use embedded_hal::delay::DelayNs;
use planner_core::Instant;

/// SysTick input clock: the board's system clock.
pub const TICKS_PER_SECOND: u64 = crate::board::SYSTICK_HZ as u64;
/// SysTick reload period: 1 ms, the resolution of a sleeping delay.
const TICKS_PER_MS: u32 = crate::board::SYSTICK_HZ / 1_000;
/// Ticks per microsecond, for the node's time.
const TICKS_PER_US: u64 = TICKS_PER_SECOND / 1_000_000;

// Whole ticks per microsecond and per millisecond (1 ms also fits SysTick's 24-bit reload):
// the clock's arithmetic is exact only then.
const _: () = assert!(TICKS_PER_SECOND.is_multiple_of(1_000_000) && TICKS_PER_MS <= 1 << 24);

/// Milliseconds since [`Clock::start`], counted by the SysTick exception.
static MILLIS: AtomicU32 = AtomicU32::new(0);

#[exception]
fn SysTick() {
    MILLIS.fetch_add(1, Ordering::Relaxed);
}

/// The SysTick clock (a handle: the state lives in SysTick and [`MILLIS`]), and what it
/// read at start.
#[derive(Debug, Clone, Copy)]
pub struct Clock(Instant);

impl Clock {
    /// Takes SysTick (1 ms reload from the core clock, interrupt on); the node's time
    /// reads `at` now.
    pub fn start(mut syst: SYST, at: Instant) -> Self {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(TICKS_PER_MS - 1);
        let mut clock = Clock(at);
        clock.restart();
        clock
    }

    /// Stops SysTick, counter and interrupt: [`Clock::now`] stands still until
    /// [`Clock::restart`]. Under QEMU's `-icount sleep=off` a core in `wfi` with no timer
    /// running halts until an interrupt, instead of jumping from tick to tick.
    // The computer in the loop's (src/sil.rs); the scripted program sleeps with SysTick
    // running.
    #[allow(dead_code)]
    pub fn stop(&mut self) {
        // SAFETY: `start` took SysTick (its SYST handle), so nothing else drives it; this
        // clears its enable and interrupt bits.
        unsafe { (*SYST::PTR).csr.modify(|csr| csr & !0b11) }
    }

    /// Starts SysTick from millisecond 0 (at [`Clock::start`], and again after
    /// [`Clock::stop`]): [`Clock::now`] counts from here.
    pub fn restart(&mut self) {
        // SAFETY: `start` took SysTick (its SYST handle) and set its source and reload, so
        // nothing else drives it; this clears the counter and sets its enable bit.
        let syst = unsafe { &*SYST::PTR };
        unsafe {
            syst.cvr.write(0);
            syst.csr.modify(|csr| csr | 0b1);
        }
        // The counter starts at 0 and loads the reload value on its first tick; wait for
        // that (a few instructions) so millisecond 0 begins at the reload.
        for _ in 0..1_000 {
            if SYST::get_current() != 0 {
                break;
            }
        }
        MILLIS.store(0, Ordering::Relaxed);
        // SAFETY: as above; sets the interrupt's enable bit.
        unsafe { syst.csr.modify(|csr| csr | 0b10) }
    }

    /// The node's time now: the start reading plus the ticks since, in microseconds.
    pub fn instant(&self) -> Instant {
        let us = self.now() / TICKS_PER_US;
        self.0
            .saturating_add(planner_core::Duration::from_micros(us))
    }

    /// Ticks (1/25 MHz) since start. The interrupt comes as the counter reaches 0, so 0 is
    /// the first tick of a millisecond and the reload value its second. Re-reads when a
    /// millisecond passed in between, so the counter and the millisecond count belong
    /// together.
    pub fn now(&self) -> u64 {
        // Bounded: a retry happens only when the 1 ms interrupt struck between the reads.
        for _ in 0..4 {
            let m = MILLIS.load(Ordering::Relaxed);
            let c = SYST::get_current();
            if MILLIS.load(Ordering::Relaxed) == m {
                return u64::from(m) * u64::from(TICKS_PER_MS)
                    + u64::from((TICKS_PER_MS - c) % TICKS_PER_MS);
            }
        }
        u64::from(MILLIS.load(Ordering::Relaxed)) * u64::from(TICKS_PER_MS)
    }
}

impl DelayNs for Clock {
    /// Sleeps while the next millisecond interrupt comes before the deadline, then spins
    /// the remainder (so a deadline on a millisecond boundary is reached without spinning).
    fn delay_ns(&mut self, ns: u32) {
        let deadline = self.now() + u64::from(ns) * TICKS_PER_SECOND / 1_000_000_000;
        while self.now() < deadline {
            // Decide and sleep with interrupts masked, so the 1 ms interrupt cannot slip in
            // between (a pending one still ends `wfi`, and is taken after the section).
            cortex_m::interrupt::free(|_| {
                if SCB::is_pendst_pending() {
                    return;
                }
                let now = self.now();
                let next_ms = (now / u64::from(TICKS_PER_MS) + 1) * u64::from(TICKS_PER_MS);
                if next_ms <= deadline {
                    cortex_m::asm::wfi();
                }
            });
        }
    }
}
