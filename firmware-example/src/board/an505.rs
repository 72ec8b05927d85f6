//! ARM MPS2 with the AN505 FPGA image: a Cortex-M33 in the SSE-200 subsystem
//! (`thumbv8m.main-none-eabihf`). The core resets into the Secure state with its vector
//! table at 0x1000_0000, so the firmware runs Secure: code in SSRAM1's Secure alias at
//! 0x1000_0000, data in SSRAM2/3's at 0x3800_0000 (`boards/an505.x`); the footprint is
//! measured from there, not from 0.

/// QEMU's `-machine`.
pub const MACHINE: &str = "mps2-an505";
/// The core QEMU emulates (`-cpu cortex-m33`).
pub const CORE: &str = "Cortex-M33";
/// SysTick's clock: the SSE-200's 20 MHz system clock (QEMU's `sysclk_frq` for the
/// AN505). At `-icount shift=3` (125 MHz of virtual time) a tick is 6.25 instructions,
/// which is why the calibration is fractional.
pub const SYSTICK_HZ: u32 = 20_000_000;
/// UART 0 (`-serial`'s first device): the CMSDK APB UART's Secure alias (0x4020_0000 + 0x1000_0000), behind a PPC that leaves it Secure after reset.
pub const UART0: usize = 0x5020_0000;
/// UART 0's receive interrupt: QEMU's `mps2-an505` wires the UART 0 of the expansion
/// area to IRQ 32 (receive) and 33 (transmit), as the AN505's interrupt map lists them.
pub const UART0_RX_IRQ: u16 = 32;
