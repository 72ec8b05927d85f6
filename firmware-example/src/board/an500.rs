//! ARM MPS2 with the AN500 FPGA image: a Cortex-M7. The memory map (code at 0, data at
//! 0x2000_0000, `boards/mps2.x`), the system clock and the instruction set
//! (`thumbv7em-none-eabihf`; the M7's double-precision FPU goes unused, the planner runs in
//! f32) are the AN386's, so the same code runs on both; this module is its own so that a
//! run says which core it measured.

/// QEMU's `-machine`.
pub const MACHINE: &str = "mps2-an500";
/// The core QEMU emulates (`-cpu cortex-m7`).
pub const CORE: &str = "Cortex-M7";
/// SysTick's clock: the board's 25 MHz system clock.
pub const SYSTICK_HZ: u32 = 25_000_000;
/// UART 0 (`-serial`'s first device): the CMSDK APB UART at 0x4000_4000, as on the AN386.
pub const UART0: usize = 0x4000_4000;
/// UART 0's receive interrupt: QEMU's `mps2` machines wire it to IRQ 0 (transmit to 1).
pub const UART0_RX_IRQ: u16 = 0;
