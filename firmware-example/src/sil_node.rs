//! The vehicle computer's node, sans I/O: bytes of serial-line CAN in, bytes out, and the
//! multi-lane planner in between. The board's loop (`sil.rs`) feeds it the UART's bytes
//! and times its work; a host feeds it a recorded line (`tests/examples/sil_mirror.rs`)
//! and must get the same bytes back, bit for bit, which is how the firmware's commands
//! in the loop are compared with the host planner's. Nothing here touches a register,
//! a clock or a log: so that both build it from this one file.
//!
//! What the node says and hears, period by period, is in `sil.rs`.

use can_gateway::slcan::{self, Line, LineBuffer, SlcanError, BELL, CR, MAX_LINE};
use can_gateway::wire::{Command, CommandStatus, Message, POS_RES, SPEED_RES};
use can_gateway::{encode, DecodeError, Frames, Instant, PlainFrame, Reassembler};
use planner_core::{
    BodyLength, BrakeLimit, CostWeights, Duration, LaneObservation, LanePlanner, LanePlannerSlot,
    Method, MpcSolver, Other, Params, Pose, Road, Settings, StepStatus, VehicleState, WorldView,
};

/// The speed MPC's Newton steps in a period at horizon `n`: its iteration cap, which is a
/// deadline (`Settings::with_answer_at_cap`: at the cap the iterate is applied if the
/// exact verification of (10) passes, else the certified fallback). A step costs about
/// 2,000 instructions per horizon step on the M4F (100,000 at N = 50), and the rest of a
/// period's work, the lateral QP included, up to REST_INSTRUCTIONS: what is left of h's
/// 1,250,000 instructions, divided.
pub const fn speed_steps(n: usize) -> u32 {
    const BUDGET: usize = 1_250_000;
    const REST_INSTRUCTIONS: usize = 350_000;
    const PER_HORIZON_STEP: usize = 2_000;
    let steps = (BUDGET - REST_INSTRUCTIONS) / (PER_HORIZON_STEP * n);
    if steps > 60 {
        60
    } else {
        steps as u32
    }
}

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
/// What the node answers to `V` (hardware and software version, Lawicel style).
const VERSION: &[u8] = b"V0101\r";
/// What the node answers to `N` (its serial number).
const SERIAL: &[u8] = b"NKK01\r";

/// Where the node's bytes go: the board's UART, or a host's buffer.
pub trait Port {
    /// Sends `bytes` in order; `Err` if they could not all be sent.
    fn send(&mut self, bytes: &[u8]) -> Result<(), Lost>;
}

/// Bytes that could not be sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lost;

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
#[derive(Debug, Clone, Copy, Default)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
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
    /// The most neighbours the planner saw at once (the view holds [`NEIGHBOURS`]).
    pub neighbours: u32,
    /// Steps whose speed plan was the solver's iterate at its deadline ([`speed_steps`]),
    /// verified and applied.
    pub capped: u32,
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
    pub last_status: CommandStatus,
    /// Its last step's solver iterations: the speed MPC's (0 if it did not solve) and the
    /// lateral QP's.
    pub last_iterations: (u32, u32),
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
            last_iterations: (0, 0),
            figures: Figures {
                periods: 0,
                fallbacks: 0,
                overruns: 0,
                worst_instructions: 0,
                frames: 0,
                refused: 0,
                bad_lines: 0,
                lost: 0,
                neighbours: 0,
                capped: 0,
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
pub enum Event {
    /// Nothing yet, or handled.
    None,
    /// An ego state arrived: build the planner if it is not, and answer with the V2V
    /// state ([`Node::announce`]).
    Ego,
    /// A tick: plan and answer with the command ([`Node::plan`]); `true` ends the run.
    Tick(u32, bool),
    /// A frame (this identifier) the codec refused, for the log; counted already.
    Refused(u32, DecodeError),
}

impl Node {
    /// Takes one byte of the line; at a line's end, acts on it.
    pub fn take(&mut self, byte: u8, port: &mut impl Port) -> Event {
        match self.lines.push::<PlainFrame>(byte) {
            None => Event::None,
            Some(Ok(Line::Command(c))) => {
                self.command(c, port);
                Event::None
            }
            Some(Ok(Line::Frame(f))) if self.open => self.frame(&f),
            // A frame while closed is dropped, as an adapter drops it.
            Some(Ok(Line::Frame(_))) => Event::None,
            // An empty line is a keep-alive: acknowledged.
            Some(Err(SlcanError::Empty)) => self.reply(port, &[CR]),
            Some(Err(_)) => {
                self.figures.bad_lines += 1;
                self.reply(port, &[BELL])
            }
        }
    }

    /// Answers an adapter command.
    fn command(&mut self, c: slcan::Command, port: &mut impl Port) {
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
        self.reply(port, answer);
    }

    fn reply(&mut self, port: &mut impl Port, bytes: &[u8]) -> Event {
        if port.send(bytes).is_err() {
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
                self.figures.refused += 1;
                Event::Refused(raw_id(f), e)
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
    pub fn start<'a, const N: usize>(
        &mut self,
        slot: &'a mut LanePlannerSlot<f32, N>,
    ) -> Option<&'a mut LanePlanner<f32, N>> {
        let ego = self.ego?;
        self.view = WorldView::new(ego.state.id);
        let lp = slot
            .init(Params::table_i(), CostWeights::default(), ego.state.lane)
            .ok()?;
        // The others' rounding, and the node's own pose's (doubled position term).
        lp.set_bus_resolution(2.0 * POS_RES as f32, SPEED_RES as f32)
            .ok()?;
        // A period has a deadline: after a fallback the speed MPC starts cold, which
        // bounds the worst solve better than the braking plan's vertex does.
        lp.set_warm_from_fallback(false);
        // and its cold starts begin with multipliers of the cost gradient's size, which
        // at N = 50 halves the iterations of a start from standing; its iteration cap is
        // a deadline (`speed_steps`).
        let settings = Settings::default()
            .with_scaled_cold_start(true)
            .with_max_iter(speed_steps(N))
            .ok()?
            .with_answer_at_cap(true);
        lp.set_solver_settings(settings);
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
    pub fn announce(&mut self, port: &mut impl Port) {
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
        self.send(&Message::State(state), port);
    }

    /// Plans period `period` and sends the command. Not inlined, so that its frame (the
    /// observation, the planner's step below it) is not added to the receive loop's.
    #[inline(never)]
    pub fn plan<const N: usize, S: MpcSolver<f32, N>>(
        &mut self,
        lp: &mut LanePlanner<f32, N, S>,
        period: u32,
        port: &mut impl Port,
    ) {
        let (Some(ego), Some(last)) = (self.ego, self.last) else {
            return;
        };
        self.view.forget_older_than(self.now, SILENT);
        self.view
            .others(self.now, lp.params().length(), &mut self.others);
        let seen = u32::try_from(self.others.len()).unwrap_or(u32::MAX);
        self.figures.neighbours = self.figures.neighbours.max(seen);
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
                let speed = match c.status {
                    StepStatus::Solved { iterations, method } => {
                        if method == Method::Capped {
                            self.figures.capped += 1;
                        }
                        iterations
                    }
                    _ => 0,
                };
                self.last_iterations = (speed, c.lateral_iterations);
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
                self.last_iterations = (0, 0);
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
        self.send(&Message::Command(cmd), port);
    }

    /// Sends `m` from the vehicle's address as SLCAN lines. Not inlined: its buffers
    /// (payload, frames, line) must not sit in the planning frame's stack.
    #[inline(never)]
    fn send(&mut self, m: &Message<f32>, port: &mut impl Port) {
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
        self.write_frames(&frames, port);
    }

    fn write_frames(&mut self, frames: &Frames<PlainFrame>, port: &mut impl Port) {
        let mut line = [0u8; MAX_LINE + 1];
        for f in frames {
            let sent = slcan::encode(f, &mut line)
                .ok()
                .and_then(|n| line.get(..n))
                .map(|l| port.send(l));
            if !matches!(sent, Some(Ok(()))) {
                self.figures.lost += 1;
            }
        }
    }
}
