//! Reassembly: frames of one sender and kind collected, in order, into a whole message's
//! payload (classic frames chunk by chunk, a CAN FD frame at once), and handed to
//! [`super::verify`].

use super::verify::{complete, Verifier};
use super::{DecodeError, Slot};
use crate::secoc::TRAILER_LEN;
use crate::wire::{
    fd_len, split_id, Message, MessageKind, CHUNK, FD_INDEX, FD_SECURED_INDEX, MAX_FRAMES,
};
use embedded_can::{Frame, Id};
use heapless::Vec;
use planner_core::{Instant, Real};

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
///     length: None,
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
    pub(super) slots: Vec<Slot, CAP>,
}

impl<const CAP: usize> Default for Reassembler<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAP: usize> Reassembler<CAP> {
    /// An empty reassembler (`const`: a `static` can hold one, off the stack).
    pub const fn new() -> Self {
        Self { slots: Vec::new() }
    }

    /// Takes one frame received at `now` (the receiver's clock): the times in a message
    /// it completes are restored, from the wire's low 32 bits of milliseconds, as the
    /// instants nearest `now` ([`super::restore_millis`]).
    pub fn push<F: Real, Fr: Frame>(
        &mut self,
        frame: &Fr,
        now: Instant,
    ) -> Result<Option<Message<F>>, DecodeError> {
        self.take::<F, Fr, 0, 0>(frame, now, None)
    }

    /// Takes one frame of a secured stream received at `now`: a message is accepted only
    /// after its authenticator frame (see [`super::encode_secured`]) verifies under `v` (its
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
            let room = pos.is_some() || !self.slots.is_full();
            result = Some(complete(&mut slot, room, counter, &trailer, now, auth)?);
        }
        match pos.and_then(|i| self.slots.get_mut(i)) {
            Some(s) => *s = slot,
            None => self.slots.push(slot).map_err(|_| DecodeError::Full)?,
        }
        Ok(result)
    }
}

/// Takes classic frame `index` of `slot`'s kind into `slot` (the authenticator frame's
/// trailer into `trailer` when `secured`): its alive counter, and whether the message is
/// now whole.
pub(super) fn classic_chunk(
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
pub(super) fn fd_chunks(
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
