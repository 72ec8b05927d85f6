//! Frame layout, units and resolutions.
//!
//! **Identifiers**: 29-bit extended, laid out like SAE J1939 so that J1939 tools parse
//! them: priority 6 (bits 28–26), data page 0, PDU format 0xFF (broadcast, PDU2), PDU
//! specific = kind code × 16 + frame index, source address = the sender's node id
//! (low byte). A message kind and frame index thus form a PGN 0xFF00 + PS.
//!
//! **Frames**: 8 data bytes. Byte 0: frame index (high nibble) and the message's alive
//! counter (low nibble, 0–15, incremented per message and sender and kind). Bytes 1–7:
//! payload. The last payload byte of a message is its CRC-8 SAE J1850 over the Data ID
//! (the kind code and the source address), the counter and every other payload byte —
//! AUTOSAR E2E in the manner of profile 1. Messages longer than 7 bytes span several
//! frames sent in index order; the receiver reassembles them.
//!
//! **Units** (SAE J2735 BSM resolutions where they fit): speed 0.02 m/s (u16), heading
//! 0.0125° (i16), yaw rate 0.01°/s (i16); positions in road coordinates, x 0.01 m (i32),
//! y 0.01 m (i16), position along an intersection path 0.01 m (u24); times 1 ms (u32: the
//! low 32 bits of the sender's clock in milliseconds, [`planner_core::time`]; they wrap
//! every 49.7 days, and a receiver restores the full instant as the one nearest its own
//! clock, [`crate::codec::restore_millis`]); lanes 4 bits, 15 = none. All little-endian.
//!
//! **Layouts** (where each field sits, byte by byte): [`crate::layout`], the one place
//! they are written; in short:
//!
//! **A vehicle state** (kind 1, 4 frames): id, x, lanes | y, heading, speed, β and flags |
//! yaw rate, stamp, braking limit (0.1 m/s², 0 = not declared) | reserved (zero), CRC.
//!
//! **Networks** add a state with its segment (kind 7, 4 frames: id, segment, lanes, β
//! and flags | x, y | heading, speed, yaw rate | stamp, CRC), a request with its junction
//! (kind 8, 3 frames: id, junction, inlet, outlet, speed | s, arrival | CRC) and an exit
//! with its junction (kind 9, 2 frames); grants come from each junction manager's own
//! address. No field straddles two frames, so a DBC describes every one.
//!
//! **Software in the loop** adds the two messages between a vehicle's computer and the
//! vehicle: its own measured state and reference speed (kind 10, [`Message::Ego`], 4
//! frames: a located state's layout, the road's lane count in its reserved byte, the
//! reference speed in its last frame's spare bytes; only from [`CLOCK_ADDRESS`]) and the computer's command (kind 11,
//! [`Message::Command`], 2 frames: speed f32, status, period | yaw rate f32, lanes, β, CRC;
//! IEEE 754 single precision, so that what the MCU planned is what the plant integrates).
//!
//! **CAN FD**: a whole message in one frame, MAC included when secured. Its identifier's
//! frame index is [`FD_INDEX`] (15; [`FD_SECURED_INDEX`], 14, when the frame carries an
//! authenticator), so that a DBC names plain, secured and classic frames apart. Byte 0:
//! that index (high nibble) and the alive counter; then the message's payload exactly as
//! the classic frames carry it, chunk after chunk (7 bytes per classic frame, CRC last);
//! then, when secured, the trailer of [`crate::secoc`]; then zeros up to the next CAN FD
//! data length ([`fd_len`]: 8, 12, 16, 20, 24, 32, 48 or 64 bytes).
//!
//! **Time master**: a simulated fleet runs in lock-step on one tick per period,
//! [`Message::Sync`] from [`CLOCK_ADDRESS`] (period number u32, end flag u8), protected
//! like every other message.

use planner_core::{BodyLength, BrakeLimit, Instant, VehicleState};

/// J1939 priority of every frame.
pub const PRIORITY: u32 = 6;
/// J1939 PDU format (broadcast).
pub const PDU_FORMAT: u32 = 0xFF;
/// Payload bytes per frame (byte 0 is the header).
pub const CHUNK: usize = 7;
/// The most frames a message spans.
pub const MAX_FRAMES: usize = 4;
/// Frame index of a CAN FD frame carrying a whole message (see the module docs).
pub const FD_INDEX: u8 = 15;
/// Frame index of a CAN FD frame carrying a whole message and its authenticator.
pub const FD_SECURED_INDEX: u8 = 14;
/// The data lengths a CAN FD frame can have beyond 8 bytes (ISO 11898-1 DLC 9–15).
pub const FD_LENGTHS: [usize; 7] = [12, 16, 20, 24, 32, 48, 64];

/// The shortest CAN FD data length that holds `n` bytes, if one does (n ≤ 64).
pub fn fd_len(n: usize) -> Option<usize> {
    if n <= 8 {
        return Some(n);
    }
    FD_LENGTHS.iter().copied().find(|&l| l >= n)
}

/// Source address of a fleet's time master (sends [`Message::Sync`]); vehicles use
/// addresses below it.
pub const CLOCK_ADDRESS: u8 = 0xF0;
/// Source address of an intersection manager (of the first junction of a network): the
/// managers' addresses, [`MANAGER_ADDRESS`]..=[`MANAGER_LAST`], are the only senders whose
/// [`Message::Grant`] and [`Message::Revoke`] a receiver accepts.
pub const MANAGER_ADDRESS: u8 = 0xF1;
/// The last manager address (13 junctions: 0xF1–0xFD; 0xFE is J1939's null address).
pub const MANAGER_LAST: u8 = 0xFD;

/// The source address of junction `j`'s manager, if it has one.
pub fn manager_address(j: usize) -> Option<u8> {
    u8::try_from(j)
        .ok()
        .and_then(|j| MANAGER_ADDRESS.checked_add(j))
        .filter(|&a| a <= MANAGER_LAST)
}
/// "No lane" in a 4-bit lane field.
pub const NO_LANE: u8 = 15;

/// Speed resolution (m/s per bit), SAE J2735.
pub const SPEED_RES: f64 = 0.02;
/// Heading resolution (rad per bit): 0.0125°, SAE J2735.
pub const HEADING_RES: f64 = 0.0125 * core::f64::consts::PI / 180.0;
/// Yaw-rate resolution (rad/s per bit): 0.01°/s, SAE J2735.
pub const YAW_RATE_RES: f64 = 0.01 * core::f64::consts::PI / 180.0;
/// Position resolution (m per bit).
pub const POS_RES: f64 = 0.01;
/// Time resolution (s per bit): times travel as whole milliseconds.
pub const TIME_RES: f64 = 0.001;
/// Largest plausible speed a receiver accepts (m/s): well above any road vehicle's.
pub const SPEED_LIMIT: f64 = 100.0;

/// Message kinds and their codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum MessageKind {
    /// V2V vehicle state (4 frames).
    State = 1,
    /// V2I registration / crossing request with inlet, outlet, arrival (2 frames).
    Request = 2,
    /// I2V grant with a lease (1 frame).
    Grant = 3,
    /// I2V revoke (1 frame).
    Revoke = 4,
    /// V2I exit (1 frame).
    Exit = 5,
    /// Time master's period tick, CANopen-SYNC-style (1 frame).
    Sync = 6,
    /// V2V vehicle state on a network's segment (4 frames).
    Located = 7,
    /// V2I crossing request at a network's junction (3 frames).
    JunctionRequest = 8,
    /// V2I exit from a network's junction (2 frames).
    JunctionExit = 9,
    /// A vehicle's own measured state and reference speed, to its computer (4 frames).
    Ego = 10,
    /// A vehicle computer's command to its actuators (2 frames).
    Command = 11,
}

impl MessageKind {
    /// Frames a message of this kind spans.
    pub fn frames(self) -> usize {
        match self {
            MessageKind::Located | MessageKind::State | MessageKind::Ego => 4,
            MessageKind::JunctionRequest => 3,
            MessageKind::Request | MessageKind::JunctionExit | MessageKind::Command => 2,
            MessageKind::Grant | MessageKind::Revoke | MessageKind::Exit | MessageKind::Sync => 1,
        }
    }
    /// From its code.
    pub fn from_code(c: u8) -> Option<Self> {
        Some(match c {
            1 => MessageKind::State,
            2 => MessageKind::Request,
            3 => MessageKind::Grant,
            4 => MessageKind::Revoke,
            5 => MessageKind::Exit,
            6 => MessageKind::Sync,
            7 => MessageKind::Located,
            8 => MessageKind::JunctionRequest,
            9 => MessageKind::JunctionExit,
            10 => MessageKind::Ego,
            11 => MessageKind::Command,
            _ => return None,
        })
    }
}

/// An intersection track: heading of travel (0 east … 3 south) and lane (0 inner).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TrackWire {
    /// Heading, 0–3.
    pub heading: u8,
    /// Lane, 0–15.
    pub lane: u8,
}

/// A registration / crossing request (V2I).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Request<F> {
    /// The vehicle.
    pub id: u16,
    /// Its inlet.
    pub inlet: TrackWire,
    /// Its outlet.
    pub outlet: TrackWire,
    /// When it entered A_C (sender's clock).
    pub arrival: Instant,
    /// Its position along its route's path (m).
    pub s: F,
    /// Its speed (m/s).
    pub v: F,
    /// Its braking limit, if it declares one. Only [`Message::JunctionRequest`] carries
    /// it; a [`Message::Request`] decodes to `None`.
    pub brake: Option<BrakeLimit>,
    /// Its length, if it declares one (else receivers take it at the longest vehicle
    /// they expect). Only [`Message::JunctionRequest`] carries it.
    pub length: Option<BodyLength>,
}

impl<F> Request<F> {
    /// The same request with its numbers converted by `f`.
    pub fn map<G>(self, f: impl Fn(F) -> G) -> Request<G> {
        Request {
            id: self.id,
            inlet: self.inlet,
            outlet: self.outlet,
            arrival: self.arrival,
            s: f(self.s),
            v: f(self.v),
            brake: self.brake,
            length: self.length,
        }
    }
}

/// What a vehicle computer's planner did in the period a [`Command`] answers: the
/// planner's [`planner_core::StepStatus`] as one byte on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum CommandStatus {
    /// The optimal plan was verified and its first input applied.
    Solved = 0,
    /// The previous plan, shifted and verified, was applied (no solve).
    Reused = 1,
    /// Fallback: the invariant did not hold.
    InvariantViolated = 2,
    /// Fallback with nothing else possible (e.g. standing behind a stopped vehicle): not
    /// a failure.
    NoRoom = 3,
    /// Fallback: the solver stopped without a solution.
    Solver = 4,
    /// Fallback: the plan failed verification against the exact constraints.
    Verification = 5,
    /// Fallback: the Yield Protocol (20)(21).
    Yield = 6,
    /// Fallback: the lane-change step could not be verified on the unicycle model.
    Lateral = 7,
    /// The computer refused its input (e.g. an ego state out of its road) and applied
    /// maximum braking.
    Rejected = 8,
}

impl CommandStatus {
    /// From its code.
    pub fn from_code(c: u8) -> Option<Self> {
        use CommandStatus::*;
        [
            Solved,
            Reused,
            InvariantViolated,
            NoRoom,
            Solver,
            Verification,
            Yield,
            Lateral,
            Rejected,
        ]
        .into_iter()
        .find(|s| *s as u8 == c)
    }

    /// The wire's status of a planner step.
    pub fn of<F>(s: &planner_core::StepStatus<F>) -> Self {
        use planner_core::{FallbackReason as R, StepStatus as S};
        match s {
            S::Solved { .. } => Self::Solved,
            S::Reused { .. } => Self::Reused,
            S::Fallback(R::InvariantViolated) => Self::InvariantViolated,
            S::Fallback(R::NoRoom) => Self::NoRoom,
            S::Fallback(R::Solver(_)) => Self::Solver,
            S::Fallback(R::Yield) => Self::Yield,
            S::Fallback(R::Lateral) => Self::Lateral,
            // Verification, and any reason added later: a failed check.
            _ => Self::Verification,
        }
    }

    /// Whether the planner's own plan was applied (no fallback, no refusal).
    pub fn planned(self) -> bool {
        matches!(self, Self::Solved | Self::Reused)
    }
}

/// A vehicle computer's command for one period ([`Message::Command`]): the speed and yaw
/// rate (1) it applies over the period, exactly as its planner computed them (IEEE 754
/// single precision on the wire, so that a simulator integrates what the MCU planned, bit
/// for bit), its lanes after the step (ℓ, α, β) and what its planner did.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Command<F> {
    /// The period it answers: the low 16 bits of the [`Message::Sync`] tick's number.
    pub period: u16,
    /// Commanded speed v (m/s).
    pub v: F,
    /// Commanded yaw rate ω (rad/s).
    pub omega: F,
    /// What the planner did.
    pub status: CommandStatus,
    /// The lane the planner takes the vehicle to be in.
    pub lane: u8,
    /// The lane it is changing to (α), if any.
    pub alpha: Option<u8>,
    /// The lane it intends to change to (β), if any.
    pub beta: Option<u8>,
}

impl<F> Command<F> {
    /// The same command with its numbers converted by `f`.
    pub fn map<G>(self, f: impl Fn(F) -> G) -> Command<G> {
        Command {
            period: self.period,
            v: f(self.v),
            omega: f(self.omega),
            status: self.status,
            lane: self.lane,
            alpha: self.alpha,
            beta: self.beta,
        }
    }
}

/// Every message the planners exchange.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Message<F> {
    /// Vehicle state (V2V).
    State(VehicleState<F>),
    /// Registration / crossing request (V2I).
    Request(Request<F>),
    /// Permission for `id` until `until` (I2V lease, intersection clock).
    Grant {
        /// The permitted vehicle.
        id: u16,
        /// Lease end.
        until: Instant,
    },
    /// Permission of `id` withdrawn at `at`.
    Revoke {
        /// The vehicle.
        id: u16,
        /// When.
        at: Instant,
    },
    /// `id` left the intersection area at `at`.
    Exit {
        /// The vehicle.
        id: u16,
        /// When.
        at: Instant,
    },
    /// A vehicle state on segment `segment` of a network, in its frame (V2V).
    Located {
        /// The segment (scenario index).
        segment: u16,
        /// The state.
        state: VehicleState<F>,
    },
    /// A crossing request at junction `junction` of a network (V2I).
    JunctionRequest {
        /// The junction (index; its manager sends from [`manager_address`]).
        junction: u8,
        /// The request.
        request: Request<F>,
    },
    /// `id` left junction `junction` of a network at `at`.
    JunctionExit {
        /// The junction.
        junction: u8,
        /// The vehicle.
        id: u16,
        /// When.
        at: Instant,
    },
    /// A vehicle's own state, as its sensors measure it, the road it is on and its
    /// reference speed: what its computer plans from. In simulation the world sends it
    /// from [`CLOCK_ADDRESS`] (software in the loop); `state.beta` is the lane its route
    /// asks for.
    Ego {
        /// The segment (scenario index; 0 on a straight road).
        segment: u16,
        /// The road's lanes (1–14).
        lanes: u8,
        /// The measured state.
        state: VehicleState<F>,
        /// The speed to keep when nothing is in the way (m/s).
        v_ref: F,
    },
    /// A vehicle computer's command for one period, to its actuators (in simulation, to
    /// the world that integrates (1)).
    Command(Command<F>),
    /// The time master's tick: period `period` begins (a simulated fleet's clock, sent by
    /// [`CLOCK_ADDRESS`]; nodes act on it as CANopen nodes act on SYNC).
    Sync {
        /// Period number, increasing by one per tick.
        period: u32,
        /// The run ends: nodes stop after this tick.
        last: bool,
    },
}

impl<F> Message<F> {
    /// The same message with its numbers converted by `f`, e.g. `f64` → `f32` for an
    /// MCU's codec or `f32` → `f64` for a host that mirrors one: the enum grows
    /// (`#[non_exhaustive]`), so a conversion outside this crate could not be written
    /// exhaustively.
    pub fn map<G>(self, f: impl Fn(F) -> G) -> Message<G> {
        match self {
            Message::State(st) => Message::State(st.map(f)),
            Message::Request(q) => Message::Request(q.map(f)),
            Message::Grant { id, until } => Message::Grant { id, until },
            Message::Revoke { id, at } => Message::Revoke { id, at },
            Message::Exit { id, at } => Message::Exit { id, at },
            Message::Located { segment, state } => Message::Located {
                segment,
                state: state.map(f),
            },
            Message::JunctionRequest { junction, request } => Message::JunctionRequest {
                junction,
                request: request.map(f),
            },
            Message::JunctionExit { junction, id, at } => {
                Message::JunctionExit { junction, id, at }
            }
            Message::Sync { period, last } => Message::Sync { period, last },
            Message::Ego {
                segment,
                lanes,
                state,
                v_ref,
            } => Message::Ego {
                segment,
                lanes,
                state: state.map(&f),
                v_ref: f(v_ref),
            },
            Message::Command(c) => Message::Command(c.map(f)),
        }
    }

    /// Its kind.
    pub fn kind(&self) -> MessageKind {
        match self {
            Message::State(_) => MessageKind::State,
            Message::Request(_) => MessageKind::Request,
            Message::Grant { .. } => MessageKind::Grant,
            Message::Revoke { .. } => MessageKind::Revoke,
            Message::Exit { .. } => MessageKind::Exit,
            Message::Sync { .. } => MessageKind::Sync,
            Message::Located { .. } => MessageKind::Located,
            Message::JunctionRequest { .. } => MessageKind::JunctionRequest,
            Message::JunctionExit { .. } => MessageKind::JunctionExit,
            Message::Ego { .. } => MessageKind::Ego,
            Message::Command(_) => MessageKind::Command,
        }
    }
}

/// The 29-bit identifier of frame `index` of a `kind` message from node `sa`.
pub fn frame_id(kind: MessageKind, index: u8, sa: u8) -> u32 {
    let ps = (kind as u32) << 4 | u32::from(index & 0x0F);
    PRIORITY << 26 | PDU_FORMAT << 16 | ps << 8 | u32::from(sa)
}

/// Splits a 29-bit identifier into (kind code, frame index, source address) if it has
/// this protocol's priority, data page and PDU format.
pub fn split_id(raw: u32) -> Option<(u8, u8, u8)> {
    if raw >> 26 != PRIORITY || (raw >> 16) & 0x3FF != PDU_FORMAT {
        return None;
    }
    let ps = ((raw >> 8) & 0xFF) as u8;
    Some((ps >> 4, ps & 0x0F, (raw & 0xFF) as u8))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn managers_have_the_addresses_0xf1_to_0xfd() {
        assert_eq!(manager_address(0), Some(MANAGER_ADDRESS));
        assert_eq!(manager_address(1), Some(0xF2));
        assert_eq!(manager_address(12), Some(MANAGER_LAST));
        assert_eq!(manager_address(13), None);
        assert_eq!(manager_address(300), None);
    }

    #[test]
    fn identifiers_split_back_into_their_fields() {
        let id = frame_id(MessageKind::Located, FD_SECURED_INDEX, 0x2A);
        assert_eq!(id, 0x18FF_7E2A);
        assert_eq!(split_id(id), Some((7, FD_SECURED_INDEX, 0x2A)));
        assert_eq!(split_id(id ^ 1 << 26), None);
        assert_eq!(fd_len(0), Some(0));
        assert_eq!(fd_len(9), Some(12));
        assert_eq!(fd_len(35), Some(48));
        assert_eq!(fd_len(64), Some(64));
        assert_eq!(fd_len(65), None);
    }
}
