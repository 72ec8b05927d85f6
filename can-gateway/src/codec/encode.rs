//! Encoding: a message's payload written through its layout ([`crate::layout`]), its CRC,
//! then classic frames, CAN FD frames, and either with an authenticator ([`crate::secoc`]).

use super::quantize::{lane_nibble, path_position, q, time, track, StateWire};
use super::{message_crc, EncodeError, Field, Frames};
use crate::layout::{self, put};
use crate::secoc::{self, Key, TRAILER_LEN};
use crate::wire::{
    fd_len, frame_id, Command, Message, Request, CHUNK, FD_INDEX, FD_SECURED_INDEX, MAX_FRAMES,
    SPEED_RES,
};
use embedded_can::{ExtendedId, Frame, Id};
use heapless::Vec;
use planner_core::{BodyLength, BrakeLimit, Instant, Real};

/// The payload bytes of a message (without CRC), and their length: each field written
/// into its place ([`crate::layout`]).
pub(super) fn payload<F: Real>(
    m: &Message<F>,
) -> Result<([u8; MAX_FRAMES * CHUNK], usize), EncodeError> {
    let mut b = [0u8; MAX_FRAMES * CHUNK];
    let len = match m {
        // The braking limit is what lets a follower credit the sender with its least
        // travel (the leader-aware invariant); it cost a fourth classic frame, and
        // nothing on CAN FD beyond the next frame length.
        Message::State(s) => StateWire::of(s)?.write(&mut b, &layout::STATE, s.id),
        Message::Located { segment, state: s } => {
            put(&mut b, layout::LOCATED.segment, &segment.to_le_bytes());
            StateWire::of(s)?.write(&mut b, &layout::LOCATED, s.id)
        }
        Message::JunctionRequest { junction, request } => {
            put(&mut b, layout::JUNCTION_REQUEST.junction, &[*junction]);
            write_request(&mut b, &layout::JUNCTION_REQUEST, request)?
        }
        Message::Request(r) => write_request(&mut b, &layout::REQUEST, r)?,
        Message::JunctionExit { junction, id, at } => {
            put(&mut b, layout::JUNCTION_EXIT.junction, &[*junction]);
            write_id_time(&mut b, &layout::JUNCTION_EXIT, *id, *at)
        }
        Message::Grant { id, until: t }
        | Message::Revoke { id, at: t }
        | Message::Exit { id, at: t } => write_id_time(&mut b, &layout::ID_TIME, *id, *t),
        Message::Ego {
            segment,
            lanes,
            state: s,
            v_ref,
        } => {
            let f = layout::EGO;
            if !(1..crate::wire::NO_LANE).contains(lanes) {
                return Err(EncodeError::OutOfRange(Field::Lane));
            }
            put(&mut b, f.state.segment.clone(), &segment.to_le_bytes());
            put(&mut b, f.road_lanes, &[*lanes]);
            StateWire::of(s)?.write(&mut b, &f.state, s.id);
            let v = q(*v_ref, SPEED_RES, 0.0, 65535.0, Field::Speed)? as u16;
            put(&mut b, f.v_ref, &v.to_le_bytes());
            f.len
        }
        Message::Command(c) => write_command(&mut b, c)?,
        Message::Sync { period, last } => {
            let f = layout::SYNC;
            put(&mut b, f.period, &period.to_le_bytes());
            put(&mut b, f.last, &[u8::from(*last)]);
            f.len
        }
    };
    Ok((b, len))
}

/// A request's fields (all but the junction) into their places; the layout's length.
fn write_request<F: Real>(
    b: &mut [u8],
    f: &layout::RequestFields,
    r: &Request<F>,
) -> Result<usize, EncodeError> {
    put(b, f.id.clone(), &r.id.to_le_bytes());
    put(b, f.inlet.clone(), &[track(r.inlet)?]);
    put(b, f.outlet.clone(), &[track(r.outlet)?]);
    let v = q(r.v, SPEED_RES, 0.0, 65535.0, Field::Speed)? as u16;
    put(b, f.speed.clone(), &v.to_le_bytes());
    // u24: the low three bytes.
    put(b, f.s.clone(), &path_position(r.s)?.to_le_bytes());
    put(b, f.arrival.clone(), &time(r.arrival).to_le_bytes());
    // Empty fields in a kind 2 request: nothing is written.
    put(b, f.brake.clone(), &[r.brake.map_or(0, BrakeLimit::tenths)]);
    put(
        b,
        f.length.clone(),
        &[r.length.map_or(0, BodyLength::tenths)],
    );
    Ok(f.len)
}

/// A command's fields into their places; the layout's length. Speed and yaw rate travel
/// as the f32 the planner computed (an f64 planner's are rounded to f32).
fn write_command<F: Real>(b: &mut [u8], c: &Command<F>) -> Result<usize, EncodeError> {
    let f = layout::COMMAND;
    let single = |x: F, field| {
        let x = x.to_f64() as f32;
        x.is_finite()
            .then_some(x)
            .ok_or(EncodeError::OutOfRange(field))
    };
    put(b, f.speed, &single(c.v, Field::Speed)?.to_le_bytes());
    put(b, f.yaw, &single(c.omega, Field::YawRate)?.to_le_bytes());
    put(b, f.status, &[c.status as u8]);
    put(b, f.period, &c.period.to_le_bytes());
    let lanes = lane_nibble(Some(c.lane))? | lane_nibble(c.alpha)? << 4;
    put(b, f.lanes, &[lanes]);
    put(b, f.beta, &[lane_nibble(c.beta)?]);
    Ok(f.len)
}

/// A vehicle id and an instant into their places; the layout's length.
fn write_id_time(b: &mut [u8], f: &layout::IdTimeFields, id: u16, t: Instant) -> usize {
    put(b, f.id.clone(), &id.to_le_bytes());
    put(b, f.time.clone(), &time(t).to_le_bytes());
    f.len
}

/// The message's payload chunks as the frames carry them: payload, zero padding, and the
/// CRC in the last byte of the last chunk.
pub(super) fn protected<F: Real>(
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
pub(super) fn fd_frame<F: Real, Fr: Frame>(
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
