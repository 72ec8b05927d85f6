//! The MPS2 boards' UART: Arm's CMSDK APB UART (QEMU `cmsdk-apb-uart`), polled. QEMU
//! connects the board's UART 0 to its first `-serial` device, so a host program on a TCP
//! or Unix socket is the other end of the line, as a USB-serial adapter would be on a
//! bench.
//!
//! A node that waits for the line sleeps in `wfi` with the receive interrupt on
//! ([`Uart::listen`], [`Uart::wait`]): under QEMU's `-icount sleep=off` a polling core
//! executes instructions as fast as the host can while the bytes trickle in one at a time
//! (the UART holds one). Three computers in the loop on the multi-lane road took 157 s of
//! wall time on two cores polling, 53 s sleeping; one alone on the dense road, whose
//! world streams 133 frames a period, took 160 s polling and 231 s sleeping (QEMU wakes the
//! core for each byte), which is why CI runs it beside the others.

use core::ptr::{read_volatile, write_volatile};

/// Data register: the byte received, or the byte to send.
const DATA: usize = 0x00;
/// State register: bit 0 transmit buffer full, bit 1 receive buffer full.
const STATE: usize = 0x04;
/// Control register: bit 0 transmit enable, bit 1 receive enable, bit 3 receive
/// interrupt enable.
const CTRL: usize = 0x08;
/// Interrupt status; writing a 1 clears that interrupt (bit 1: a byte was received).
const INT_CLEAR: usize = 0x0C;
/// Baud-rate divider: the UART clock over the bit rate, at least 16.
const BAUDDIV: usize = 0x10;
const TX_FULL: u32 = 1 << 0;
const RX_FULL: u32 = 1 << 1;
const TX_ENABLE: u32 = 1 << 0;
const RX_ENABLE: u32 = 1 << 1;
const RX_INT_ENABLE: u32 = 1 << 3;
const RX_INT: u32 = 1 << 1;
/// Polls of a full transmit buffer before a byte is given up: a wedged UART stops the
/// sender instead of hanging it (a byte takes about 87 µs at 115,200 bit/s, 11,000
/// instructions at 125 MHz; QEMU's takes none).
const TX_POLLS: u32 = 100_000;

/// A byte could not be sent: the transmit buffer stayed full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct TxTimeout;

/// One CMSDK APB UART, polled.
pub struct Uart {
    base: usize,
}

impl Uart {
    /// Takes the UART at `base` at 115,200 bit/s from a `clock_hz` clock, transmit and
    /// receive enabled, interrupts off.
    ///
    /// # Safety
    /// `base` is a CMSDK APB UART's address on this board, and nothing else drives it.
    pub unsafe fn new(base: usize, clock_hz: u32) -> Self {
        let uart = Self { base };
        uart.write_reg(BAUDDIV, (clock_hz / 115_200).max(16));
        uart.write_reg(CTRL, TX_ENABLE | RX_ENABLE);
        uart
    }

    fn write_reg(&self, offset: usize, value: u32) {
        // SAFETY: `new`'s contract: `base` is this UART's register block.
        unsafe { write_volatile((self.base + offset) as *mut u32, value) }
    }

    fn read_reg(&self, offset: usize) -> u32 {
        // SAFETY: as in `write_reg`.
        unsafe { read_volatile((self.base + offset) as *const u32) }
    }

    /// The byte received, if one is waiting.
    pub fn read(&mut self) -> Option<u8> {
        self.ready().then(|| self.read_reg(DATA) as u8)
    }

    fn ready(&self) -> bool {
        self.read_reg(STATE) & RX_FULL != 0
    }

    /// Turns the receive interrupt on: each byte raises the board's UART 0 receive
    /// interrupt, which [`Uart::clear_receive_interrupt`] acknowledges (its handler).
    pub fn listen(&mut self) {
        self.write_reg(CTRL, TX_ENABLE | RX_ENABLE | RX_INT_ENABLE);
    }

    /// Sleeps (`wfi`) until a byte is waiting, if none is: decided with interrupts masked,
    /// so a byte arriving in between still ends the sleep (its interrupt is pending, and
    /// is taken after the section). Needs [`Uart::listen`] and the interrupt enabled.
    pub fn wait(&self) {
        cortex_m::interrupt::free(|_| {
            if !self.ready() {
                cortex_m::asm::wfi();
            }
        });
    }

    /// Acknowledges the receive interrupt of the UART at `base` (the byte stays waiting).
    ///
    /// # Safety
    /// `base` is a CMSDK APB UART's address on this board.
    pub unsafe fn clear_receive_interrupt(base: usize) {
        // SAFETY: the caller's contract.
        unsafe { write_volatile((base + INT_CLEAR) as *mut u32, RX_INT) }
    }

    /// Sends `byte`, waiting (bounded) for room.
    pub fn write(&mut self, byte: u8) -> Result<(), TxTimeout> {
        for _ in 0..TX_POLLS {
            if self.read_reg(STATE) & TX_FULL == 0 {
                self.write_reg(DATA, u32::from(byte));
                return Ok(());
            }
        }
        Err(TxTimeout)
    }

    /// Sends `bytes` in order.
    pub fn write_all(&mut self, bytes: &[u8]) -> Result<(), TxTimeout> {
        bytes.iter().try_for_each(|&b| self.write(b))
    }
}
