//! What the program costs on the board, measured on the board: peak stack by painting
//! the free stack and finding the lowest word written since, instructions per SysTick
//! tick by timing a loop of known length (the factor that turns tick counts into
//! instruction counts under QEMU's `-icount`), and the footprint from the linker's
//! symbols.

use crate::clock::Clock;

/// Word painted over the free stack before the run.
const PAINT: u32 = 0xDEAD_BEEF;
/// Iterations of the calibration loop (two instructions each).
const CALIBRATION_ITERATIONS: u32 = 1_000_000;

extern "C" {
    static __sdata: u32;
    static __edata: u32;
    static __sbss: u32;
    static __ebss: u32;
    static __erodata: u32;
    static __vector_table: u32;
    static _stack_start: u32;
}

/// Paints the free stack from the end of static RAM up to 256 bytes below the current
/// stack pointer.
pub fn paint_stack() {
    let bottom = unsafe { &__ebss as *const u32 as usize };
    let sp = cortex_m::register::msp::read() as usize - 256;
    let mut a = (bottom + 3) & !3;
    while a < sp {
        unsafe { core::ptr::write_volatile(a as *mut u32, PAINT) };
        a += 4;
    }
}

/// The lowest stack address written since the last paint.
pub fn lowest_unpainted() -> usize {
    let bottom = unsafe { &__ebss as *const u32 as usize };
    let top = unsafe { &_stack_start as *const u32 as usize };
    let mut a = (bottom + 3) & !3;
    while a < top && unsafe { core::ptr::read_volatile(a as *const u32) } == PAINT {
        a += 4;
    }
    a
}

/// Bytes of stack ever used: from the top down to the lowest word no longer painted.
pub fn peak_stack() -> usize {
    let top = unsafe { &_stack_start as *const u32 as usize };
    top - lowest_unpainted()
}

/// Paints the free stack afresh and returns the stack pointer here: a call made next
/// used `sp − lowest_unpainted()` bytes of stack (its frame and all it called).
pub fn repaint() -> usize {
    let sp = cortex_m::register::msp::read() as usize;
    paint_stack();
    sp
}

/// Hundredths of an instruction per SysTick tick, measured: a loop of exactly 2
/// instructions per iteration (`subs`, `bne`) timed by the clock. Under `-icount shift=3`
/// (8 ns per instruction) this is 500 with a 25 MHz SysTick and 625 with a 20 MHz one;
/// hundredths, because a whole number would be 6 % off on the second. Without `-icount`
/// it is meaningless, and so are the instruction counts.
pub fn calibrate(clock: &Clock) -> u32 {
    let t0 = clock.now();
    let mut n = CALIBRATION_ITERATIONS;
    // SAFETY: a register-only countdown loop.
    unsafe {
        core::arch::asm!("1:", "subs {0}, {0}, #1", "bne 1b", inout(reg) n, options(nomem, nostack));
    }
    let _ = n;
    let ticks = (clock.now() - t0).max(1);
    let hundredths = (200 * u64::from(CALIBRATION_ITERATIONS) + ticks / 2) / ticks;
    u32::try_from(hundredths).unwrap_or(u32::MAX)
}

/// Flash and static RAM in bytes, from the linker's symbols: flash from the vector table,
/// which sits at the flash origin (0 on the AN386 and AN500, 0x1000_0000 on the AN505).
pub fn footprint() -> (usize, usize) {
    // SAFETY: only the symbols' addresses are taken, never their contents.
    unsafe {
        let addr = |s: &u32| s as *const u32 as usize;
        let data = addr(&__edata) - addr(&__sdata);
        let bss = addr(&__ebss) - addr(&__sbss);
        (addr(&__erodata) - addr(&__vector_table) + data, data + bss)
    }
}
