//! What the world says to a computer in the loop and hears back, each period, in the
//! manner of CANopen's SYNC (the world is the time master):
//!
//! 1. [`Computer::announce`]: the vehicle's measured state, road and reference speed go
//!    out as an `Ego` message from the time master's address; the computer answers with
//!    its V2V state, which the world puts on its bus for the others;
//! 2. [`Computer::command`]: the states the vehicle heard this period are relayed from
//!    their senders' addresses, then the tick; the computer answers with its command,
//!    which the world integrates.
//!
//! A run ends with a tick marked last ([`Computer::finish`]): the firmware logs its
//! figures and exits with its verdict.

use super::{Board, FirmwareError, FirmwareReport, Link};
use can_gateway::wire::{Command, Message, MessageKind, CLOCK_ADDRESS};
use planner_core::VehicleState;
use std::collections::HashMap;
use std::path::Path;
use std::time::Duration;

/// How long a finished image may take to log its figures and exit.
const EXIT_TIMEOUT: Duration = Duration::from_secs(10);

/// What the vehicle's own sensors and route tell its computer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ego {
    /// Its measured state (the wire rounds it: 0.01 m, 0.0125°, 0.02 m/s); `beta` is the
    /// lane its route asks for.
    pub state: VehicleState<f64>,
    /// Lanes of its road.
    pub lanes: u8,
    /// Its reference speed (m/s).
    pub v_ref: f64,
}

/// One vehicle's computer in the loop.
pub struct Computer {
    link: Link,
    id: u16,
    board: Board,
    /// The next tick's number.
    period: u32,
    /// Alive counters per (source address, kind): each sender's messages of a kind
    /// count on, as on a real bus.
    counters: HashMap<(u8, u8), u8>,
    /// It failed to answer once: the lock-step is lost, and its run fails.
    failed: Option<String>,
}

impl Computer {
    /// Starts the image `elf` on `board` as vehicle `id`'s computer, its log into `log`.
    pub fn start(elf: &Path, board: Board, id: u16, log: &Path) -> Result<Self, FirmwareError> {
        Ok(Self {
            link: Link::start(elf, board, log)?,
            id,
            board,
            period: 0,
            counters: HashMap::new(),
            failed: None,
        })
    }

    /// The vehicle's source address.
    fn sa(&self) -> u8 {
        (self.id & 0xFF) as u8
    }

    fn send(&mut self, m: &Message<f64>, sa: u8) -> Result<(), FirmwareError> {
        let c = self.counters.entry((sa, m.kind() as u8)).or_insert(0);
        *c = (*c + 1) % 16;
        let counter = *c;
        self.link.send(m, sa, counter)
    }

    /// Why it failed, if it did.
    pub fn failed(&self) -> Option<&str> {
        self.failed.as_deref()
    }

    /// Tells the computer where the vehicle is; its V2V state for this period.
    pub fn announce(&mut self, ego: &Ego) -> Result<VehicleState<f64>, FirmwareError> {
        self.tell(ego)?;
        self.state()
    }

    /// Relays what the vehicle heard, then the tick (`last` ends the run); its command.
    pub fn command(
        &mut self,
        heard: &[VehicleState<f64>],
        last: bool,
    ) -> Result<Command<f64>, FirmwareError> {
        self.tick(heard, last)?;
        self.answer()
    }

    /// The first half of [`Computer::announce`]: the ego state sent. A world with
    /// several computers tells each before it waits for any, so that their images work
    /// at once.
    pub fn tell(&mut self, ego: &Ego) -> Result<(), FirmwareError> {
        let r = self.alive().and_then(|()| self.send_ego(ego));
        self.note(r)
    }

    /// The second half of [`Computer::announce`]: its V2V state.
    pub fn state(&mut self) -> Result<VehicleState<f64>, FirmwareError> {
        let r = match self
            .alive()
            .and_then(|()| self.link.receive(MessageKind::State, self.sa()))
        {
            Ok(Message::State(s)) => Ok(s),
            Ok(_) => Err(FirmwareError::Timeout("its state")),
            Err(e) => Err(e),
        };
        self.note(r)
    }

    /// The first half of [`Computer::command`]: what it heard and the tick, sent.
    pub fn tick(&mut self, heard: &[VehicleState<f64>], last: bool) -> Result<(), FirmwareError> {
        let r = self.alive().and_then(|()| self.send_tick(heard, last));
        self.note(r)
    }

    /// The second half of [`Computer::command`]: its command for the last tick.
    pub fn answer(&mut self) -> Result<Command<f64>, FirmwareError> {
        let period = self.period.wrapping_sub(1);
        let r = match self
            .alive()
            .and_then(|()| self.link.receive(MessageKind::Command, self.sa()))
        {
            // The answer to that tick, not a late one.
            Ok(Message::Command(c)) if c.period == period as u16 => Ok(c),
            Ok(_) => Err(FirmwareError::Timeout("its command for this period")),
            Err(e) => Err(e),
        };
        self.note(r)
    }

    /// An error once it has failed: the lock-step is lost, and each wait would time out.
    fn alive(&self) -> Result<(), FirmwareError> {
        match self.failed {
            Some(_) => Err(FirmwareError::Timeout(
                "nothing: it stopped answering earlier",
            )),
            None => Ok(()),
        }
    }

    /// `r`, its failure remembered (the first one).
    fn note<T>(&mut self, r: Result<T, FirmwareError>) -> Result<T, FirmwareError> {
        if let (Err(e), None) = (&r, &self.failed) {
            self.failed = Some(e.to_string());
        }
        r
    }

    fn send_ego(&mut self, ego: &Ego) -> Result<(), FirmwareError> {
        self.link.now = ego.state.stamp;
        let m = Message::Ego {
            segment: 0,
            lanes: ego.lanes,
            state: ego.state,
            v_ref: ego.v_ref,
        };
        self.send(&m, CLOCK_ADDRESS)
    }

    fn send_tick(&mut self, heard: &[VehicleState<f64>], last: bool) -> Result<(), FirmwareError> {
        for s in heard {
            self.send(&Message::State(*s), (s.id & 0xFF) as u8)?;
        }
        let period = self.period;
        self.send(&Message::Sync { period, last }, CLOCK_ADDRESS)?;
        self.period += 1;
        Ok(())
    }

    /// The last period (`ego`, nothing heard, the tick marked last), then the image's
    /// exit.
    pub fn finish(mut self, ego: &Ego) -> FirmwareReport {
        let ended = self.failed.is_none()
            && self
                .announce(ego)
                .and_then(|_| self.command(&[], true))
                .is_ok();
        let (vehicle, board, periods) = (self.id, self.board, self.period);
        let log = self.link.log().display().to_string();
        let (rx, tx) = self.link.serial();
        let serial = [rx.display().to_string(), tx.display().to_string()];
        let exit = if ended {
            self.link.wait(EXIT_TIMEOUT)
        } else {
            None
        };
        FirmwareReport {
            vehicle,
            board: board.qemu().0.to_string(),
            periods,
            exit,
            failed: self.failed,
            log,
            serial,
        }
    }
}
