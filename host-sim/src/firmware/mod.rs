//! Vehicle computers in the loop: a vehicle of the world whose computer is the firmware's
//! image (`firmware-example`'s `sil` program) running in QEMU, with nothing between them
//! but CAN frames on a serial line.
//!
//! - [`link`]: one QEMU process and its UART as serial-line CAN (SLCAN) on a local TCP
//!   socket — frames out, frames in, the process's end;
//! - [`affinity`]: each QEMU on one host core, the QEMUs of a run spread over the cores;
//! - [`computer`]: what the world says to the computer and hears back, per period: its
//!   measured state ([`can_gateway::wire::Message::Ego`]) answered with its V2V state, then
//!   what it hears and the tick ([`can_gateway::wire::Message::Sync`]) answered with its
//!   command ([`can_gateway::wire::Message::Command`]).
//!
//! Lock-step and deterministic: the world waits for each answer, and QEMU runs with
//! `-icount shift=3,sleep=off`, so the firmware's work is counted in instructions of a
//! virtual 125 MHz core, never in host time; its commands depend only on the frames it
//! received. The firmware drives roads (the multi-lane planner); junctions are not its.

pub mod affinity;
pub mod computer;
pub mod link;

pub use computer::{Computer, Ego};
pub use link::{Board, Link};

use std::fmt;
use std::path::PathBuf;

/// Which vehicles are computers in the loop, and the image they run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FirmwareSpec {
    /// The firmware's `sil` ELF (built for `board`).
    pub elf: PathBuf,
    /// The QEMU machine it runs on.
    pub board: Board,
    /// The vehicles (ids) whose computers it is.
    pub vehicles: Vec<u16>,
}

/// How a computer in the loop ended.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct FirmwareReport {
    /// The vehicle.
    pub vehicle: u16,
    /// The QEMU machine.
    pub board: String,
    /// Ticks it answered.
    pub periods: u32,
    /// Its exit status: 0 only if every period's work fit h = 10 ms of its virtual clock,
    /// nothing it received was refused and its stack stayed within 8 KiB (`None`: it did
    /// not exit).
    pub exit: Option<i32>,
    /// Why the world stopped hearing from it, if it did.
    pub failed: Option<String>,
    /// Its defmt log, undecoded (`defmt-print -e ELF < LOG` reads it).
    pub log: String,
    /// Its serial line, byte for byte: what it received, then what it sent. The bytes
    /// received are all its inputs: the host's mirror of the node
    /// (`tests/examples/sil_mirror.rs`) replays them and must send the same bytes.
    pub serial: [String; 2],
}

impl FirmwareReport {
    /// Whether the firmware ended well.
    pub fn ok(&self) -> bool {
        self.exit == Some(0)
    }
}

/// Why a computer in the loop could not be run, or stopped answering.
#[derive(Debug)]
#[non_exhaustive]
pub enum FirmwareError {
    /// QEMU could not be started, or its UART socket never opened.
    Start(String),
    /// The serial line failed (a read, a write, the socket).
    Io(std::io::Error),
    /// No answer within the link's timeout.
    Timeout(&'static str),
    /// A message could not be encoded for the wire.
    Encode(can_gateway::EncodeError),
    /// A frame could not be written as a serial-line CAN line.
    Line(can_gateway::slcan::SlcanError),
    /// The firmware's log file could not be made.
    Log(String),
}

impl fmt::Display for FirmwareError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Start(e) => write!(f, "the firmware could not be started: {e}"),
            Self::Io(e) => write!(f, "the firmware's serial line failed: {e}"),
            Self::Timeout(what) => write!(f, "the firmware did not answer (waiting for {what})"),
            Self::Encode(e) => write!(f, "a message could not be encoded: {e}"),
            Self::Line(e) => write!(f, "a frame could not be written as a line: {e}"),
            Self::Log(e) => write!(f, "the firmware's log: {e}"),
        }
    }
}

impl std::error::Error for FirmwareError {}

impl From<std::io::Error> for FirmwareError {
    fn from(e: std::io::Error) -> Self {
        Self::Io(e)
    }
}
