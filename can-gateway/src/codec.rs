//! Encoding messages into frames, and reassembling frames into messages.
//!
//! The decoder is total: every input frame yields `Ok(None)` (part of a message stored),
//! `Ok(Some(message))` (a whole, verified message) or a typed [`DecodeError`], and a
//! frame that yields an error leaves the reassembler exactly as it was.

use crate::crc;
use crate::secoc::{self, AuthError, FreshnessRx, Key, KeyStore, TRAILER_LEN};
use crate::wire::{
    fd_len, frame_id, split_id, Message, MessageKind, Request, TrackWire, CHUNK, CLOCK_ADDRESS,
    FD_INDEX, FD_SECURED_INDEX, HEADING_RES, MANAGER_ADDRESS, MANAGER_LAST, MAX_FRAMES, NO_LANE,
    POS_RES, SPEED_LIMIT, SPEED_RES, YAW_RATE_RES,
};
use embedded_can::{ExtendedId, Frame, Id};
use heapless::Vec;
use planner_core::{Instant, Real, VehicleState};

/// The frames of one message.
pub type Frames<Fr> = Vec<Fr, MAX_FRAMES>;

/// Which field could not be encoded or was implausible on decoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Field {
    /// x.
    X,
    /// y.
    Y,
    /// Heading.
    Heading,
    /// Speed.
    Speed,
    /// Yaw rate.
    YawRate,
    /// A lane.
    Lane,
    /// A position along a path.
    PathPosition,
    /// A track's heading.
    TrackHeading,
    /// A flag byte other than 0 or 1, or an undefined flag bit set.
    Flag,
}

/// State message, byte 13, high nibble: the sender does not cooperate (a scripted or
/// legacy vehicle: it neither hears intentions nor yields).
const NOT_COOPERATIVE: u8 = 0x10;

/// Why a message could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum EncodeError {
    /// A value is NaN, infinite or outside what its field can carry.
    OutOfRange(Field),
    /// The frame type refused the identifier or data (never for a conforming type).
    Frame,
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::OutOfRange(..) => write!(
                f,
                "a value is NaN, infinite or outside what its field can carry ({self:?})"
            ),
            Self::Frame => f.write_str(
                "the frame type refused the identifier or data (never for a conforming type)",
            ),
        }
    }
}

impl core::error::Error for EncodeError {}

/// Why a frame was rejected (the reassembler is unchanged).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum DecodeError {
    /// A standard (11-bit) identifier or a remote frame: not ours.
    NotOurs,
    /// Extended identifier outside this protocol (priority, data page, PDU format).
    ForeignId,
    /// Unknown message kind code.
    UnknownKind(u8),
    /// The frame index is not below the kind's frame count.
    BadFrameIndex,
    /// Not 8 data bytes (a classic frame), not the length of its kind's CAN FD frame, or
    /// padding that is not zero.
    BadLength,
    /// The header's frame index differs from the identifier's.
    HeaderMismatch,
    /// A continuation frame without its message's first frame, or with another alive
    /// counter, or out of order.
    OutOfSequence,
    /// The message CRC does not match.
    Crc,
    /// A field is outside its plausible range.
    OutOfRange(Field),
    /// The sender's address differs from the id in the message.
    SenderMismatch,
    /// Same alive counter as the last accepted message of this sender and kind.
    Duplicate,
    /// Time stamp not newer than the last accepted state of this sender.
    Stale,
    /// The reassembler tracks as many senders as it can hold.
    Full,
    /// A secured message's authenticator was refused ([`crate::secoc`]).
    Auth(AuthError),
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotOurs => f.write_str("a standard (11-bit) identifier or a remote frame: not ours"),
            Self::ForeignId => f.write_str("extended identifier outside this protocol (priority, data page, PDU format)"),
            Self::UnknownKind(..) => write!(f, "unknown message kind code ({self:?})"),
            Self::BadFrameIndex => f.write_str("the frame index is not below the kind's frame count"),
            Self::BadLength => f.write_str("not 8 data bytes (a classic frame), not the length of its kind's CAN FD frame, or padding that is not zero"),
            Self::HeaderMismatch => f.write_str("the header's frame index differs from the identifier's"),
            Self::OutOfSequence => f.write_str("a continuation frame without its message's first frame, or with another alive counter, or out of order"),
            Self::Crc => f.write_str("the message CRC does not match"),
            Self::OutOfRange(..) => write!(f, "a field is outside its plausible range ({self:?})"),
            Self::SenderMismatch => f.write_str("the sender's address differs from the id in the message"),
            Self::Duplicate => f.write_str("same alive counter as the last accepted message of this sender and kind"),
            Self::Stale => f.write_str("time stamp not newer than the last accepted state of this sender"),
            Self::Full => f.write_str("the reassembler tracks as many senders as it can hold"),
            Self::Auth(e) => write!(f, "a secured message's authenticator was refused: {e}"),
        }
    }
}

impl core::error::Error for DecodeError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Auth(e) => Some(e),
            _ => None,
        }
    }
}

fn q<F: Real>(x: F, res: f64, lo: f64, hi: f64, field: Field) -> Result<i64, EncodeError> {
    let v = x.to_f64() / res;
    if !(v.is_finite() && v >= lo && v <= hi) {
        return Err(EncodeError::OutOfRange(field));
    }
    // Round half away from zero without std.
    Ok(if v >= 0.0 {
        (v + 0.5) as i64
    } else {
        (v - 0.5) as i64
    })
}

fn lane_nibble(l: Option<u8>) -> Result<u8, EncodeError> {
    match l {
        None => Ok(NO_LANE),
        Some(x) if x < NO_LANE => Ok(x),
        Some(_) => Err(EncodeError::OutOfRange(Field::Lane)),
    }
}

/// A time as the wire carries it: the low 32 bits of its milliseconds ([`crate::wire`]).
fn time(t: Instant) -> u32 {
    t.as_millis() as u32
}

/// A track as its byte: heading in the low nibble, lane in the high one.
fn track(t: TrackWire) -> Result<u8, EncodeError> {
    if t.heading < 4 && t.lane < 16 {
        Ok(t.heading | t.lane << 4)
    } else {
        Err(EncodeError::OutOfRange(Field::TrackHeading))
    }
}

/// A position along a path, 0.01 m in 24 bits.
fn path_position<F: Real>(s: F) -> Result<u32, EncodeError> {
    Ok(q(
        s,
        POS_RES,
        0.0,
        f64::from(0xFF_FFFFu32),
        Field::PathPosition,
    )? as u32)
}

/// A state's fields, quantized (the same for [`Message::State`] and
/// [`Message::Located`]; only their places differ).
struct StateWire {
    x: i32,
    y: i16,
    heading: i16,
    speed: u16,
    yaw: i16,
    lanes: u8,
    beta_flags: u8,
    stamp: u32,
    /// The braking limit in tenths of m/s² (0: not declared).
    brake: u8,
}

impl StateWire {
    fn of<F: Real>(s: &VehicleState<F>) -> Result<Self, EncodeError> {
        let pi = core::f64::consts::PI;
        let th = s.theta.to_f64();
        // Wrap into [−π, π) so any heading fits the i16 field (π itself goes out as −π).
        let th = th - 2.0 * pi * libm_floor((th + pi) / (2.0 * pi));
        // β in the low nibble; flags in the high one (bit 4: does not cooperate).
        let flags = if s.cooperative { 0 } else { NOT_COOPERATIVE };
        Ok(Self {
            x: q(
                s.x,
                POS_RES,
                f64::from(i32::MIN),
                f64::from(i32::MAX),
                Field::X,
            )? as i32,
            y: q(s.y, POS_RES, -32768.0, 32767.0, Field::Y)? as i16,
            heading: q(
                F::from_f64(th),
                HEADING_RES,
                -32768.0,
                32767.0,
                Field::Heading,
            )? as i16,
            speed: q(s.v, SPEED_RES, 0.0, 65535.0, Field::Speed)? as u16,
            yaw: q(s.omega, YAW_RATE_RES, -32768.0, 32767.0, Field::YawRate)? as i16,
            lanes: lane_nibble(Some(s.lane))? | lane_nibble(s.alpha)? << 4,
            beta_flags: lane_nibble(s.beta)? | flags,
            stamp: time(s.stamp),
            brake: s.brake.map_or(0, planner_core::BrakeLimit::tenths),
        })
    }

    /// The state of vehicle `id` from these fields, if plausible; its stamp restored as
    /// the instant nearest `now`.
    fn state<F: Real>(&self, id: u16, now: Instant) -> Result<VehicleState<F>, DecodeError> {
        let f = |x: f64| F::from_f64(x);
        let v = f64::from(self.speed) * SPEED_RES;
        if v > SPEED_LIMIT {
            return Err(DecodeError::OutOfRange(Field::Speed));
        }
        let own = self.lanes & 0x0F;
        if own == NO_LANE {
            return Err(DecodeError::OutOfRange(Field::Lane));
        }
        // Flags: only "does not cooperate" is defined; the rest must be clear.
        if self.beta_flags & 0xF0 & !NOT_COOPERATIVE != 0 {
            return Err(DecodeError::OutOfRange(Field::Flag));
        }
        let th = f64::from(self.heading) * HEADING_RES;
        if th.abs() > core::f64::consts::PI + HEADING_RES {
            return Err(DecodeError::OutOfRange(Field::Heading));
        }
        Ok(VehicleState {
            id,
            x: f(f64::from(self.x) * POS_RES),
            y: f(f64::from(self.y) * POS_RES),
            theta: f(th),
            v: f(v),
            omega: f(f64::from(self.yaw) * YAW_RATE_RES),
            lane: own,
            alpha: lane(self.lanes >> 4),
            beta: lane(self.beta_flags & 0x0F),
            stamp: restore_millis(self.stamp, now),
            cooperative: self.beta_flags & NOT_COOPERATIVE == 0,
            brake: planner_core::BrakeLimit::from_tenths(self.brake),
        })
    }
}

/// The payload bytes of a message (without CRC), and their length.
fn payload<F: Real>(m: &Message<F>) -> Result<([u8; MAX_FRAMES * CHUNK], usize), EncodeError> {
    let mut b = [0u8; MAX_FRAMES * CHUNK];
    let mut w = Writer { b: &mut b, at: 0 };
    match m {
        Message::State(s) => {
            // Frame 0: id, x, lanes | 1: y, heading, speed, β and flags | 2: yaw rate,
            // stamp, braking limit | 3: reserved (zero), CRC (no field straddles two
            // frames). The braking limit is what lets a follower credit the sender with
            // its least travel (the leader-aware invariant); it costs a fourth classic
            // frame, and nothing on CAN FD beyond the next frame length.
            let q = StateWire::of(s)?;
            w.put(&s.id.to_le_bytes());
            w.put(&q.x.to_le_bytes());
            w.put(&[q.lanes]);
            w.put(&q.y.to_le_bytes());
            w.put(&q.heading.to_le_bytes());
            w.put(&q.speed.to_le_bytes());
            w.put(&[q.beta_flags]);
            w.put(&q.yaw.to_le_bytes());
            w.put(&q.stamp.to_le_bytes());
            w.put(&[q.brake]);
        }
        Message::Located { segment, state: s } => {
            // Frame 0: id, segment, lanes, β and flags, braking limit | 1: x, y | 2:
            // heading, speed, yaw rate | 3: stamp, CRC (padding keeps every field in one
            // frame). The braking limit took frame 0's padding byte: 0, as an older
            // sender wrote it, reads as "not declared".
            let q = StateWire::of(s)?;
            w.put(&s.id.to_le_bytes());
            w.put(&segment.to_le_bytes());
            w.put(&[q.lanes, q.beta_flags, q.brake]);
            w.put(&q.x.to_le_bytes());
            w.put(&q.y.to_le_bytes());
            w.put(&[0]);
            w.put(&q.heading.to_le_bytes());
            w.put(&q.speed.to_le_bytes());
            w.put(&q.yaw.to_le_bytes());
            w.put(&[0]);
            w.put(&q.stamp.to_le_bytes());
        }
        Message::JunctionRequest { junction, request } => {
            // Frame 0: id, junction, inlet, outlet, speed | 1: s, arrival | 2: CRC.
            let r = request;
            w.put(&r.id.to_le_bytes());
            w.put(&[*junction, track(r.inlet)?, track(r.outlet)?]);
            w.put(&(q(r.v, SPEED_RES, 0.0, 65535.0, Field::Speed)? as u16).to_le_bytes());
            w.put(
                path_position(r.s)?
                    .to_le_bytes()
                    .get(..3)
                    .unwrap_or(&[0, 0, 0]),
            );
            w.put(&time(r.arrival).to_le_bytes());
        }
        Message::JunctionExit { junction, id, at } => {
            // Frame 0: id, junction, time | 1: CRC.
            w.put(&id.to_le_bytes());
            w.put(&[*junction]);
            w.put(&time(*at).to_le_bytes());
        }
        Message::Request(r) => {
            // Frame 0: id, inlet, outlet, s; frame 1: arrival, speed, CRC.
            w.put(&r.id.to_le_bytes());
            w.put(&[track(r.inlet)?, track(r.outlet)?]);
            w.put(
                path_position(r.s)?
                    .to_le_bytes()
                    .get(..3)
                    .unwrap_or(&[0, 0, 0]),
            );
            w.put(&time(r.arrival).to_le_bytes());
            w.put(&(q(r.v, SPEED_RES, 0.0, 65535.0, Field::Speed)? as u16).to_le_bytes());
        }
        Message::Grant { id, until: t }
        | Message::Revoke { id, at: t }
        | Message::Exit { id, at: t } => {
            w.put(&id.to_le_bytes());
            w.put(&time(*t).to_le_bytes());
        }
        Message::Sync { period, last } => {
            w.put(&period.to_le_bytes());
            w.put(&[u8::from(*last)]);
        }
    }
    let n = w.at;
    Ok((b, n))
}

fn libm_floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

struct Writer<'a> {
    b: &'a mut [u8; MAX_FRAMES * CHUNK],
    at: usize,
}

impl Writer<'_> {
    fn put(&mut self, bytes: &[u8]) {
        for &x in bytes {
            if let Some(slot) = self.b.get_mut(self.at) {
                *slot = x;
            }
            self.at += 1;
        }
    }
}

/// The E2E CRC of a message: Data ID (kind code, source address), counter, payload.
fn message_crc(kind: MessageKind, sa: u8, counter: u8, payload: &[u8]) -> u8 {
    let c = crc::update(crc::INIT, &[kind as u8, sa, counter & 0x0F]);
    crc::finish(crc::update(c, payload))
}

/// The message's payload chunks as the frames carry them: payload, zero padding, and the
/// CRC in the last byte of the last chunk.
fn protected<F: Real>(
    msg: &Message<F>,
    sa: u8,
    counter: u8,
) -> Result<[u8; MAX_FRAMES * CHUNK], EncodeError> {
    let kind = msg.kind();
    let (mut bytes, _) = payload(msg)?;
    let total = kind.frames() * CHUNK;
    let crc = message_crc(kind, sa, counter, bytes.get(..total - 1).unwrap_or(&[]));
    if let Some(last) = bytes.get_mut(total - 1) {
        *last = crc;
    }
    Ok(bytes)
}

/// Encodes `msg` into one CAN FD frame ([`crate::wire`]: index [`FD_INDEX`], the header,
/// the payload chunks back to back, zero padding to a CAN FD length). `Fr` must take
/// data beyond 8 bytes (e.g. [`crate::FdFrame`]), else [`EncodeError::Frame`].
pub fn encode_fd<F: Real, Fr: Frame>(
    msg: &Message<F>,
    sa: u8,
    counter: u8,
) -> Result<Fr, EncodeError> {
    fd_frame(msg, sa, counter, None)
}

/// Encodes `msg` into one CAN FD frame with its authenticator: index
/// [`FD_SECURED_INDEX`], the header, the payload chunks, then the trailer of
/// [`crate::secoc`] over the same bytes as [`encode_secured`]'s, zero padding.
pub fn encode_fd_secured<F: Real, Fr: Frame>(
    msg: &Message<F>,
    sa: u8,
    counter: u8,
    key: &Key,
    fv: u64,
) -> Result<Fr, EncodeError> {
    fd_frame(msg, sa, counter, Some((key, fv)))
}

/// The frame of [`encode_fd`] or, with a key, [`encode_fd_secured`]. The longest, a
/// secured located state, takes 1 + 28 + 6 = 35 bytes: a 48-byte frame (`fd::` tests
/// check every kind's length).
fn fd_frame<F: Real, Fr: Frame>(
    msg: &Message<F>,
    sa: u8,
    counter: u8,
    secured: Option<(&Key, u64)>,
) -> Result<Fr, EncodeError> {
    let kind = msg.kind();
    let bytes = protected(msg, sa, counter)?;
    let body = bytes.get(..kind.frames() * CHUNK).unwrap_or(&[]);
    let index = if secured.is_some() {
        FD_SECURED_INDEX
    } else {
        FD_INDEX
    };
    let mut data = [0u8; 64];
    let mut w = 0;
    for b in core::iter::once(index << 4 | (counter & 0x0F)).chain(body.iter().copied()) {
        if let Some(slot) = data.get_mut(w) {
            *slot = b;
        }
        w += 1;
    }
    if let Some((key, fv)) = secured {
        let t = secoc::trailer(key, secoc::data_id(kind as u8, sa), counter, body, fv);
        if let Some(dst) = data.get_mut(w..w + TRAILER_LEN) {
            dst.copy_from_slice(&t);
        }
        w += TRAILER_LEN;
    }
    let len = fd_len(w).ok_or(EncodeError::Frame)?;
    let id = ExtendedId::new(frame_id(kind, index, sa)).ok_or(EncodeError::Frame)?;
    Fr::new(Id::Extended(id), data.get(..len).unwrap_or(&[])).ok_or(EncodeError::Frame)
}

/// Encodes `msg`, sent by node `sa` with alive counter `counter` (taken mod 16), into
/// its frames.
pub fn encode<F: Real, Fr: Frame>(
    msg: &Message<F>,
    sa: u8,
    counter: u8,
) -> Result<Frames<Fr>, EncodeError> {
    let kind = msg.kind();
    let bytes = protected(msg, sa, counter)?;
    let mut out = Frames::new();
    for i in 0..kind.frames() {
        let mut data = [0u8; 8];
        data[0] = (i as u8) << 4 | (counter & 0x0F);
        if let (Some(dst), Some(src)) = (data.get_mut(1..), bytes.get(i * CHUNK..(i + 1) * CHUNK)) {
            dst.copy_from_slice(src);
        }
        let id = ExtendedId::new(frame_id(kind, i as u8, sa)).ok_or(EncodeError::Frame)?;
        let f = Fr::new(Id::Extended(id), &data).ok_or(EncodeError::Frame)?;
        out.push(f).map_err(|_| EncodeError::Frame)?;
    }
    Ok(out)
}

/// The frames of a secured message: the message's frames, then its authenticator frame.
pub type SecuredFrames<Fr> = Vec<Fr, { MAX_FRAMES + 1 }>;

/// Encodes `msg` as [`encode`] does and appends the authenticator frame: index = the
/// kind's frame count, the same alive counter, then the trailer of [`crate::secoc`] (the
/// low 16 bits of `fv`, the truncated AES-128-CMAC under `key` over the Data ID, counter,
/// the message frames' 7-byte payloads and `fv`), zero-padded to 8 bytes.
pub fn encode_secured<F: Real, Fr: Frame>(
    msg: &Message<F>,
    sa: u8,
    counter: u8,
    key: &Key,
    fv: u64,
) -> Result<SecuredFrames<Fr>, EncodeError> {
    let kind = msg.kind();
    let plain: Frames<Fr> = encode(msg, sa, counter)?;
    let mut bytes = [0u8; MAX_FRAMES * CHUNK];
    for (i, f) in plain.iter().enumerate() {
        if let (Some(dst), Some(src)) =
            (bytes.get_mut(i * CHUNK..(i + 1) * CHUNK), f.data().get(1..))
        {
            dst.copy_from_slice(src);
        }
    }
    let body = bytes.get(..kind.frames() * CHUNK).unwrap_or(&[]);
    let t = secoc::trailer(key, secoc::data_id(kind as u8, sa), counter, body, fv);
    let index = kind.frames() as u8;
    let mut data = [0u8; 8];
    data[0] = index << 4 | (counter & 0x0F);
    if let Some(dst) = data.get_mut(1..1 + TRAILER_LEN) {
        dst.copy_from_slice(&t);
    }
    let mut out = SecuredFrames::new();
    for f in plain {
        out.push(f).map_err(|_| EncodeError::Frame)?;
    }
    let id = ExtendedId::new(frame_id(kind, index, sa)).ok_or(EncodeError::Frame)?;
    let f = Fr::new(Id::Extended(id), &data).ok_or(EncodeError::Frame)?;
    out.push(f).map_err(|_| EncodeError::Frame)?;
    Ok(out)
}

/// What a secured receiver verifies with: the senders' keys and its freshness record
/// (its clock is the `now` of [`Reassembler::push_secured`]).
pub struct Verifier<'a, const K: usize, const R: usize> {
    /// Keys by source address.
    pub keys: &'a KeyStore<K>,
    /// The last accepted freshness per sender and kind.
    pub freshness: &'a mut FreshnessRx<R>,
}

/// Reassembly and acceptance state for one sender and kind.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Slot {
    sa: u8,
    kind: MessageKind,
    /// Counter of the message being reassembled and frames seen (bit i = frame i).
    partial: Option<(u8, u8)>,
    bytes: [u8; MAX_FRAMES * CHUNK],
    /// Counter of the last accepted message.
    last_counter: Option<u8>,
    /// Stamp of the last accepted state (the wire's ms), or period of the last tick.
    last_stamp: Option<u32>,
}

/// Reassembles frames into verified messages, for up to `CAP` (sender, kind) pairs.
///
/// # Examples
///
/// A state sent as classic CAN frames and taken back in, as a receiving node does:
///
/// ```
/// use can_gateway::{encode, Frames, Instant, Message, PlainFrame, Reassembler};
/// use planner_core::VehicleState;
///
/// let now = Instant::from_millis(1_000);
/// let state = VehicleState {
///     id: 7, x: 120.25f32, y: 1.8, theta: 0.0, v: 13.9, omega: 0.0, lane: 0,
///     alpha: None, beta: None, stamp: now, cooperative: true, brake: None,
/// };
/// // Source address 7, E2E counter 0.
/// let frames: Frames<PlainFrame> = encode(&Message::State(state), 7, 0)?;
/// let mut rx = Reassembler::<4>::new();
/// let mut got = None;
/// for f in &frames {
///     if let Some(m) = rx.push::<f32, _>(f, now)? {
///         got = Some(m);
///     }
/// }
/// let Some(Message::State(s)) = got else { panic!("one whole message") };
/// // Quantised on the wire: within half a step (0.01 m, 0.02 m/s).
/// assert!((s.x - 120.25).abs() <= 0.005 && (s.v - 13.9).abs() <= 0.01);
/// # Ok::<(), Box<dyn core::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct Reassembler<const CAP: usize> {
    slots: Vec<Slot, CAP>,
}

impl<const CAP: usize> Default for Reassembler<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

fn rd_u16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([
        b.get(at).copied().unwrap_or(0),
        b.get(at + 1).copied().unwrap_or(0),
    ])
}
fn rd_u32(b: &[u8], at: usize) -> u32 {
    u32::from(rd_u16(b, at)) | u32::from(rd_u16(b, at + 2)) << 16
}

impl<const CAP: usize> Reassembler<CAP> {
    /// An empty reassembler (`const`: a `static` can hold one, off the stack).
    pub const fn new() -> Self {
        Self { slots: Vec::new() }
    }

    /// Takes one frame received at `now` (the receiver's clock): the times in a message
    /// it completes are restored, from the wire's low 32 bits of milliseconds, as the
    /// instants nearest `now` ([`restore_millis`]).
    pub fn push<F: Real, Fr: Frame>(
        &mut self,
        frame: &Fr,
        now: Instant,
    ) -> Result<Option<Message<F>>, DecodeError> {
        self.take::<F, Fr, 0, 0>(frame, now, None)
    }

    /// Takes one frame of a secured stream received at `now`: a message is accepted only
    /// after its authenticator frame (see [`encode_secured`]) verifies under `v` (its
    /// freshness checked against `now`); until then, and on any error, nothing is
    /// accepted and nothing recorded.
    pub fn push_secured<F: Real, Fr: Frame, const K: usize, const R: usize>(
        &mut self,
        frame: &Fr,
        now: Instant,
        v: Verifier<'_, K, R>,
    ) -> Result<Option<Message<F>>, DecodeError> {
        self.take(frame, now, Some(v))
    }

    fn take<F: Real, Fr: Frame, const K: usize, const R: usize>(
        &mut self,
        frame: &Fr,
        now: Instant,
        auth: Option<Verifier<'_, K, R>>,
    ) -> Result<Option<Message<F>>, DecodeError> {
        let raw = match frame.id() {
            Id::Extended(e) if !frame.is_remote_frame() => e.as_raw(),
            _ => return Err(DecodeError::NotOurs),
        };
        let (code, index, sa) = split_id(raw).ok_or(DecodeError::ForeignId)?;
        let kind = MessageKind::from_code(code).ok_or(DecodeError::UnknownKind(code))?;
        // Work on a copy: an error must leave the reassembler unchanged.
        let pos = self.slots.iter().position(|s| s.sa == sa && s.kind == kind);
        let mut slot = match pos.and_then(|i| self.slots.get(i)) {
            Some(s) => *s,
            None => Slot {
                sa,
                kind,
                partial: None,
                bytes: [0; MAX_FRAMES * CHUNK],
                last_counter: None,
                last_stamp: None,
            },
        };
        let mut trailer = [0u8; TRAILER_LEN];
        let secured = auth.is_some();
        let (counter, whole) = if index == FD_INDEX || index == FD_SECURED_INDEX {
            (
                fd_chunks(&mut slot, index, frame.data(), &mut trailer, secured)?,
                true,
            )
        } else {
            classic_chunk(&mut slot, index, frame.data(), &mut trailer, secured)?
        };
        let mut result = None;
        if whole {
            result = Some(self.complete(&mut slot, pos, counter, &trailer, now, auth)?);
        }
        match pos.and_then(|i| self.slots.get_mut(i)) {
            Some(s) => *s = slot,
            None => self.slots.push(slot).map_err(|_| DecodeError::Full)?,
        }
        Ok(result)
    }

    /// Checks a whole message in `slot` (its payload chunks, and `trailer` when secured)
    /// and records it there: CRC, duplicate, plausibility, sender, freshness of states
    /// and ticks, room, and last the authenticator.
    fn complete<F: Real, const K: usize, const R: usize>(
        &self,
        slot: &mut Slot,
        pos: Option<usize>,
        counter: u8,
        trailer: &[u8; TRAILER_LEN],
        now: Instant,
        auth: Option<Verifier<'_, K, R>>,
    ) -> Result<Message<F>, DecodeError> {
        let (kind, sa) = (slot.kind, slot.sa);
        let total = kind.frames() * CHUNK;
        let body = slot.bytes.get(..total - 1).unwrap_or(&[]);
        let crc = slot.bytes.get(total - 1).copied().unwrap_or(0);
        if message_crc(kind, sa, counter, body) != crc {
            return Err(DecodeError::Crc);
        }
        if slot.last_counter == Some(counter) {
            return Err(DecodeError::Duplicate);
        }
        let msg = decode_body::<F>(kind, body, now)?;
        if !sender_ok(&msg, sa) {
            return Err(DecodeError::SenderMismatch);
        }
        // States must be newer than the last (by stamp), ticks later (by period).
        let ordinal = match kind {
            MessageKind::State => Some(rd_u32(body, 16)),
            MessageKind::Located => Some(rd_u32(body, 21)),
            MessageKind::Sync => Some(rd_u32(body, 0)),
            _ => None,
        };
        // Both wrap (stamps every 49.7 days, periods every 2³²): "newer" is serial-number
        // arithmetic (RFC 1982), true for anything less than half the range ahead.
        if let Some(stamp) = ordinal {
            if slot
                .last_stamp
                .is_some_and(|l| stamp.wrapping_sub(l) as i32 <= 0)
            {
                return Err(DecodeError::Stale);
            }
            slot.last_stamp = Some(stamp);
        }
        if pos.is_none() && self.slots.is_full() {
            return Err(DecodeError::Full);
        }
        // Last, as the only check that records something outside this slot.
        if let Some(v) = auth {
            let all = slot.bytes.get(..total).unwrap_or(&[]);
            v.freshness
                .verify(
                    v.keys,
                    kind as u8,
                    sa,
                    counter,
                    all,
                    trailer,
                    now.as_millis(),
                )
                .map_err(DecodeError::Auth)?;
        }
        slot.last_counter = Some(counter);
        Ok(msg)
    }
}

/// Whether `sa` may send `msg`: a vehicle speaks only for itself; permissions come only
/// from an intersection manager (a vehicle cannot grant itself, or another, entry to
/// A_S); ticks only from the time master.
fn sender_ok<F>(msg: &Message<F>, sa: u8) -> bool {
    match msg {
        Message::State(s) | Message::Located { state: s, .. } => s.id & 0xFF == u16::from(sa),
        Message::Request(r) | Message::JunctionRequest { request: r, .. } => {
            r.id & 0xFF == u16::from(sa)
        }
        Message::Exit { id, .. } | Message::JunctionExit { id, .. } => id & 0xFF == u16::from(sa),
        Message::Grant { .. } | Message::Revoke { .. } => {
            (MANAGER_ADDRESS..=MANAGER_LAST).contains(&sa)
        }
        Message::Sync { .. } => sa == CLOCK_ADDRESS,
    }
}

/// Takes classic frame `index` of `slot`'s kind into `slot` (the authenticator frame's
/// trailer into `trailer` when `secured`): its alive counter, and whether the message is
/// now whole.
fn classic_chunk(
    slot: &mut Slot,
    index: u8,
    data: &[u8],
    trailer: &mut [u8; TRAILER_LEN],
    secured: bool,
) -> Result<(u8, bool), DecodeError> {
    let kind = slot.kind;
    let n = kind.frames() + usize::from(secured);
    if usize::from(index) >= n {
        return Err(DecodeError::BadFrameIndex);
    }
    if data.len() != 8 {
        return Err(DecodeError::BadLength);
    }
    let header = data.first().copied().unwrap_or(0);
    if header >> 4 != index {
        return Err(DecodeError::HeaderMismatch);
    }
    let counter = header & 0x0F;
    let seen = match (index, slot.partial) {
        (0, _) => 0u8,
        (i, Some((c, seen))) if c == counter && seen == (1u8 << i) - 1 => seen,
        _ => return Err(DecodeError::OutOfSequence),
    };
    let at = usize::from(index) * CHUNK;
    if usize::from(index) < kind.frames() {
        if let (Some(dst), Some(src)) = (slot.bytes.get_mut(at..at + CHUNK), data.get(1..)) {
            dst.copy_from_slice(src);
        }
    } else if let Some(src) = data.get(1..1 + TRAILER_LEN) {
        // The authenticator frame: its trailer, and zero padding.
        trailer.copy_from_slice(src);
        if data
            .get(1 + TRAILER_LEN..)
            .is_some_and(|p| p.iter().any(|b| *b != 0))
        {
            return Err(DecodeError::BadLength);
        }
    }
    let seen = seen | 1 << index;
    let whole = usize::from(index) + 1 == n;
    slot.partial = if whole { None } else { Some((counter, seen)) };
    Ok((counter, whole))
}

/// Takes a CAN FD frame (index [`FD_INDEX`] or [`FD_SECURED_INDEX`]) carrying a whole
/// message of `slot`'s kind into `slot`, and its trailer into `trailer`: its alive
/// counter. A secured receiver takes only frames with an authenticator; a plain one takes
/// both (as it takes a classic secured stream's message frames).
fn fd_chunks(
    slot: &mut Slot,
    index: u8,
    data: &[u8],
    trailer: &mut [u8; TRAILER_LEN],
    secured: bool,
) -> Result<u8, DecodeError> {
    let with_trailer = index == FD_SECURED_INDEX;
    if secured && !with_trailer {
        return Err(DecodeError::BadFrameIndex);
    }
    let body = slot.kind.frames() * CHUNK;
    let used = 1 + body + if with_trailer { TRAILER_LEN } else { 0 };
    let padded = data.get(used..).is_some_and(|p| p.iter().any(|b| *b != 0));
    if fd_len(used) != Some(data.len()) || padded {
        return Err(DecodeError::BadLength);
    }
    let header = data.first().copied().unwrap_or(0);
    if header >> 4 != index {
        return Err(DecodeError::HeaderMismatch);
    }
    if let (Some(dst), Some(src)) = (slot.bytes.get_mut(..body), data.get(1..1 + body)) {
        dst.copy_from_slice(src);
    }
    if let Some(src) = data.get(1 + body..used) {
        if with_trailer {
            trailer.copy_from_slice(src);
        }
    }
    // A whole message: any classic reassembly of this sender and kind is superseded.
    slot.partial = None;
    Ok(header & 0x0F)
}

fn lane(n: u8) -> Option<u8> {
    (n != NO_LANE).then_some(n)
}

/// A track from its byte, if its heading is one of the four.
fn track_of(x: u8) -> Result<TrackWire, DecodeError> {
    let t = TrackWire {
        heading: x & 0x0F,
        lane: x >> 4,
    };
    if t.heading > 3 {
        return Err(DecodeError::OutOfRange(Field::TrackHeading));
    }
    Ok(t)
}

/// A speed from its field, if plausible.
fn speed(raw: u16) -> Result<f64, DecodeError> {
    let v = f64::from(raw) * SPEED_RES;
    if v > SPEED_LIMIT {
        return Err(DecodeError::OutOfRange(Field::Speed));
    }
    Ok(v)
}

/// The instant whose milliseconds have the low 32 bits `low` and that is nearest `now`
/// (the wire carries times that way, [`crate::wire`]): exact for any time within 24.8
/// days of the receiver's clock, whatever either clock reads.
pub fn restore_millis(low: u32, now: Instant) -> Instant {
    const RANGE: u64 = 1 << 32;
    let now_ms = now.as_millis();
    let base = (now_ms & !(RANGE - 1)) | u64::from(low);
    let mut best = base;
    for c in [base.checked_sub(RANGE), base.checked_add(RANGE)]
        .into_iter()
        .flatten()
    {
        if c.abs_diff(now_ms) < best.abs_diff(now_ms) {
            best = c;
        }
    }
    Instant::from_millis(best)
}

/// Decodes a verified payload received at `now` and checks plausibility.
fn decode_body<F: Real>(
    kind: MessageKind,
    b: &[u8],
    now: Instant,
) -> Result<Message<F>, DecodeError> {
    let f = |x: f64| F::from_f64(x);
    let t = |at: usize| restore_millis(rd_u32(b, at), now);
    let byte = |i: usize| b.get(i).copied().unwrap_or(0);
    Ok(match kind {
        MessageKind::State => Message::State(
            StateWire {
                x: rd_u32(b, 2) as i32,
                lanes: byte(6),
                y: rd_u16(b, 7) as i16,
                heading: rd_u16(b, 9) as i16,
                speed: rd_u16(b, 11),
                beta_flags: byte(13),
                yaw: rd_u16(b, 14) as i16,
                stamp: rd_u32(b, 16),
                brake: byte(20),
            }
            .state(rd_u16(b, 0), now)?,
        ),
        MessageKind::Located => Message::Located {
            segment: rd_u16(b, 2),
            state: StateWire {
                lanes: byte(4),
                beta_flags: byte(5),
                brake: byte(6),
                x: rd_u32(b, 7) as i32,
                y: rd_u16(b, 11) as i16,
                heading: rd_u16(b, 14) as i16,
                speed: rd_u16(b, 16),
                yaw: rd_u16(b, 18) as i16,
                stamp: rd_u32(b, 21),
            }
            .state(rd_u16(b, 0), now)?,
        },
        MessageKind::JunctionRequest => {
            let (inlet, outlet) = (track_of(byte(3))?, track_of(byte(4))?);
            let s = u32::from(rd_u16(b, 7)) | u32::from(byte(9)) << 16;
            Message::JunctionRequest {
                junction: byte(2),
                request: Request {
                    id: rd_u16(b, 0),
                    inlet,
                    outlet,
                    arrival: t(10),
                    s: f(f64::from(s) * POS_RES),
                    v: f(speed(rd_u16(b, 5))?),
                },
            }
        }
        MessageKind::JunctionExit => Message::JunctionExit {
            junction: byte(2),
            id: rd_u16(b, 0),
            at: t(3),
        },
        MessageKind::Request => {
            let (inlet, outlet) = (track_of(byte(2))?, track_of(byte(3))?);
            let s = u32::from(rd_u16(b, 4)) | u32::from(byte(6)) << 16;
            Message::Request(Request {
                id: rd_u16(b, 0),
                inlet,
                outlet,
                arrival: t(7),
                s: f(f64::from(s) * POS_RES),
                v: f(speed(rd_u16(b, 11))?),
            })
        }
        MessageKind::Grant | MessageKind::Revoke | MessageKind::Exit => {
            let id = rd_u16(b, 0);
            let t = t(2);
            match kind {
                MessageKind::Grant => Message::Grant { id, until: t },
                MessageKind::Revoke => Message::Revoke { id, at: t },
                _ => Message::Exit { id, at: t },
            }
        }
        MessageKind::Sync => {
            let last = match byte(4) {
                0 => false,
                1 => true,
                _ => return Err(DecodeError::OutOfRange(Field::Flag)),
            };
            Message::Sync {
                period: rd_u32(b, 0),
                last,
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::frame::PlainFrame as TestFrame;

    /// The receiver's clock in these tests (every stamp is within 24.8 days of it).
    const NOW: Instant = Instant::from_secs(20);

    /// `s` seconds after the epoch, to the millisecond.
    fn secs(s: f64) -> Instant {
        Instant::from_millis((s * 1e3).round() as u64)
    }

    fn state() -> VehicleState<f64> {
        VehicleState {
            id: 0x0107,
            x: 1234.56,
            y: 5.4,
            theta: -0.1234,
            v: 15.02,
            omega: 0.25,
            lane: 2,
            alpha: Some(1),
            beta: None,
            stamp: secs(12.34),
            cooperative: true,
            brake: None,
        }
    }

    /// States every 10 ms, received 3 ms later, by a receiver whose clock reads 0, 60
    /// days, just before the wire's 32-bit milliseconds wrap (49.7 days), or a century:
    /// every one is accepted (none stale across the wrap) with its stamp restored exactly,
    /// and encoding never runs out of range.
    #[test]
    fn every_fresh_state_is_taken_whatever_the_uptime_and_across_the_wrap() {
        let day = 86_400_000u64;
        for base_ms in [0, 60 * day, (1 << 32) - 500, 36_525 * day] {
            let mut r = Reassembler::<4>::new();
            for k in 0..100u64 {
                let stamp = Instant::from_millis(base_ms + 10 * k);
                let st = VehicleState { stamp, ..state() };
                let frames: Frames<TestFrame> =
                    encode(&Message::State(st), 0x07, k as u8).expect("any uptime encodes");
                let now = stamp.saturating_add(planner_core::Duration::from_millis(3));
                let mut got = None;
                for f in &frames {
                    got = r.push::<f32, _>(f, now).expect("fresh");
                }
                let Some(Message::State(s)) = got else {
                    panic!("a state at {base_ms} + {k}");
                };
                assert_eq!(s.stamp, stamp);
            }
        }
    }

    #[test]
    fn restored_times_are_the_nearest_to_the_receivers_clock() {
        let wrap = 1u64 << 32;
        let at = |ms| Instant::from_millis(ms);
        // Just after the wrap, a stamp sent just before it.
        assert_eq!(
            restore_millis((wrap - 5) as u32, at(wrap + 3)),
            at(wrap - 5)
        );
        // Just before it, a stamp from a sender whose clock is a little ahead.
        assert_eq!(restore_millis(2, at(wrap - 1)), at(wrap + 2));
        // Near the epoch, nothing before it.
        assert_eq!(restore_millis(u32::MAX, at(1)), at(u64::from(u32::MAX)));
        assert_eq!(restore_millis(7, at(0)), at(7));
        // 24 days either way is exact.
        let now = 3 * wrap + 12_345;
        for d in [0, 1, 24 * 86_400_000] {
            assert_eq!(restore_millis((now + d) as u32, at(now)), at(now + d));
            assert_eq!(restore_millis((now - d) as u32, at(now)), at(now - d));
        }
    }

    #[test]
    fn round_trip_and_e2e_checks() {
        let m = Message::State(state());
        let frames: Frames<TestFrame> = encode(&m, 0x07, 3).unwrap();
        assert_eq!(frames.len(), 4);
        let mut r = Reassembler::<4>::new();
        for f in &frames[..3] {
            assert_eq!(r.push::<f64, _>(f, NOW), Ok(None));
        }
        let Ok(Some(Message::State(s))) = r.push::<f64, _>(&frames[3], NOW) else {
            panic!("a state");
        };
        let e = state();
        assert_eq!(
            (s.id, s.lane, s.alpha, s.beta),
            (e.id, e.lane, e.alpha, e.beta)
        );
        assert!((s.x - e.x).abs() <= 0.005 && (s.y - e.y).abs() <= 0.005);
        assert!((s.v - e.v).abs() <= 0.01 && s.stamp == e.stamp);
        assert!(
            (s.theta - e.theta).abs() <= HEADING_RES && (s.omega - e.omega).abs() <= YAW_RATE_RES
        );
        // The same message again: duplicate (same counter), reassembler unchanged.
        let before = r.clone().slots;
        for f in &frames[..3] {
            assert_eq!(r.push::<f64, _>(f, NOW), Ok(None));
        }
        assert_eq!(
            r.push::<f64, _>(&frames[3], NOW),
            Err(DecodeError::Duplicate)
        );
        // A newer counter but an older stamp: stale.
        let mut old = state();
        old.stamp = secs(1.0);
        let frames: Frames<TestFrame> = encode(&Message::State(old), 0x07, 4).unwrap();
        for f in &frames[..3] {
            let _ = r.push::<f64, _>(f, NOW);
        }
        assert_eq!(r.push::<f64, _>(&frames[3], NOW), Err(DecodeError::Stale));
        assert_eq!(r.slots[0].last_counter, before[0].last_counter);
        // A flipped bit: CRC.
        let mut newer = state();
        newer.stamp = secs(20.0);
        let mut frames: Frames<TestFrame> = encode(&Message::State(newer), 0x07, 5).unwrap();
        let mut d = [0u8; 8];
        d.copy_from_slice(frames[1].data());
        d[3] ^= 0x10;
        frames[1] = TestFrame::new(frames[1].id(), &d).unwrap();
        for f in &frames[..3] {
            let _ = r.push::<f64, _>(f, NOW);
        }
        assert_eq!(r.push::<f64, _>(&frames[3], NOW), Err(DecodeError::Crc));
        // A continuation without its first frame.
        let mut r2 = Reassembler::<4>::new();
        assert_eq!(
            r2.push::<f64, _>(&frames[2], NOW),
            Err(DecodeError::OutOfSequence)
        );
        // Sender address and id disagree.
        let frames: Frames<TestFrame> = encode(&Message::State(state()), 0x08, 1).unwrap();
        for f in &frames[..3] {
            let _ = r2.push::<f64, _>(f, NOW);
        }
        assert_eq!(
            r2.push::<f64, _>(&frames[3], NOW),
            Err(DecodeError::SenderMismatch)
        );
    }

    #[test]
    fn intersection_messages_round_trip() {
        let req = Request {
            id: 9,
            inlet: TrackWire {
                heading: 2,
                lane: 1,
            },
            outlet: TrackWire {
                heading: 3,
                lane: 1,
            },
            arrival: secs(3.5),
            s: 97.25,
            v: 13.9,
        };
        let mut r = Reassembler::<8>::new();
        for (m, sa) in [
            (Message::Request(req), 9u8),
            (
                Message::Grant {
                    id: 9,
                    until: secs(4.0),
                },
                MANAGER_ADDRESS,
            ),
            (
                Message::Revoke {
                    id: 9,
                    at: secs(4.5),
                },
                MANAGER_ADDRESS,
            ),
            (
                Message::Exit {
                    id: 9,
                    at: secs(9.0),
                },
                9,
            ),
        ] {
            let frames: Frames<TestFrame> = encode(&m, sa, 0).unwrap();
            let mut got = None;
            for f in &frames {
                got = r.push::<f64, _>(f, NOW).unwrap();
            }
            match (got.unwrap(), m) {
                (Message::Request(a), Message::Request(b)) => {
                    assert_eq!((a.id, a.inlet, a.outlet), (b.id, b.inlet, b.outlet));
                    assert!((a.s - b.s).abs() < 0.006 && a.arrival == b.arrival);
                }
                (a, b) => assert_eq!(a, b),
            }
        }
        // A grant or revoke from anyone but the manager is refused (a vehicle granting
        // itself entry), and leaves the reassembler as it was.
        for m in [
            Message::<f64>::Grant {
                id: 9,
                until: secs(5.0),
            },
            Message::Revoke {
                id: 9,
                at: secs(5.0),
            },
        ] {
            for sa in [9u8, 0, CLOCK_ADDRESS] {
                let frames: Frames<TestFrame> = encode(&m, sa, 3).unwrap();
                let before = r.slots.clone();
                assert_eq!(
                    r.push::<f64, _>(&frames[0], NOW),
                    Err(DecodeError::SenderMismatch)
                );
                assert_eq!(r.slots, before);
            }
        }
        // Encoding refuses what a field cannot carry.
        let mut s = state();
        s.v = f64::NAN;
        assert_eq!(
            encode::<f64, TestFrame>(&Message::State(s), 7, 0).unwrap_err(),
            EncodeError::OutOfRange(Field::Speed)
        );
        s = state();
        s.lane = 15;
        assert_eq!(
            encode::<f64, TestFrame>(&Message::State(s), 7, 0).unwrap_err(),
            EncodeError::OutOfRange(Field::Lane)
        );
    }

    fn request(id: u16) -> Request<f64> {
        Request {
            id,
            inlet: TrackWire {
                heading: 2,
                lane: 1,
            },
            outlet: TrackWire {
                heading: 3,
                lane: 1,
            },
            arrival: secs(3.5),
            s: 97.25,
            v: 13.9,
        }
    }

    /// Every message that names its sender, each with the vehicle it names (id 9).
    fn naming_vehicle_9() -> [Message<f64>; 6] {
        let mut st = state();
        st.id = 9;
        [
            Message::Exit {
                id: 9,
                at: secs(9.0),
            },
            Message::JunctionExit {
                junction: 2,
                id: 9,
                at: secs(9.0),
            },
            Message::Request(request(9)),
            Message::JunctionRequest {
                junction: 2,
                request: request(9),
            },
            Message::State(st),
            Message::Located {
                segment: 4,
                state: st,
            },
        ]
    }

    /// Pushes every frame of `m` from `sa`; the last push's result.
    fn push_all(
        r: &mut Reassembler<8>,
        m: &Message<f64>,
        sa: u8,
        counter: u8,
    ) -> Result<Option<Message<f64>>, DecodeError> {
        let frames: Frames<TestFrame> = encode(m, sa, counter).unwrap();
        let mut last = Ok(None);
        for f in &frames {
            last = r.push::<f64, _>(f, NOW);
        }
        last
    }

    mod secured {
        use super::*;
        use crate::secoc::{derive_key, FreshnessRx, Key, KeyStore};

        pub(super) const MASTER: Key = Key([7; 16]);

        pub(super) fn keys() -> KeyStore<8> {
            let mut k = KeyStore::new();
            for sa in [9u8, 8, MANAGER_ADDRESS, CLOCK_ADDRESS] {
                k.insert(sa, derive_key(&MASTER, sa)).unwrap();
            }
            k
        }

        /// Every kind, each from a sender allowed to send it.
        pub(super) fn every_kind() -> [(Message<f64>, u8); 9] {
            let [e, je, rq, jrq, st, loc] = naming_vehicle_9();
            [
                (e, 9),
                (je, 9),
                (rq, 9),
                (jrq, 9),
                (st, 9),
                (loc, 9),
                (
                    Message::Grant {
                        id: 9,
                        until: secs(4.0),
                    },
                    MANAGER_ADDRESS,
                ),
                (
                    Message::Revoke {
                        id: 9,
                        at: secs(4.0),
                    },
                    MANAGER_ADDRESS,
                ),
                (
                    Message::Sync {
                        period: 4,
                        last: false,
                    },
                    CLOCK_ADDRESS,
                ),
            ]
        }

        pub(super) struct Rx {
            pub(super) r: Reassembler<8>,
            keys: KeyStore<8>,
            fresh: FreshnessRx<16>,
        }

        impl Rx {
            pub(super) fn new() -> Self {
                Self {
                    r: Reassembler::new(),
                    keys: keys(),
                    fresh: FreshnessRx::default(),
                }
            }
            pub(super) fn push<Fr: Frame>(
                &mut self,
                f: &Fr,
                now_ms: u64,
            ) -> Result<Option<Message<f64>>, DecodeError> {
                let v = Verifier {
                    keys: &self.keys,
                    freshness: &mut self.fresh,
                };
                self.r
                    .push_secured::<f64, _, 8, 16>(f, Instant::from_millis(now_ms), v)
            }
            fn push_all(
                &mut self,
                frames: &[TestFrame],
                now_ms: u64,
            ) -> Vec<Result<Option<Message<f64>>, DecodeError>, 8> {
                frames.iter().map(|f| self.push(f, now_ms)).collect()
            }
        }

        fn sign(
            m: &Message<f64>,
            sa: u8,
            counter: u8,
            key_of: u8,
            fv: u64,
        ) -> SecuredFrames<TestFrame> {
            encode_secured(m, sa, counter, &derive_key(&MASTER, key_of), fv).unwrap()
        }

        #[test]
        fn every_kind_round_trips_with_its_authenticator_and_not_before() {
            for (m, sa) in every_kind() {
                let mut rx = Rx::new();
                let frames = sign(&m, sa, 3, sa, 1_000);
                assert_eq!(frames.len(), m.kind().frames() + 1);
                let out = rx.push_all(&frames, 1_000);
                let (last, rest) = out.split_last().unwrap();
                assert!(
                    rest.iter().all(|r| *r == Ok(None)),
                    "{m:?}: accepted before its MAC"
                );
                let got = (*last).unwrap().unwrap();
                assert_eq!(
                    encode::<f64, TestFrame>(&got, sa, 3).unwrap(),
                    encode(&m, sa, 3).unwrap()
                );
                // The same frames again: the E2E counter already refuses them.
                let again = rx.push_all(&frames, 1_010);
                assert_eq!(*again.last().unwrap(), Err(DecodeError::Duplicate), "{m:?}");
                // After a newer message, the old one replayed: its freshness is taken (states
                // and ticks are refused by their stamps first).
                let later = match m {
                    Message::State(mut st) => {
                        st.stamp = st
                            .stamp
                            .saturating_add(planner_core::Duration::from_millis(100));
                        Message::State(st)
                    }
                    Message::Located { segment, mut state } => {
                        state.stamp = state
                            .stamp
                            .saturating_add(planner_core::Duration::from_millis(100));
                        Message::Located { segment, state }
                    }
                    Message::Sync { period, last } => Message::Sync {
                        period: period + 1,
                        last,
                    },
                    other => other,
                };
                let newer = sign(&later, sa, 4, sa, 1_005);
                assert!(matches!(
                    rx.push_all(&newer, 1_005).last(),
                    Some(Ok(Some(_)))
                ));
                let replay = rx.push_all(&frames, 1_010);
                let expect = match m.kind() {
                    MessageKind::State | MessageKind::Located | MessageKind::Sync => {
                        DecodeError::Stale
                    }
                    _ => DecodeError::Auth(AuthError::Replayed),
                };
                assert_eq!(*replay.last().unwrap(), Err(expect), "{m:?}");
                // A plain receiver refuses the authenticator frame's index.
                let mut plain = Reassembler::<8>::new();
                let mut res = Ok(None);
                for f in &frames {
                    res = plain.push::<f64, _>(f, NOW);
                }
                assert_eq!(res, Err(DecodeError::BadFrameIndex));
            }
        }

        #[test]
        fn a_forged_grant_is_refused_and_changes_nothing() {
            // A vehicle writes the manager's address: the CRC and the sender rule pass, the
            // MAC (under the vehicle's own key, or any but the manager's) does not.
            let grant = Message::<f64>::Grant {
                id: 8,
                until: secs(9.0),
            };
            let mut rx = Rx::new();
            let forged = sign(&grant, MANAGER_ADDRESS, 1, 8, 2_000);
            let before = rx.r.slots.clone();
            let out = rx.push_all(&forged, 2_000);
            assert_eq!(
                *out.last().unwrap(),
                Err(DecodeError::Auth(AuthError::BadMac))
            );
            assert_eq!(
                rx.r.slots.len(),
                before.len() + 1,
                "only the partial frame is held"
            );
            assert!(rx.r.slots.iter().all(|s| s.last_counter.is_none()));
            // The real grant with the same counter is still accepted afterwards.
            let real = sign(&grant, MANAGER_ADDRESS, 1, MANAGER_ADDRESS, 2_000);
            assert!(matches!(
                rx.push_all(&real, 2_000).last(),
                Some(Ok(Some(_)))
            ));
            // An unknown sender has no key.
            let mut st = state();
            st.id = 0x33;
            let unknown = sign(&Message::State(st), 0x33, 0, 0x33, 2_000);
            assert_eq!(
                *rx.push_all(&unknown, 2_000).last().unwrap(),
                Err(DecodeError::Auth(AuthError::UnknownKey))
            );
        }

        #[test]
        fn stale_spliced_and_padded_authenticators_are_refused() {
            let m = Message::Exit {
                id: 9,
                at: secs(1.0),
            };
            let mut rx = Rx::new();
            // Recorded a second ago: outside the 500 ms window.
            let old = sign(&m, 9, 2, 9, 10_000);
            assert_eq!(
                *rx.push_all(&old, 11_000).last().unwrap(),
                Err(DecodeError::Auth(AuthError::Stale))
            );
            // The authenticator of another message (another time) spliced onto this one.
            let a = sign(&m, 9, 2, 9, 20_000);
            let b = sign(
                &Message::Exit {
                    id: 9,
                    at: secs(2.0),
                },
                9,
                2,
                9,
                20_001,
            );
            let spliced = [a[0], b[1]];
            assert_eq!(
                *rx.push_all(&spliced, 20_001).last().unwrap(),
                Err(DecodeError::Auth(AuthError::BadMac))
            );
            // Non-zero padding after the trailer.
            let mut data = [0u8; 8];
            data.copy_from_slice(a[1].data());
            data[7] = 1;
            let padded = TestFrame::new(a[1].id(), &data).unwrap();
            rx.push(&a[0], 20_000).unwrap();
            assert_eq!(rx.push(&padded, 20_000), Err(DecodeError::BadLength));
            // The genuine one still goes through after all that.
            assert!(matches!(rx.push_all(&a, 20_000).last(), Some(Ok(Some(_)))));
        }
    }

    mod fd {
        use super::secured::{every_kind, Rx, MASTER};
        use super::*;
        use crate::frame::FdFrame;
        use crate::secoc::derive_key;

        fn fd(m: &Message<f64>, sa: u8, counter: u8) -> FdFrame {
            encode_fd(m, sa, counter).unwrap()
        }

        fn with_data(f: &FdFrame, data: &[u8]) -> FdFrame {
            FdFrame::new_fd(f.id(), data).unwrap()
        }

        #[test]
        fn every_kind_fits_one_frame_that_carries_its_classic_chunks() {
            for (m, sa) in every_kind() {
                let n = m.kind().frames();
                let f = fd(&m, sa, 5);
                let used = 1 + n * CHUNK;
                assert_eq!(f.data().len(), fd_len(used).unwrap(), "{m:?}");
                assert_eq!(f.is_fd(), used > 8);
                assert_eq!(f.data()[0], FD_INDEX << 4 | 5);
                let Id::Extended(id) = f.id() else {
                    panic!("extended")
                };
                assert_eq!(id.as_raw(), frame_id(m.kind(), FD_INDEX, sa));
                let classic: Frames<TestFrame> = encode(&m, sa, 5).unwrap();
                for (i, c) in classic.iter().enumerate() {
                    assert_eq!(
                        &f.data()[1 + i * CHUNK..1 + (i + 1) * CHUNK],
                        &c.data()[1..]
                    );
                }
                assert!(f.data()[used..].iter().all(|b| *b == 0));
                let mut r = Reassembler::<8>::new();
                let got = r.push::<f64, _>(&f, NOW).unwrap().unwrap();
                assert_eq!(encode::<f64, TestFrame>(&got, sa, 5).unwrap(), classic);
                let before = r.slots.clone();
                assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::Duplicate));
                assert_eq!(r.slots, before);
            }
            // A classic frame type cannot carry a message beyond 8 bytes.
            let st = Message::State(state());
            assert_eq!(
                encode_fd::<f64, TestFrame>(&st, 7, 0),
                Err(EncodeError::Frame)
            );
        }

        #[test]
        fn malformed_frames_are_refused_and_change_nothing() {
            let st = Message::State(state());
            let f = fd(&st, 0x07, 2);
            let d = f.data();
            assert_eq!(d.len(), 32);
            let mut r = Reassembler::<8>::new();
            // A classic first frame of another message is pending.
            let classic: Frames<TestFrame> = encode(&st, 0x07, 9).unwrap();
            assert_eq!(r.push::<f64, _>(&classic[0], NOW), Ok(None));
            let before = r.slots.clone();
            let mut longer = [0u8; 48];
            longer[..32].copy_from_slice(d);
            let mut padded = [0u8; 32];
            padded.copy_from_slice(d);
            padded[31] = 1;
            let mut header = [0u8; 32];
            header.copy_from_slice(d);
            header[0] = 2;
            let mut flipped = [0u8; 32];
            flipped.copy_from_slice(d);
            flipped[5] ^= 0x10;
            let mut other = state();
            other.id = 0x0108;
            let cases = [
                (with_data(&f, &d[..24]), DecodeError::BadLength),
                (with_data(&f, &longer), DecodeError::BadLength),
                (with_data(&f, &padded), DecodeError::BadLength),
                (with_data(&f, &header), DecodeError::HeaderMismatch),
                (with_data(&f, &flipped), DecodeError::Crc),
                // Sent by 0x07, naming vehicle 0x0108.
                (
                    fd(&Message::State(other), 0x07, 2),
                    DecodeError::SenderMismatch,
                ),
            ];
            for (bad, why) in cases {
                assert_eq!(r.push::<f64, _>(&bad, NOW), Err(why));
                assert_eq!(r.slots, before, "{why:?} changed the reassembler");
            }
            // The genuine frame supersedes the pending classic reassembly.
            assert!(matches!(
                r.push::<f64, _>(&f, NOW),
                Ok(Some(Message::State(_)))
            ));
            assert_eq!(
                r.push::<f64, _>(&classic[1], NOW),
                Err(DecodeError::OutOfSequence)
            );
        }

        #[test]
        fn a_secured_frame_carries_the_classic_authenticator_and_a_plain_one_is_refused() {
            for (m, sa) in every_kind() {
                let n = m.kind().frames();
                let key = derive_key(&MASTER, sa);
                let f: FdFrame = encode_fd_secured(&m, sa, 3, &key, 1_000).unwrap();
                let used = 1 + n * CHUNK + TRAILER_LEN;
                assert_eq!(f.data().len(), fd_len(used).unwrap(), "{m:?}");
                assert_eq!(f.data()[0] >> 4, FD_SECURED_INDEX);
                // The same MAC and freshness as the classic authenticator frame.
                let classic: SecuredFrames<TestFrame> =
                    encode_secured(&m, sa, 3, &key, 1_000).unwrap();
                assert_eq!(
                    &f.data()[1 + n * CHUNK..used],
                    &classic[n].data()[1..1 + TRAILER_LEN]
                );
                let mut rx = Rx::new();
                let got = rx.push(&f, 1_000).unwrap().unwrap();
                assert_eq!(
                    encode::<f64, TestFrame>(&got, sa, 3).unwrap(),
                    encode(&m, sa, 3).unwrap()
                );
                // A plain receiver reads the message (it verifies nothing).
                assert!(Reassembler::<8>::new()
                    .push::<f64, _>(&f, NOW)
                    .unwrap()
                    .is_some());
                // A secured receiver never takes a frame without an authenticator.
                let mut rx = Rx::new();
                assert_eq!(
                    rx.push(&fd(&m, sa, 3), 1_000),
                    Err(DecodeError::BadFrameIndex)
                );
                assert!(rx.r.slots.is_empty());
            }
            // A vehicle forging the manager's grant: refused, nothing recorded.
            let grant = Message::<f64>::Grant {
                id: 8,
                until: secs(9.0),
            };
            let forged: FdFrame =
                encode_fd_secured(&grant, MANAGER_ADDRESS, 1, &derive_key(&MASTER, 8), 2_000)
                    .unwrap();
            let mut rx = Rx::new();
            assert_eq!(
                rx.push(&forged, 2_000),
                Err(DecodeError::Auth(AuthError::BadMac))
            );
            assert!(rx.r.slots.is_empty());
        }
    }

    #[test]
    fn exits_requests_and_states_come_only_from_the_vehicle_they_name() {
        // On an Exit the manager forgets the vehicle: one forged by another node would let
        // a conflicting route be granted while the vehicle is still inside A_S.
        for m in naming_vehicle_9() {
            let mut r = Reassembler::<8>::new();
            for sa in [8u8, 10, 0x19, MANAGER_ADDRESS, CLOCK_ADDRESS] {
                let before = r.slots.clone();
                assert_eq!(
                    push_all(&mut r, &m, sa, 1).map(|_| ()),
                    Err(DecodeError::SenderMismatch),
                    "{m:?} from {sa:#x}"
                );
                // Only the partial frames of that sender are kept: nothing accepted.
                assert!(
                    r.slots.iter().all(|s| s.last_counter.is_none()),
                    "{m:?} from {sa:#x}: {before:?}"
                );
            }
            assert!(
                matches!(push_all(&mut r, &m, 9, 1), Ok(Some(_))),
                "{m:?} from its own vehicle is accepted"
            );
        }
    }

    #[test]
    fn continuation_frames_of_another_message_are_not_spliced_in() {
        // Two states of one sender: frames of the second must not complete the first,
        // whatever their CRC (which alone lets 1 in 256 splices through).
        let (mut a, mut b) = (state(), state());
        a.stamp = secs(20.0);
        b.stamp = secs(21.0);
        b.x = -50.0;
        let fa: Frames<TestFrame> = encode(&Message::State(a), 0x07, 3).unwrap();
        let fb: Frames<TestFrame> = encode(&Message::State(b), 0x07, 4).unwrap();
        let mut r = Reassembler::<4>::new();
        assert_eq!(r.push::<f64, _>(&fa[0], NOW), Ok(None));
        let kept = r.slots.clone();
        // b's second frame after a's first: another counter.
        assert_eq!(
            r.push::<f64, _>(&fb[1], NOW),
            Err(DecodeError::OutOfSequence)
        );
        assert_eq!(r.slots, kept, "a refused frame changes nothing");
        // a's last frame before its second: out of order.
        assert_eq!(
            r.push::<f64, _>(&fa[2], NOW),
            Err(DecodeError::OutOfSequence)
        );
        assert_eq!(r.slots, kept);
        // a itself still completes.
        assert_eq!(r.push::<f64, _>(&fa[1], NOW), Ok(None));
        assert_eq!(r.push::<f64, _>(&fa[2], NOW), Ok(None));
        let Ok(Some(Message::State(got))) = r.push::<f64, _>(&fa[3], NOW) else {
            panic!("a completes");
        };
        assert!((got.x - a.x).abs() < 0.01);
        // b's first frame, then a's (old) frames: a's counter is not b's.
        assert_eq!(r.push::<f64, _>(&fb[0], NOW), Ok(None));
        assert_eq!(
            r.push::<f64, _>(&fa[1], NOW),
            Err(DecodeError::OutOfSequence)
        );
        // A splice whose CRC happens to match is still refused: build b's second frame
        // with a's counter in its header and check that the counter alone refuses it.
        let mut d = [0u8; 8];
        d.copy_from_slice(fb[1].data());
        d[0] = (d[0] & 0xF0) | 0x03;
        let forged = TestFrame::new(fb[1].id(), &d).unwrap();
        assert_eq!(
            r.push::<f64, _>(&forged, NOW),
            Err(DecodeError::OutOfSequence)
        );
    }

    #[test]
    fn sync_ticks_come_from_the_clock_in_order() {
        let mut r = Reassembler::<4>::new();
        let tick = |period, last, sa, counter| -> Frames<TestFrame> {
            encode::<f64, _>(&Message::Sync { period, last }, sa, counter).unwrap()
        };
        let f = tick(7, false, CLOCK_ADDRESS, 1);
        assert_eq!(f.len(), 1);
        assert_eq!(
            r.push::<f64, _>(&f[0], NOW),
            Ok(Some(Message::Sync {
                period: 7,
                last: false
            }))
        );
        // A tick not newer than the last, or from another node, is refused.
        assert_eq!(
            r.push::<f64, _>(&tick(7, false, CLOCK_ADDRESS, 2)[0], NOW),
            Err(DecodeError::Stale)
        );
        assert_eq!(
            r.push::<f64, _>(&tick(8, false, 0x12, 2)[0], NOW),
            Err(DecodeError::SenderMismatch)
        );
        assert_eq!(
            r.push::<f64, _>(&tick(8, true, CLOCK_ADDRESS, 2)[0], NOW),
            Ok(Some(Message::Sync {
                period: 8,
                last: true
            }))
        );
    }

    #[test]
    fn foreign_frames_are_refused() {
        let mut r = Reassembler::<2>::new();
        let std_id = embedded_can::StandardId::new(0x123).unwrap();
        let f = TestFrame::new(std_id, &[0; 8]).unwrap();
        assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::NotOurs));
        let f = TestFrame::new(ExtendedId::new(0x18FEF100).unwrap(), &[0; 8]).unwrap();
        assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::ForeignId));
        let f = TestFrame::new(
            ExtendedId::new(frame_id(MessageKind::Grant, 0, 0)).unwrap(),
            &[0; 5],
        )
        .unwrap();
        assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::BadLength));
        let f = TestFrame::new(
            ExtendedId::new(frame_id(MessageKind::Grant, 1, 0)).unwrap(),
            &[0x10; 8],
        )
        .unwrap();
        assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::BadFrameIndex));
        let raw = 6 << 26 | 0xFF << 16 | 0xC0 << 8 | 1;
        let f = TestFrame::new(ExtendedId::new(raw).unwrap(), &[0; 8]).unwrap();
        assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::UnknownKind(12)));
        assert!(r.slots.is_empty());
    }

    /// Survivors of `cargo mutants -f can-gateway/src/codec.rs` (docs/mutants.md), each
    /// killed here: range checks on encoding, the heading's wrap, the decoder's bounds,
    /// remote frames, staleness of `Located`, and every field of the junction messages.
    mod mutation_audit {
        use super::*;

        #[test]
        fn finite_values_outside_a_field_are_refused() {
            let mut s = state();
            s.v = -1.0;
            let e = encode::<f64, TestFrame>(&Message::State(s), 7, 0).unwrap_err();
            assert_eq!(e, EncodeError::OutOfRange(Field::Speed));
            s = state();
            s.x = 3.0e7; // beyond i32 at 0.01 m
            let e = encode::<f64, TestFrame>(&Message::State(s), 7, 0).unwrap_err();
            assert_eq!(e, EncodeError::OutOfRange(Field::X));
        }

        #[test]
        fn tracks_must_fit_their_nibbles() {
            for (heading, lane, ok) in
                [(3, 15, true), (4, 0, false), (0, 16, false), (4, 16, false)]
            {
                let mut req = request(9);
                req.inlet = TrackWire { heading, lane };
                let got = encode::<f64, TestFrame>(&Message::Request(req), 9, 0);
                assert_eq!(got.is_ok(), ok, "heading {heading} lane {lane}");
                if !ok {
                    assert_eq!(
                        got.unwrap_err(),
                        EncodeError::OutOfRange(Field::TrackHeading)
                    );
                }
            }
            // Both nibbles arrive where they were put.
            let mut req = request(9);
            req.inlet = TrackWire {
                heading: 3,
                lane: 15,
            };
            let mut r = Reassembler::<8>::new();
            let Ok(Some(Message::Request(got))) = push_all(&mut r, &Message::Request(req), 9, 0)
            else {
                panic!("a request");
            };
            assert_eq!(got.inlet, req.inlet);
        }

        #[test]
        fn headings_wrap_into_minus_pi_to_pi() {
            let pi = core::f64::consts::PI;
            for (theta, want) in [
                (3.0 * pi + 0.25, -pi + 0.25),
                (2.0 * pi + 0.5, 0.5),
                (-2.0 * pi - 0.5, -0.5),
                (pi, -pi),
                (-pi, -pi),
                (1.0, 1.0),
            ] {
                let mut s = state();
                s.theta = theta;
                let mut r = Reassembler::<8>::new();
                let Ok(Some(Message::State(got))) = push_all(&mut r, &Message::State(s), 7, 0)
                else {
                    panic!("a state");
                };
                assert!(
                    (got.theta - want).abs() <= HEADING_RES,
                    "{theta} → {}, want {want}",
                    got.theta
                );
            }
            assert_eq!(libm_floor(1.0), 1.0);
            assert_eq!(libm_floor(-0.5), -1.0);
            assert_eq!(libm_floor(2.5), 2.0);
        }

        fn wire_state(heading: i16, speed: u16) -> StateWire {
            StateWire {
                x: 0,
                y: 0,
                heading,
                speed,
                yaw: 0,
                lanes: 0xF1,
                beta_flags: NO_LANE,
                stamp: 1,
                brake: 0,
            }
        }

        #[test]
        fn decoded_headings_and_speeds_are_bounded() {
            let pi = core::f64::consts::PI;
            let at_pi = (pi / HEADING_RES).round() as i16;
            assert!(wire_state(at_pi, 0).state::<f64>(7, NOW).is_ok());
            assert!(wire_state(-at_pi, 0).state::<f64>(7, NOW).is_ok());
            assert_eq!(
                wire_state(at_pi + 2, 0).state::<f64>(7, NOW).err(),
                Some(DecodeError::OutOfRange(Field::Heading))
            );
            assert_eq!(
                wire_state(i16::MAX, 0).state::<f64>(7, NOW).err(),
                Some(DecodeError::OutOfRange(Field::Heading))
            );
            let limit = (SPEED_LIMIT / SPEED_RES).round() as u16;
            assert!(wire_state(0, limit).state::<f64>(7, NOW).is_ok());
            assert_eq!(
                wire_state(0, limit + 1).state::<f64>(7, NOW).err(),
                Some(DecodeError::OutOfRange(Field::Speed))
            );
            assert_eq!(speed(limit), Ok(SPEED_LIMIT));
            assert_eq!(speed(limit + 1), Err(DecodeError::OutOfRange(Field::Speed)));
        }

        #[test]
        fn remote_frames_are_not_ours() {
            let id = ExtendedId::new(frame_id(MessageKind::Grant, 0, MANAGER_ADDRESS)).unwrap();
            let f = TestFrame::new_remote(id, 8).unwrap();
            let mut r = Reassembler::<2>::new();
            assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::NotOurs));
            assert!(r.slots.is_empty());
        }

        #[test]
        fn an_older_located_state_is_stale() {
            let mut r = Reassembler::<8>::new();
            let mut st = state();
            st.id = 7;
            st.stamp = secs(20.0);
            let newer = Message::Located {
                segment: 1,
                state: st,
            };
            assert!(matches!(push_all(&mut r, &newer, 7, 1), Ok(Some(_))));
            st.stamp = secs(10.0);
            let older = Message::Located {
                segment: 1,
                state: st,
            };
            assert_eq!(push_all(&mut r, &older, 7, 2), Err(DecodeError::Stale));
        }

        #[test]
        fn both_state_kinds_carry_the_braking_limit_and_zero_means_undeclared() {
            let mut st = state();
            st.id = 7;
            st.brake = planner_core::BrakeLimit::from_mps2(4.5);
            let brake_of = |m: Option<Message<f64>>| match m {
                Some(Message::Located { state, .. } | Message::State(state)) => state.brake,
                _ => panic!("a state"),
            };
            for located in [false, true] {
                let message = |st: VehicleState<f64>| match located {
                    true => Message::Located {
                        segment: 1,
                        state: st,
                    },
                    false => Message::State(st),
                };
                let mut r = Reassembler::<8>::new();
                let mut declared = st;
                let got = push_all(&mut r, &message(declared), 7, 1);
                assert_eq!(brake_of(got.unwrap()), declared.brake, "located {located}");
                // An older sender's zero byte: not declared, so followers take a wall.
                declared.brake = None;
                declared.stamp = declared
                    .stamp
                    .saturating_add(planner_core::Duration::from_millis(10));
                let got = push_all(&mut r, &message(declared), 7, 2);
                assert_eq!(brake_of(got.unwrap()), None, "located {located}");
                // CAN FD carries the same byte.
                let fd: crate::FdFrame = encode_fd(&message(st), 7, 3).unwrap();
                let mut r = Reassembler::<8>::new();
                let got = r.push::<f64, _>(&fd, NOW);
                assert_eq!(brake_of(got.unwrap()), st.brake, "located {located}");
            }
        }

        #[test]
        fn junction_messages_keep_every_field() {
            let mut req = request(9);
            req.s = 1000.25; // beyond 16 bits at 0.01 m: the third byte counts
            req.arrival = secs(123.456);
            req.v = 13.9;
            let m = Message::JunctionRequest {
                junction: 2,
                request: req,
            };
            let mut r = Reassembler::<8>::new();
            let Ok(Some(Message::JunctionRequest {
                junction,
                request: got,
            })) = push_all(&mut r, &m, 9, 0)
            else {
                panic!("a junction request");
            };
            assert_eq!(
                (junction, got.id, got.inlet, got.outlet),
                (2, 9, req.inlet, req.outlet)
            );
            assert!((got.s - req.s).abs() < 0.006, "{}", got.s);
            assert_eq!(got.arrival, req.arrival);
            assert!((got.v - req.v).abs() < 0.011, "{}", got.v);
            // The plain request too.
            let Ok(Some(Message::Request(got))) = push_all(&mut r, &Message::Request(req), 9, 1)
            else {
                panic!("a request");
            };
            assert!((got.s - req.s).abs() < 0.006 && got.arrival == req.arrival);
            let exit = Message::JunctionExit {
                junction: 2,
                id: 9,
                at: secs(77.125),
            };
            assert_eq!(push_all(&mut r, &exit, 9, 2), Ok(Some(exit)));
        }
    }
}
