//! The board the firmware runs on, one module per QEMU machine: its name, core and SysTick
//! clock here, its memory map in `boards/*.x` (build.rs links the one the features pick),
//! and how a run ends. Everything else in the firmware is board-agnostic: the clock
//! derives its periods from [`SYSTICK_HZ`], the footprint is measured from the vector
//! table (the flash origin, which is not 0 on every board), and instructions per tick are
//! calibrated, not assumed.
//!
//! | feature | QEMU `-machine` | core | target | SysTick |
//! |---|---|---|---|---|
//! | (none) | `mps2-an386` | Cortex-M4F | `thumbv7em-none-eabihf` | 25 MHz |
//! | `an500` | `mps2-an500` | Cortex-M7 | `thumbv7em-none-eabihf` | 25 MHz |
//! | `an505` | `mps2-an505` | Cortex-M33 (Secure state) | `thumbv8m.main-none-eabihf` | 20 MHz |

#[cfg(not(any(feature = "an500", feature = "an505")))]
mod an386;
#[cfg(not(any(feature = "an500", feature = "an505")))]
pub use an386::*;

#[cfg(feature = "an500")]
mod an500;
#[cfg(feature = "an500")]
pub use an500::*;

#[cfg(feature = "an505")]
mod an505;
#[cfg(feature = "an505")]
pub use an505::*;

use cortex_m_semihosting::debug;

/// Ends the run with the firmware's verdict as QEMU's exit status (semihosting
/// `SYS_EXIT`, which every MPS2 machine in QEMU honours with `-semihosting-config
/// enable=on`). On a board without a debugger attached the core sleeps instead.
pub fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::wfi();
    }
}

/// A panic ends the run as a failure (the program's exit status is its verdict).
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    exit(false)
}

/// defmt's own panics (e.g. a re-entrant logger) end the run as a failure too.
#[defmt::panic_handler]
fn defmt_panic() -> ! {
    exit(false)
}
