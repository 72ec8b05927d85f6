//! The MPS2 boards' UART: Arm's CMSDK APB UART (QEMU `cmsdk-apb-uart`), polled. QEMU
//! connects the board's UART 0 to its first `-serial` device, so a host program on a TCP
//! or Unix socket is the other end of the line, as a USB-serial adapter would be on a
//! bench.

use core::ptr::{read_volatile, write_volatile};

/// Data register: the byte received, or the byte to send.
const DATA: usize = 0x00;
/// State register: bit 0 transmit buffer full, bit 1 receive buffer full.
const STATE: usize = 0x04;
/// Control register: bit 0 transmit enable, bit 1 receive enable.
const CTRL: usize = 0x08;
/// Baud-rate divider: the UART clock over the bit rate, at least 16.
const BAUDDIV: usize = 0x10;
const TX_FULL: u32 = 1 << 0;
const RX_FULL: u32 = 1 << 1;
const TX_ENABLE: u32 = 1 << 0;
const RX_ENABLE: u32 = 1 << 1;
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
        (self.read_reg(STATE) & RX_FULL != 0).then(|| self.read_reg(DATA) as u8)
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
