//! ARM MPS2 with the AN386 FPGA image: a Cortex-M4F (`thumbv7em-none-eabihf`), code at 0
//! and data at 0x2000_0000 (`boards/mps2.x`).

/// QEMU's `-machine`.
pub const MACHINE: &str = "mps2-an386";
/// The core QEMU emulates (`-cpu cortex-m4`).
pub const CORE: &str = "Cortex-M4F";
/// SysTick's clock: the board's 25 MHz system clock (QEMU's `sysclk_frq`), which SysTick
/// takes as the core clock.
pub const SYSTICK_HZ: u32 = 25_000_000;
/// UART 0 (`-serial`'s first device): the CMSDK APB UART at 0x4000_4000.
pub const UART0: usize = 0x4000_4000;
/// UART 0's receive interrupt: QEMU's `mps2` machines wire it to IRQ 0 (transmit to 1).
pub const UART0_RX_IRQ: u16 = 0;
