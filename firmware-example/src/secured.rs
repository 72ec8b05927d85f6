//! SecOC on the MCU: what verifying an authenticated message costs here.
//!
//! The node's key is fixed at build time (`FW_SECOC_KEY`, 32 hex digits, read by
//! `build.rs`; a documented development key when unset — never for a vehicle). The
//! controller is in loopback (as in the approach scenario), so the node verifies what it
//! signed itself: its key store holds its own key under its address. Each message is a
//! vehicle state, signed with a fresh freshness value (the period's time in ms), sent as
//! classic CAN (four data frames and the authenticator frame) or as one CAN FD frame,
//! and pushed frame by frame into a reassembler that checks CRC, counter, freshness and
//! the AES-128-CMAC; only that pushing is timed. Before each CAN FD message a copy of it
//! with one payload bit flipped is pushed and must be refused, so the figures are those of
//! a check that works.

use can_gateway::codec::{encode_fd_secured, encode_secured, Verifier};
use can_gateway::secoc::{FreshnessRx, Key, KeyStore};
use can_gateway::{FdFrame, Message, PlainFrame, Reassembler};
use embedded_can::Frame;
use planner_core::{Duration, VehicleState};

include!(concat!(env!("OUT_DIR"), "/secoc_key.rs"));

/// This node's CAN source address.
const SA: u8 = 1;
/// Messages verified per frame format.
pub const MESSAGES: usize = 200;

/// The state sent in period `k`.
fn state(k: u32) -> Message<f32> {
    let t = k as f32 * 0.01;
    Message::State(VehicleState {
        id: u16::from(SA),
        x: 20.0 * t,
        y: 1.8,
        theta: 0.0,
        v: 20.0,
        omega: 0.0,
        lane: 0,
        alpha: None,
        beta: None,
        stamp: crate::scenarios::CLOCK_START
            .saturating_add(Duration::from_millis(10 * u64::from(k))),
        cooperative: true,
        brake: None,
        length: None,
    })
}

/// What the verification run found.
pub struct Verified {
    /// Messages accepted (of [`MESSAGES`]).
    pub accepted: u32,
    /// Tampered copies accepted (must be 0).
    pub forged_accepted: u32,
}

/// The receiver: the key store and freshness state a node keeps.
struct Receiver {
    keys: KeyStore<2>,
    fresh: FreshnessRx<4>,
    rx: Reassembler<4>,
}

impl Receiver {
    fn new() -> Self {
        let mut keys = KeyStore::new();
        // Two slots, one key: cannot fail.
        let _ = keys.insert(SA, Key(KEY));
        Self {
            keys,
            fresh: FreshnessRx::default(),
            rx: Reassembler::new(),
        }
    }

    /// Pushes `frames`; `true` if the last one completed a verified message.
    fn take<Fr: Frame>(&mut self, frames: &[Fr], now_ms: u64) -> bool {
        let mut done = false;
        for f in frames {
            let v = Verifier {
                keys: &self.keys,
                freshness: &mut self.fresh,
            };
            let at = can_gateway::Instant::from_millis(now_ms);
            done = matches!(self.rx.push_secured::<f32, _, 2, 4>(f, at, v), Ok(Some(_)));
        }
        done
    }
}

/// A copy of `f` with one payload bit flipped.
fn flipped<Fr: Frame>(f: &Fr) -> Option<Fr> {
    let mut data = [0u8; 64];
    let n = f.data().len();
    data.get_mut(..n)?.copy_from_slice(f.data());
    *data.get_mut(1)? ^= 0x10;
    Fr::new(f.id(), data.get(..n)?)
}

/// Pushes `frames` into `r`, timing it with `now` into `record(k, ticks)`; `true` if they
/// completed a verified message.
fn timed<Fr: Frame>(
    r: &mut Receiver,
    frames: &[Fr],
    now_ms: u64,
    k: u32,
    now: &mut dyn FnMut() -> u32,
    record: &mut dyn FnMut(usize, u32),
) -> bool {
    let t0 = now();
    let ok = r.take(frames, now_ms);
    record(k as usize, now().wrapping_sub(t0));
    ok
}

/// Signs, sends and verifies [`MESSAGES`] states as classic CAN (`fd` false) or CAN FD,
/// timing each verification with `now` (ticks) into `record(i, ticks)`.
#[inline(never)]
pub fn run(fd: bool, now: &mut dyn FnMut() -> u32, record: &mut dyn FnMut(usize, u32)) -> Verified {
    let key = Key(KEY);
    let mut r = Receiver::new();
    let mut out = Verified {
        accepted: 0,
        forged_accepted: 0,
    };
    for k in 0..MESSAGES as u32 {
        let now_ms = crate::scenarios::CLOCK_START.as_millis() + u64::from(k) * 10;
        let counter = (k % 16) as u8;
        let msg = state(k);
        let ok = if fd {
            let Ok(f) = encode_fd_secured::<f32, FdFrame>(&msg, SA, counter, &key, now_ms) else {
                return out;
            };
            // A tampered copy first (same freshness): refused, and it must not stop the
            // genuine one.
            if let Some(bad) = flipped(&f) {
                out.forged_accepted += u32::from(r.take(&[bad], now_ms));
            }
            timed(&mut r, &[f], now_ms, k, now, record)
        } else {
            let Ok(frames) = encode_secured::<f32, PlainFrame>(&msg, SA, counter, &key, now_ms)
            else {
                return out;
            };
            timed(&mut r, &frames, now_ms, k, now, record)
        };
        out.accepted += u32::from(ok);
    }
    out
}
