//! The vehicle computer in the loop (`src/sil.rs`, its node in `src/sil_node.rs`): the
//! planner as one vehicle of a world simulated on the other end of the board's UART,
//! serial-line CAN between them. Built
//! beside the scripted program (`src/main.rs`) from the same board, clock and measurement
//! modules; `run.sh BOARD N OUT sil` builds it and drives it with `sil_check.py`.
#![no_std]
#![no_main]

// Shared with the scripted program, which uses all of them; this one uses a part.
#[path = "../board/mod.rs"]
mod board;
#[allow(dead_code)]
#[path = "../clock.rs"]
mod clock;
#[allow(dead_code)]
#[path = "../measure.rs"]
mod measure;
#[path = "../sil.rs"]
mod sil;
#[path = "../sil_node.rs"]
mod sil_node;
#[path = "../uart.rs"]
mod uart;

use cortex_m_rt::entry;
// defmt's global logger: semihosting, which QEMU writes to its standard output.
use defmt_semihosting as _;

#[entry]
fn main() -> ! {
    sil::run()
}
