//! Verification of a whole message before it is accepted: CRC, duplicate, plausibility,
//! sender, freshness of states and ticks, room, and last the authenticator
//! ([`crate::secoc`]) — the one check that records something outside its slot.

use super::decode::{decode_body, sender_ok};
use super::{message_crc, DecodeError, Slot};
use crate::layout;
use crate::secoc::{FreshnessRx, KeyStore, TRAILER_LEN};
use crate::wire::{Message, MessageKind, CHUNK};
use planner_core::{Instant, Real};

/// What a secured receiver verifies with: the senders' keys and its freshness record
/// (its clock is the `now` of [`super::Reassembler::push_secured`]).
pub struct Verifier<'a, const K: usize, const R: usize> {
    /// Keys by source address.
    pub keys: &'a KeyStore<K>,
    /// The last accepted freshness per sender and kind.
    pub freshness: &'a mut FreshnessRx<R>,
}

/// Checks a whole message in `slot` (its payload chunks, and `trailer` when secured)
/// and records it there: CRC, duplicate, plausibility, sender, freshness of states and
/// ticks, room (`room`: the slot is already kept, or the reassembler has space for it),
/// and last the authenticator.
pub(super) fn complete<F: Real, const K: usize, const R: usize>(
    slot: &mut Slot,
    room: bool,
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
        MessageKind::State => Some(layout::STATE.stamp),
        MessageKind::Located => Some(layout::LOCATED.stamp),
        MessageKind::Ego => Some(layout::EGO.state.stamp),
        MessageKind::Sync => Some(layout::SYNC.period),
        _ => None,
    }
    .map(|f| u32::from_le_bytes(layout::get(body, f)));
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
    if !room {
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
