//! The vehicle computer in the loop: the planner as one vehicle of a world simulated
//! elsewhere, with nothing between them but CAN frames on a serial line.
//!
//! The link is serial-line CAN (SLCAN, [`can_gateway::slcan`]) on the board's UART, as a
//! USB-CAN adapter speaks it: Linux `slcand`, python-can's `slcan` interface or a
//! simulator can be the other end. Commands (`O`, `C`, `Sn`, `V`, …) are answered as an
//! adapter answers them; frames are taken only while the channel is open.
//!
//! Each period, in the manner of CANopen's SYNC (the world is the time master):
//! 1. the world sends the vehicle's own state as its sensors measure it, its road and its
//!    reference speed ([`Message::Ego`], from the time master's address); the computer
//!    answers with its V2V state message (its measured pose and speed, its lane, the
//!    lane it changes to and the one it intends, its braking limit and length);
//! 2. the world sends what the vehicle hears on the bus (the others' V2V states), then
//!    the tick ([`Message::Sync`]); on the tick the computer runs the multi-lane planner
//!    (Sec. IV–V) and answers with its command ([`Message::Command`]: v and ω as the f32
//!    the planner computed, and its lanes ℓ, α, β after the step), which the world
//!    integrates (1).
//!
//! The node's time is the world's: the stamp of the last ego state. The planner's
//! v_{t−h} and ω_{t−h} are the command it gave last period (what the world applied),
//! not the measured speed, which the wire rounds to 0.02 m/s; its pose is the measured
//! one, rounded to 0.01 m, and the planner's bus resolution is doubled in position to
//! cover its own rounding as well as the others'. The tick with `last` set ends the run:
//! the node logs its figures (periods, instructions per step in the board's virtual
//! 125 MHz clock, periods over h = 10 ms, fallbacks, frames refused, peak stack) and
//! exits through semihosting with success only if every period was on time and no frame
//! or line was refused.

use crate::board;
use crate::clock::Clock;
use crate::measure;
use crate::uart::Uart;
use can_gateway::slcan::{self, Line, LineBuffer, SlcanError, BELL, CR, MAX_LINE};
use can_gateway::wire::{Command, CommandStatus, Message, POS_RES, SPEED_RES};
use can_gateway::{encode, Frames, Instant, PlainFrame, Reassembler};
use planner_core::{
    BodyLength, BrakeLimit, CostWeights, Duration, LaneObservation, LanePlanner, LanePlannerSlot,
    Other, Params, Pose, Road, VehicleState, WorldView,
};

/// The planner's horizon: 20, or 50 with the `n50` feature.
#[cfg(not(feature = "n50"))]
pub const N: usize = 20;
/// The planner's horizon: 20, or 50 with the `n50` feature.
#[cfg(feature = "n50")]
pub const N: usize = 50;

/// The most neighbours the node tracks: a dense multi-lane road's 32 in range.
pub const NEIGHBOURS: usize = 32;
/// Senders × kinds the reassembler follows: each neighbour's state, and the world's ego
/// state and tick.
const SENDERS: usize = NEIGHBOURS + 2;
/// Lane width of every road (m), SPEC §8.
pub const LANE_WIDTH: f32 = 3.6;
/// A neighbour not heard for this long is dropped from the view. Over the link nothing
/// is lost: only vehicles that left the world fall silent.
const SILENT: Duration = Duration::from_secs(1);
/// The control period's budget in instructions: 10 ms at the virtual 125 MHz.
const PERIOD_INSTRUCTIONS: u64 = 1_250_000;
/// Most stack the node may use, painted: 8 KiB, as the scripted run.
const STACK_BUDGET: usize = 8 * 1024;
/// What the node answers to `V` (hardware and software version, Lawicel style).
const VERSION: &[u8] = b"V0101\r";
/// What the node answers to `N` (its serial number).
const SERIAL: &[u8] = b"NKK01\r";

/// The vehicle's own state as last measured, and what came with it.
#[derive(Debug, Clone, Copy)]
struct Ego {
    lanes: u8,
    state: VehicleState<f32>,
    v_ref: f32,
}

/// What the planner said last: its lane bookkeeping and the command applied since.
#[derive(Debug, Clone, Copy)]
struct Last {
    lane: u8,
    alpha: Option<u8>,
    beta: Option<u8>,
    v: f32,
    omega: f32,
}

/// The run's figures.
#[derive(Debug, Clone, Copy, Default, defmt::Format)]
pub struct Figures {
    /// Ticks answered.
    pub periods: u32,
    /// Steps the planner did not plan itself (fallback or refused input; standing
    /// behind a stopped vehicle, `NoRoom`, and yielding are not counted).
    pub fallbacks: u32,
    /// Steps whose work took more than h.
    pub overruns: u32,
    /// The most instructions one tick's work took (plan and answer).
    pub worst_instructions: u64,
    /// Frames received.
    pub frames: u32,
    /// Frames refused by the codec or the view.
    pub refused: u32,
    /// Lines that were neither a frame nor a command.
    pub bad_lines: u32,
    /// Frames that could not be sent.
    pub lost: u32,
}

/// The node: its link, codec, view and planner bookkeeping (all `const`-constructible,
/// so it lives in `.bss`).
pub struct Node {
    lines: LineBuffer,
    rx: Reassembler<SENDERS>,
    view: WorldView<f32, NEIGHBOURS>,
    others: heapless::Vec<Other<f32>, NEIGHBOURS>,
    open: bool,
    ego: Option<Ego>,
    last: Option<Last>,
    now: Instant,
    /// Alive counters of its states and of its commands.
    counters: (u8, u8),
    /// What its planner did last.
    last_status: CommandStatus,
    /// The run's figures.
    pub figures: Figures,
}

impl Node {
    /// A node that has heard nothing, its channel closed.
    pub const fn new() -> Self {
        Self {
            lines: LineBuffer::new(),
            rx: Reassembler::new(),
            view: WorldView::new(0),
            others: heapless::Vec::new(),
            open: false,
            ego: None,
            last: None,
            now: Instant::from_micros(0),
            counters: (0, 0),
            last_status: CommandStatus::Solved,
            figures: Figures {
                periods: 0,
                fallbacks: 0,
                overruns: 0,
                worst_instructions: 0,
                frames: 0,
                refused: 0,
                bad_lines: 0,
                lost: 0,
            },
        }
    }
}

impl Default for Node {
    fn default() -> Self {
        Self::new()
    }
}

/// A frame's identifier as a number, for the log.
fn raw_id(f: &PlainFrame) -> u32 {
    use embedded_can::{Frame, Id};
    match f.id() {
        Id::Standard(s) => u32::from(s.as_raw()),
        Id::Extended(e) => e.as_raw(),
    }
}

/// What a byte completed.
enum Event {
    /// Nothing yet, or handled.
    None,
    /// An ego state arrived: answer with the V2V state.
    Ego,
    /// A tick: plan and answer with the command; `true` ends the run.
    Tick(u32, bool),
}

static mut NODE: Node = Node::new();
static mut SLOT: LanePlannerSlot<f32, N> = LanePlannerSlot::new();

/// Runs the node until the world's last tick; never returns.
pub fn run() -> ! {
    measure::paint_stack();
    let Some(cp) = cortex_m::Peripherals::take() else {
        board::exit(false)
    };
    // The clock only times the node's work: its time is the world's (the ego states').
    let clock = Clock::start(cp.SYST, Instant::from_micros(0));
    let per_tick = measure::calibrate(&clock);
    defmt::info!(
        "sil: board {=str} ({=str}), N={=usize}, {=u32} instructions per 100 SysTick ticks; SLCAN on UART 0",
        board::MACHINE,
        board::CORE,
        N,
        per_tick
    );
    // SAFETY: the board's UART 0, driven by nothing else.
    let mut uart = unsafe { Uart::new(board::UART0, board::SYSTICK_HZ) };
    // SAFETY: `run` runs once and never returns; these are the only references.
    let node = unsafe { &mut *core::ptr::addr_of_mut!(NODE) };
    let mut slot = Some(unsafe { &mut *core::ptr::addr_of_mut!(SLOT) });
    let mut planner: Option<&mut LanePlanner<f32, N>> = None;
    loop {
        let Some(byte) = uart.read() else { continue };
        match node.take(byte, &mut uart) {
            Event::None => {}
            Event::Ego => {
                // The planner is built once, on the first ego state.
                if let Some(s) = slot.take() {
                    planner = node.start(s);
                }
                node.announce(&mut uart);
            }
            Event::Tick(period, last) => {
                let Some(lp) = planner.as_deref_mut() else {
                    node.figures.refused += 1;
                    continue;
                };
                // Start on a millisecond's boundary: the only interrupt is SysTick's, so
                // `wfi` returns at its next tick. The world sends nothing until the command
                // (no byte can be missed), and the work's SysTick count no longer depends
                // on when the tick arrived: under QEMU's -icount, each run counts the same.
                cortex_m::asm::wfi();
                let t0 = clock.now();
                node.plan(lp, period, &mut uart);
                let ticks = clock.now() - t0;
                node.count(period, ticks * u64::from(per_tick) / 100);
                if last {
                    finish(node)
                }
            }
        }
    }
}

/// Logs the run's figures and exits: success only if every period was on time and
/// nothing was refused or lost.
fn finish(node: &Node) -> ! {
    let f = node.figures;
    let peak = measure::peak_stack();
    defmt::info!("sil: {}", f);
    defmt::info!(
        "sil: {=u32} periods, worst {=u64} instructions per period (h = {=u64}), {=u32} over h; peak stack {=usize} B",
        f.periods,
        f.worst_instructions,
        PERIOD_INSTRUCTIONS,
        f.overruns,
        peak
    );
    let (flash, ram) = measure::footprint();
    defmt::info!(
        "sil: footprint (N={=usize}): flash={=usize} B, static RAM={=usize} B",
        N,
        flash,
        ram
    );
    let ok = f.overruns == 0
        && f.refused == 0
        && f.bad_lines == 0
        && f.lost == 0
        && peak <= STACK_BUDGET;
    board::exit(ok && f.periods > 0)
}

impl Node {
    /// Takes one byte of the line; at a line's end, acts on it.
    fn take(&mut self, byte: u8, uart: &mut Uart) -> Event {
        match self.lines.push::<PlainFrame>(byte) {
            None => Event::None,
            Some(Ok(Line::Command(c))) => {
                self.command(c, uart);
                Event::None
            }
            Some(Ok(Line::Frame(f))) if self.open => self.frame(&f),
            // A frame while closed is dropped, as an adapter drops it.
            Some(Ok(Line::Frame(_))) => Event::None,
            // An empty line is a keep-alive: acknowledged.
            Some(Err(SlcanError::Empty)) => self.reply(uart, &[CR]),
            Some(Err(_)) => {
                self.figures.bad_lines += 1;
                self.reply(uart, &[BELL])
            }
        }
    }

    /// Answers an adapter command.
    fn command(&mut self, c: slcan::Command, uart: &mut Uart) {
        let answer: &[u8] = match c {
            slcan::Command::Open | slcan::Command::ListenOnly => {
                self.open = true;
                &[CR]
            }
            slcan::Command::Close => {
                self.open = false;
                &[CR]
            }
            slcan::Command::Version => VERSION,
            slcan::Command::SerialNumber => SERIAL,
            slcan::Command::Status => b"F00\r",
            slcan::Command::Bitrate(_) | slcan::Command::Timestamps(_) => &[CR],
        };
        self.reply(uart, answer);
    }

    fn reply(&mut self, uart: &mut Uart, bytes: &[u8]) -> Event {
        if uart.write_all(bytes).is_err() {
            self.figures.lost += 1;
        }
        Event::None
    }

    /// Takes a frame into the codec; a whole message into the view or the node.
    #[inline(never)]
    fn frame(&mut self, f: &PlainFrame) -> Event {
        self.figures.frames += 1;
        match self.rx.push::<f32, _>(f, self.now) {
            Ok(None) => Event::None,
            Ok(Some(m)) => self.message(m),
            Err(e) => {
                // The first few, said: a world that speaks another protocol shows at once.
                if self.figures.refused < 4 {
                    defmt::warn!("sil: frame {=u32:08x} refused: {}", raw_id(f), e);
                }
                self.figures.refused += 1;
                Event::None
            }
        }
    }

    fn message(&mut self, m: Message<f32>) -> Event {
        match m {
            // The segment is the world's bookkeeping: the node drives the road it is told.
            Message::Ego {
                lanes,
                state,
                v_ref,
                ..
            } => {
                self.now = state.stamp;
                self.ego = Some(Ego {
                    lanes,
                    state,
                    v_ref,
                });
                Event::Ego
            }
            Message::Sync { period, last } => Event::Tick(period, last),
            Message::State(s) | Message::Located { state: s, .. } => {
                if self.view.update(&s, self.now).is_err() {
                    self.figures.refused += 1;
                }
                Event::None
            }
            // Intersection messages: this node drives roads only.
            _ => Event::None,
        }
    }

    /// Builds the planner on the first ego state: its id is the vehicle's, its lane the
    /// measured one.
    fn start(
        &mut self,
        slot: &'static mut LanePlannerSlot<f32, N>,
    ) -> Option<&'static mut LanePlanner<f32, N>> {
        let ego = self.ego?;
        self.view = WorldView::new(ego.state.id);
        let lp = slot
            .init(Params::table_i(), CostWeights::default(), ego.state.lane)
            .ok()?;
        // The others' rounding, and the node's own pose's (doubled position term).
        lp.set_bus_resolution(2.0 * POS_RES as f32, SPEED_RES as f32)
            .ok()?;
        self.last = Some(Last {
            lane: ego.state.lane,
            alpha: None,
            beta: ego.state.beta,
            v: ego.state.v,
            omega: ego.state.omega,
        });
        Some(lp)
    }

    /// Sends the vehicle's V2V state: its measured pose and speed, its own lanes.
    #[inline(never)]
    fn announce(&mut self, uart: &mut Uart) {
        let (Some(ego), Some(last)) = (self.ego, self.last) else {
            return;
        };
        let params = Params::<f32>::table_i();
        let state = VehicleState {
            lane: last.lane,
            alpha: last.alpha,
            beta: last.beta,
            cooperative: true,
            brake: BrakeLimit::from_mps2(params.brake()),
            length: BodyLength::from_m(params.length()),
            ..ego.state
        };
        self.send(&Message::State(state), uart);
    }

    /// Plans period `period` and sends the command. Not inlined, so that its frame (the
    /// observation, the planner's step below it) is not added to the receive loop's.
    #[inline(never)]
    fn plan(&mut self, lp: &mut LanePlanner<f32, N>, period: u32, uart: &mut Uart) {
        let (Some(ego), Some(last)) = (self.ego, self.last) else {
            return;
        };
        self.view.forget_older_than(self.now, SILENT);
        self.view
            .others(self.now, lp.params().length(), &mut self.others);
        let s = ego.state;
        let obs = LaneObservation {
            pose: Pose {
                x: s.x,
                y: s.y,
                theta: s.theta,
            },
            v_prev: last.v,
            omega_prev: last.omega,
            others: &self.others,
            road: Road {
                lanes: ego.lanes,
                lane_width: LANE_WIDTH,
                end_x: None,
            },
            target_lane: s.beta.unwrap_or(last.lane),
            target: 0.0,
            v_ref: ego.v_ref,
        };
        let cmd = match lp.step(&obs) {
            Ok(c) => {
                self.last = Some(Last {
                    lane: c.lane,
                    alpha: c.alpha,
                    beta: c.beta,
                    v: c.v,
                    omega: c.omega,
                });
                Command {
                    period: period as u16,
                    v: c.v,
                    omega: c.omega,
                    status: CommandStatus::of(&c.status),
                    lane: c.lane,
                    alpha: c.alpha,
                    beta: c.beta,
                }
            }
            Err(_) => {
                let (v, omega) = lp.braking_command(s.theta, last.v);
                self.last = Some(Last { v, omega, ..last });
                Command {
                    period: period as u16,
                    v,
                    omega,
                    status: CommandStatus::Rejected,
                    lane: last.lane,
                    alpha: last.alpha,
                    beta: last.beta,
                }
            }
        };
        // Standing with no room and yielding (20)(21) are the protocol, not failures.
        let protocol = matches!(cmd.status, CommandStatus::NoRoom | CommandStatus::Yield);
        self.last_status = cmd.status;
        if !(cmd.status.planned() || protocol) {
            self.figures.fallbacks += 1;
        }
        self.send(&Message::Command(cmd), uart);
    }

    /// Counts one tick's work of `instructions`.
    fn count(&mut self, period: u32, instructions: u64) {
        let f = &mut self.figures;
        f.periods += 1;
        f.worst_instructions = f.worst_instructions.max(instructions);
        if instructions > PERIOD_INSTRUCTIONS {
            f.overruns += 1;
            defmt::warn!(
                "sil: period {=u32} took {=u64} instructions ({})",
                period,
                instructions,
                self.last_status
            );
        }
    }

    /// Sends `m` from the vehicle's address as SLCAN lines. Not inlined: its buffers
    /// (payload, frames, line) must not sit in the planning frame's stack.
    #[inline(never)]
    fn send(&mut self, m: &Message<f32>, uart: &mut Uart) {
        let Some(ego) = self.ego else { return };
        let sa = ego.state.id as u8;
        let counter = match m {
            Message::Command(_) => &mut self.counters.1,
            _ => &mut self.counters.0,
        };
        *counter = (*counter + 1) % 16;
        let Ok(frames) = encode::<f32, PlainFrame>(m, sa, *counter) else {
            self.figures.lost += 1;
            return;
        };
        self.write_frames(&frames, uart);
    }

    fn write_frames(&mut self, frames: &Frames<PlainFrame>, uart: &mut Uart) {
        let mut line = [0u8; MAX_LINE + 1];
        for f in frames {
            let sent = slcan::encode(f, &mut line)
                .ok()
                .and_then(|n| line.get(..n))
                .map(|l| uart.write_all(l));
            if !matches!(sent, Some(Ok(()))) {
                self.figures.lost += 1;
            }
        }
    }
}
