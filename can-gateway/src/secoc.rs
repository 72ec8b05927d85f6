//! Message authentication in the manner of AUTOSAR SecOC.
//!
//! CAN has no sender authentication: the source address in an identifier is whatever the
//! writer puts there, and the E2E counter and CRC of [`crate::codec`] protect against
//! faults, not against a node that forges a grant, replays an old one or claims another
//! vehicle's id. A secured message therefore carries an **authenticator**: a MAC over
//!
//! ```text
//! Data ID (kind code, source address) ‖ alive counter ‖ the message's bytes ‖ freshness (u64 BE)
//! ```
//!
//! with AES-128-CMAC (RustCrypto's `aes` and `cmac`; no cryptography is written here),
//! truncated to its leftmost [`MAC_LEN`] bytes, and the low [`FV_LEN`] bytes of the
//! freshness value. Both go in a **trailer** of [`TRAILER_LEN`] bytes: on classic CAN one
//! extra frame after the message's frames, on CAN FD inside the message's one frame.
//!
//! # Freshness: time-based
//! The freshness value is the sender's time in milliseconds on the fleet's shared clock
//! (the same clock the planners' synchronous steps and the state stamps use), made
//! strictly increasing per sender and message kind: `max(now, last + 1)`. Time rather
//! than a counter because
//! - a receiver can check the first message it ever hears from a sender (a vehicle that
//!   joins mid-run, a manager that restarts) without a synchronisation message: it
//!   rebuilds the full value from its own clock, so **resynchronisation is clock
//!   synchronisation** — nothing per sender has to be agreed;
//! - a recorded message replayed later is outside the acceptance window whatever the
//!   receiver remembers, even after the receiver restarted and forgot its last values.
//!
//! # Acceptance
//! A receiver at time `now` takes the full value `fv` that has the received low bits and
//! is nearest to `now`, and accepts the message when
//! 1. it has a key for the sender ([`AuthError::UnknownKey`] otherwise),
//! 2. `|fv − now| ≤` its window ([`AuthError::Stale`] otherwise; default
//!    [`DEFAULT_WINDOW_MS`], far below the 2¹⁶ ms the truncated value can tell apart),
//! 3. `fv` is above the last value accepted from that sender and kind
//!    ([`AuthError::Replayed`] otherwise: an attacker who replays a message inside the
//!    window finds its value taken),
//! 4. the MAC matches in constant time ([`AuthError::BadMac`] otherwise).
//!
//! Only then is `fv` recorded; a rejected message changes nothing. The window bounds how
//! far apart two clocks may drift (sync ticks keep them within one period) and how long a
//! message recorded by an attacker but never delivered to a receiver stays replayable.
//!
//! # Keys
//! One AES-128 key per node (source address), held by every node that must verify it
//! ([`KeyStore`]). Simulations may derive every node's key from one master key
//! ([`derive_key`], NIST SP 800-108 counter mode with CMAC as the PRF); deployed nodes
//! get theirs provisioned (the firmware at build time).

use aes::Aes128;
use cmac::digest::KeyInit;
use cmac::{Cmac, Mac};
use heapless::Vec;

/// Bytes of the truncated MAC on the wire (32 bits).
pub const MAC_LEN: usize = 4;
/// Bytes of the truncated freshness value on the wire (16 bits: 65.5 s of milliseconds).
pub const FV_LEN: usize = 2;
/// Bytes of the trailer: truncated freshness, then truncated MAC.
pub const TRAILER_LEN: usize = FV_LEN + MAC_LEN;
/// Default acceptance window (ms): how far a freshness value may be from the receiver's
/// clock. Far below half the truncated range (32.8 s), so the nearest value is unique.
pub const DEFAULT_WINDOW_MS: u64 = 500;
/// The largest window a receiver may use: below half the truncated range, or the
/// nearest full value would be ambiguous.
pub const MAX_WINDOW_MS: u64 = (1 << (8 * FV_LEN)) / 2 - 1;

/// An AES-128 key.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Key(pub [u8; 16]);

impl core::fmt::Debug for Key {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        // Never print key material.
        f.write_str("Key(…)")
    }
}

/// Why a secured message was rejected (nothing was recorded).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum AuthError {
    /// No key for the sender's address.
    UnknownKey,
    /// The MAC does not match.
    BadMac,
    /// The freshness value is not above the last accepted one of this sender and kind.
    Replayed,
    /// The freshness value is outside the acceptance window around the receiver's clock.
    Stale,
    /// The receiver tracks as many (sender, kind) pairs as it can hold.
    Full,
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for AuthError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::UnknownKey => f.write_str("no key for the sender's address"),
            Self::BadMac => f.write_str("the MAC does not match"),
            Self::Replayed => f.write_str(
                "the freshness value is not above the last accepted one of this sender and kind",
            ),
            Self::Stale => f.write_str(
                "the freshness value is outside the acceptance window around the receiver's clock",
            ),
            Self::Full => {
                f.write_str("the receiver tracks as many (sender, kind) pairs as it can hold")
            }
        }
    }
}

impl core::error::Error for AuthError {}

/// The Data ID of a message: its kind code and its sender's address.
pub fn data_id(kind_code: u8, sa: u8) -> u16 {
    u16::from(kind_code) << 8 | u16::from(sa)
}

/// The full, untruncated CMAC over the authenticated data.
fn cmac(key: &Key, data_id: u16, counter: u8, message: &[u8], fv: u64) -> Cmac<Aes128> {
    let mut m = <Cmac<Aes128> as KeyInit>::new(&key.0.into());
    m.update(&data_id.to_be_bytes());
    m.update(&[counter & 0x0F]);
    m.update(message);
    m.update(&fv.to_be_bytes());
    m
}

/// The truncated MAC (leftmost [`MAC_LEN`] bytes) of a message.
pub fn mac(key: &Key, data_id: u16, counter: u8, message: &[u8], fv: u64) -> [u8; MAC_LEN] {
    let full = cmac(key, data_id, counter, message, fv)
        .finalize()
        .into_bytes();
    let mut out = [0; MAC_LEN];
    for (o, b) in out.iter_mut().zip(full.iter()) {
        *o = *b;
    }
    out
}

/// The trailer of a message: truncated freshness (little-endian), truncated MAC.
pub fn trailer(key: &Key, data_id: u16, counter: u8, message: &[u8], fv: u64) -> [u8; TRAILER_LEN] {
    let mut t = [0; TRAILER_LEN];
    let low = (fv as u16).to_le_bytes();
    let m = mac(key, data_id, counter, message, fv);
    for (o, b) in t.iter_mut().zip(low.iter().chain(m.iter())) {
        *o = *b;
    }
    t
}

/// A node's key derived from a simulation's master key: NIST SP 800-108 counter mode,
/// PRF = AES-128-CMAC, one block: `[1] ‖ "SecOC node key" ‖ [0] ‖ [sa] ‖ [0x00, 0x80]`.
/// For simulations only: a deployed node's key is provisioned, never derivable by peers.
pub fn derive_key(master: &Key, sa: u8) -> Key {
    let mut m = <Cmac<Aes128> as KeyInit>::new(&master.0.into());
    m.update(&[1]);
    m.update(b"SecOC node key");
    m.update(&[0, sa, 0x00, 0x80]);
    let out = m.finalize().into_bytes();
    let mut k = [0; 16];
    k.copy_from_slice(&out);
    Key(k)
}

/// The keys a node verifies with (and its own, to send with), by source address.
#[derive(Debug, Clone)]
pub struct KeyStore<const CAP: usize> {
    keys: Vec<(u8, Key), CAP>,
}

impl<const CAP: usize> Default for KeyStore<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAP: usize> KeyStore<CAP> {
    /// No keys.
    pub const fn new() -> Self {
        Self { keys: Vec::new() }
    }

    /// Sets the key of `sa` (replacing an older one); `Err(Full)` if there is no room.
    pub fn insert(&mut self, sa: u8, key: Key) -> Result<(), AuthError> {
        match self.keys.iter_mut().find(|(a, _)| *a == sa) {
            Some(slot) => slot.1 = key,
            None => self.keys.push((sa, key)).map_err(|_| AuthError::Full)?,
        }
        Ok(())
    }

    /// The key of `sa`.
    pub fn get(&self, sa: u8) -> Option<&Key> {
        self.keys.iter().find(|(a, _)| *a == sa).map(|(_, k)| k)
    }
}

/// The sender's side of freshness: strictly increasing values per message kind.
#[derive(Debug, Clone, Default)]
pub struct FreshnessTx {
    /// Last value sent, per kind code (codes are below 16).
    last: [u64; 16],
}

impl FreshnessTx {
    /// No message sent yet.
    pub const fn new() -> Self {
        Self { last: [0; 16] }
    }

    /// The freshness value of the next message of `kind_code` sent at `now_ms`: the time,
    /// or one above the last value if the clock has not moved on (two messages of a kind
    /// in one millisecond).
    pub fn next(&mut self, kind_code: u8, now_ms: u64) -> u64 {
        let mut fv = now_ms;
        if let Some(slot) = self.last.get_mut(usize::from(kind_code & 0x0F)) {
            fv = fv.max(slot.saturating_add(1));
            *slot = fv;
        }
        fv
    }
}

/// The receiver's side: the last accepted freshness per (sender, kind), and the window.
#[derive(Debug, Clone)]
pub struct FreshnessRx<const CAP: usize> {
    last: Vec<(u16, u64), CAP>,
    window_ms: u64,
}

impl<const CAP: usize> Default for FreshnessRx<CAP> {
    fn default() -> Self {
        Self::new(DEFAULT_WINDOW_MS)
    }
}

impl<const CAP: usize> FreshnessRx<CAP> {
    /// Nothing accepted yet; `window_ms` is clamped to [`MAX_WINDOW_MS`].
    pub const fn new(window_ms: u64) -> Self {
        let window_ms = if window_ms > MAX_WINDOW_MS {
            MAX_WINDOW_MS
        } else {
            window_ms
        };
        Self {
            last: Vec::new(),
            window_ms,
        }
    }

    /// The full freshness value with the low bits `low` nearest to `now_ms`.
    pub fn full_value(low: u16, now_ms: u64) -> u64 {
        const RANGE: u64 = 1 << (8 * FV_LEN);
        let candidate = (now_ms & !(RANGE - 1)) | u64::from(low);
        let mut best = candidate;
        for c in [candidate.checked_sub(RANGE), candidate.checked_add(RANGE)]
            .into_iter()
            .flatten()
        {
            if c.abs_diff(now_ms) < best.abs_diff(now_ms) {
                best = c;
            }
        }
        best
    }

    /// Verifies a secured message from `sa` whose trailer is `trailer`, at the receiver's
    /// time `now_ms`, and records its freshness if it is accepted. `message` is every
    /// byte the MAC covers after the Data ID and counter (the message's frames' payload).
    #[allow(clippy::too_many_arguments)]
    pub fn verify<const K: usize>(
        &mut self,
        keys: &KeyStore<K>,
        kind_code: u8,
        sa: u8,
        counter: u8,
        message: &[u8],
        trailer: &[u8; TRAILER_LEN],
        now_ms: u64,
    ) -> Result<u64, AuthError> {
        let key = keys.get(sa).ok_or(AuthError::UnknownKey)?;
        let id = data_id(kind_code, sa);
        let [l0, l1, ..] = *trailer;
        let low = u16::from_le_bytes([l0, l1]);
        let fv = Self::full_value(low, now_ms);
        if fv.abs_diff(now_ms) > self.window_ms {
            return Err(AuthError::Stale);
        }
        let pos = self.last.iter().position(|(d, _)| *d == id);
        if pos
            .and_then(|i| self.last.get(i))
            .is_some_and(|(_, last)| fv <= *last)
        {
            return Err(AuthError::Replayed);
        }
        cmac(key, id, counter, message, fv)
            .verify_truncated_left(trailer.get(FV_LEN..).unwrap_or(&[]))
            .map_err(|_| AuthError::BadMac)?;
        match pos.and_then(|i| self.last.get_mut(i)) {
            Some(slot) => slot.1 = fv,
            None => self.last.push((id, fv)).map_err(|_| AuthError::Full)?,
        }
        Ok(fv)
    }

    /// Forgets every accepted value (a restarted receiver): the window alone then guards
    /// against replays until each sender is heard again.
    pub fn reset(&mut self) {
        self.last.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::fmt::Write;

    const K1: Key = Key([
        0x2b, 0x7e, 0x15, 0x16, 0x28, 0xae, 0xd2, 0xa6, 0xab, 0xf7, 0x15, 0x88, 0x09, 0xcf, 0x4f,
        0x3c,
    ]);

    #[test]
    fn cmac_matches_the_rfc_4493_vectors() {
        // RFC 4493 §4, Example 2 (16 bytes): the MAC is the library's, checked here so a
        // wrong key schedule or cipher choice cannot pass unnoticed.
        let msg = [
            0x6b, 0xc1, 0xbe, 0xe2, 0x2e, 0x40, 0x9f, 0x96, 0xe9, 0x3d, 0x7e, 0x11, 0x73, 0x93,
            0x17, 0x2a,
        ];
        let mut m = <Cmac<Aes128> as KeyInit>::new(&K1.0.into());
        m.update(&msg);
        let tag = m.finalize().into_bytes();
        assert_eq!(
            tag.as_slice(),
            &[
                0x07, 0x0a, 0x16, 0xb4, 0x6b, 0x4d, 0x41, 0x44, 0xf7, 0x9b, 0xdd, 0x9d, 0xd0, 0x4a,
                0x28, 0x7c
            ]
        );
        // Example 1 (empty message).
        let m = <Cmac<Aes128> as KeyInit>::new(&K1.0.into());
        assert_eq!(
            m.finalize().into_bytes().as_slice(),
            &[
                0xbb, 0x1d, 0x69, 0x29, 0xe9, 0x59, 0x37, 0x28, 0x7f, 0xa3, 0x7d, 0x12, 0x9b, 0x75,
                0x67, 0x46
            ]
        );
    }

    #[test]
    fn the_mac_covers_the_documented_bytes_in_order() {
        // The authenticated data, laid out by hand as the module documents it: Data ID
        // (kind code, then sender address, big-endian), the alive counter's 4 bits, the
        // payload, the full 64-bit freshness value (big-endian). Another implementation
        // (a tester, a gateway in C) must compute the same MAC from this description.
        let msg = [0xA5u8, 0x5A, 0x01, 0x80, 0xFF, 0x00, 0x42];
        for counter in [0u8, 3, 9, 15] {
            let fv = 0x0001_2345_6789_ABCDu64;
            let mut bytes = [0u8; 3 + 7 + 8];
            bytes[..3].copy_from_slice(&[0x01, 0x05, counter]);
            bytes[3..10].copy_from_slice(&msg);
            bytes[10..].copy_from_slice(&fv.to_be_bytes());
            let mut m = <Cmac<Aes128> as KeyInit>::new(&K1.0.into());
            m.update(&bytes);
            let full = m.finalize().into_bytes();
            assert_eq!(
                mac(&K1, data_id(1, 0x05), counter, &msg, fv).as_slice(),
                full.get(..MAC_LEN).expect("16 bytes"),
                "counter {counter}"
            );
        }
    }

    fn store() -> KeyStore<4> {
        let mut k = KeyStore::new();
        k.insert(0x05, derive_key(&K1, 0x05)).expect("room");
        k.insert(0xF1, derive_key(&K1, 0xF1)).expect("room");
        k
    }

    #[test]
    fn a_fresh_message_is_accepted_once() {
        let keys = store();
        let key = keys.get(0x05).copied().expect("key");
        let mut rx = FreshnessRx::<4>::default();
        let msg = [1, 2, 3, 4, 5, 6, 7];
        let t = trailer(&key, data_id(1, 0x05), 3, &msg, 70_000);
        assert_eq!(rx.verify(&keys, 1, 0x05, 3, &msg, &t, 70_010), Ok(70_000));
        // The same bytes again: replayed.
        assert_eq!(
            rx.verify(&keys, 1, 0x05, 3, &msg, &t, 70_020),
            Err(AuthError::Replayed)
        );
        // A later one is accepted.
        let t2 = trailer(&key, data_id(1, 0x05), 4, &msg, 70_100);
        assert_eq!(rx.verify(&keys, 1, 0x05, 4, &msg, &t2, 70_100), Ok(70_100));
    }

    #[test]
    fn every_field_is_covered_by_the_mac() {
        let keys = store();
        let key = keys.get(0x05).copied().expect("key");
        let msg = [9u8; 14];
        let t = trailer(&key, data_id(1, 0x05), 3, &msg, 1_000);
        let check = |kind: u8, sa: u8, counter: u8, m: &[u8], t: &[u8; TRAILER_LEN]| {
            FreshnessRx::<4>::default().verify(&keys, kind, sa, counter, m, t, 1_000)
        };
        assert_eq!(check(1, 0x05, 3, &msg, &t), Ok(1_000));
        assert_eq!(check(2, 0x05, 3, &msg, &t), Err(AuthError::BadMac), "kind");
        assert_eq!(
            check(1, 0x05, 4, &msg, &t),
            Err(AuthError::BadMac),
            "counter"
        );
        for i in 0..msg.len() {
            let mut m = msg;
            m[i] ^= 1;
            assert_eq!(
                check(1, 0x05, 3, &m, &t),
                Err(AuthError::BadMac),
                "byte {i}"
            );
        }
        for i in 0..TRAILER_LEN {
            let mut u = t;
            u[i] ^= 0x80;
            // A changed freshness byte moves the value out of the window or breaks the MAC.
            assert!(check(1, 0x05, 3, &msg, &u).is_err(), "trailer byte {i}");
        }
        // Another node's key (the manager's address) cannot sign for vehicle 5.
        let forged = trailer(
            keys.get(0xF1).expect("key"),
            data_id(1, 0x05),
            3,
            &msg,
            1_000,
        );
        assert_eq!(check(1, 0x05, 3, &msg, &forged), Err(AuthError::BadMac));
        // A sender without a key.
        assert_eq!(check(1, 0x06, 3, &msg, &t), Err(AuthError::UnknownKey));
    }

    #[test]
    fn the_window_and_the_truncated_value() {
        let keys = store();
        let key = keys.get(0x05).copied().expect("key");
        let msg = [0u8; 7];
        let at = |fv: u64, now: u64, window: u64| {
            let t = trailer(&key, data_id(1, 0x05), 0, &msg, fv);
            FreshnessRx::<4>::new(window).verify(&keys, 1, 0x05, 0, &msg, &t, now)
        };
        assert_eq!(
            at(100_000, 100_500, 500),
            Ok(100_000),
            "at the window's edge"
        );
        assert_eq!(
            at(100_000, 100_501, 500),
            Err(AuthError::Stale),
            "just past it"
        );
        assert_eq!(
            at(100_501, 100_000, 500),
            Err(AuthError::Stale),
            "from the future"
        );
        assert_eq!(at(100_500, 100_000, 500), Ok(100_500));
        // Across a wrap of the 16 low bits, both ways.
        assert_eq!(at(0x1_FFFF, 0x2_0003, 500), Ok(0x1_FFFF));
        assert_eq!(at(0x2_0003, 0x1_FFFF, 500), Ok(0x2_0003));
        // A message recorded 65.536 s ago has the same low bits: its MAC (over the full
        // value) does not verify under today's value.
        assert_eq!(at(100_000, 100_000 + 65_536, 500), Err(AuthError::BadMac));
        // Near time 0 nothing underflows.
        assert_eq!(at(3, 0, 500), Ok(3));
        assert_eq!(FreshnessRx::<1>::full_value(0xFFFF, 0), 0xFFFF);
        assert_eq!(FreshnessRx::<1>::new(u64::MAX).window_ms, MAX_WINDOW_MS);
        // The widest window is just under half the 16-bit range: a value 32.767 s old is
        // still recovered (its nearest full value is the right one) and accepted, and a
        // wider request is clamped to it, never to something narrower.
        assert_eq!(at(100_000, 132_767, u64::MAX), Ok(100_000));
        assert_eq!(at(100_000, 132_768, u64::MAX), Err(AuthError::Stale));
        assert_eq!(FreshnessRx::<1>::new(32_767).window_ms, 32_767);
        assert_eq!(FreshnessRx::<1>::new(32_768).window_ms, 32_767);
    }

    #[test]
    fn a_rejection_changes_nothing_and_a_restart_forgets() {
        let keys = store();
        let key = keys.get(0x05).copied().expect("key");
        let msg = [7u8; 7];
        let mut rx = FreshnessRx::<1>::default();
        let good = trailer(&key, data_id(1, 0x05), 0, &msg, 5_000);
        let mut bad = good;
        bad[FV_LEN] ^= 1;
        assert_eq!(
            rx.verify(&keys, 1, 0x05, 0, &msg, &bad, 5_000),
            Err(AuthError::BadMac)
        );
        assert_eq!(rx.verify(&keys, 1, 0x05, 0, &msg, &good, 5_000), Ok(5_000));
        // Full: a second (sender, kind) does not fit, and is not recorded.
        let other = trailer(&key, data_id(2, 0x05), 0, &msg, 5_001);
        assert_eq!(
            rx.verify(&keys, 2, 0x05, 0, &msg, &other, 5_001),
            Err(AuthError::Full)
        );
        rx.reset();
        // After a restart the window alone guards: the old message is accepted again
        // only while it is still within the window.
        assert_eq!(rx.verify(&keys, 1, 0x05, 0, &msg, &good, 5_400), Ok(5_000));
        rx.reset();
        assert_eq!(
            rx.verify(&keys, 1, 0x05, 0, &msg, &good, 5_600),
            Err(AuthError::Stale)
        );
    }

    #[test]
    fn sender_freshness_strictly_increases_per_kind() {
        let mut tx = FreshnessTx::new();
        assert_eq!(tx.next(1, 10), 10);
        assert_eq!(tx.next(1, 10), 11);
        assert_eq!(
            tx.next(1, 5),
            12,
            "a clock that steps back does not reuse a value"
        );
        assert_eq!(tx.next(2, 10), 10, "kinds are independent");
        assert_eq!(tx.next(1, 100), 100);
    }

    #[test]
    fn derived_keys_differ_per_node_and_master() {
        let a = derive_key(&K1, 1);
        assert_ne!(a, derive_key(&K1, 2));
        assert_ne!(a, derive_key(&Key([0; 16]), 1));
        assert_eq!(a, derive_key(&K1, 1));
        let mut shown = heapless::String::<32>::new();
        write!(shown, "{a:?}").unwrap();
        assert_eq!(shown.as_str(), "Key(…)");
    }
}
