//! The attack experiment's oracle: every frame a genuine node of the fleet
//! transmitted, so that a message a receiver accepted can be told from one an intruder
//! forged or replayed.
//!
//! No node consults the ledger to decide anything — it stands where ground truth stands
//! for the monitors: outside the nodes, counting. A receiver that completes a message
//! reports the frame that completed it. A receiver can accept a given frame (identifier
//! and data, byte for byte) at most as often as genuine nodes transmitted it; every
//! acceptance beyond that is a copy nobody genuine sent — a replay — and a frame no
//! genuine node ever transmitted is a forgery. Counting copies rather than comparing
//! times keeps a genuine message heard late (a manager reading the vehicles' SYNC of the
//! period before) from counting as a replay. Only the completing frame of a classic
//! multi-frame message is compared; the intruder writes whole messages, so that frame is
//! as much its own as the others.

use can_gateway::FdFrame;
use embedded_can::{Frame, Id};
use std::collections::hash_map::DefaultHasher;
use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// A frame as the ledger keys it: a 64-bit hash of its identifier (extended or not),
/// whether it is CAN FD, and its data.
fn key(frame: &FdFrame) -> u64 {
    let mut h = DefaultHasher::new();
    match frame.id() {
        Id::Extended(x) => (1u8, x.as_raw()).hash(&mut h),
        Id::Standard(s) => (0u8, u32::from(s.as_raw())).hash(&mut h),
    }
    (frame.is_fd(), frame.data()).hash(&mut h);
    h.finish()
}

/// Transmissions by genuine nodes, and acceptances by each receiver, per frame.
#[derive(Debug, Default)]
struct Counts {
    sent: HashMap<u64, u32>,
    taken: HashMap<(u8, u64), u32>,
}

/// What genuine nodes sent, and what receivers accepted that none of them sent.
#[derive(Debug, Default)]
pub struct Ledger {
    counts: Mutex<Counts>,
    forged: AtomicU64,
    accepted: AtomicU64,
}

impl Ledger {
    /// An empty ledger.
    pub fn new() -> Self {
        Self::default()
    }

    /// A genuine node transmitted `frame`.
    pub fn sent(&self, frame: &FdFrame) {
        if let Ok(mut c) = self.counts.lock() {
            *c.sent.entry(key(frame)).or_default() += 1;
        }
    }

    /// The node at address `receiver` accepted the message that `frame` completed:
    /// counted as forged when it has now taken that frame more often than genuine nodes
    /// sent it.
    pub fn accepted(&self, frame: &FdFrame, receiver: u8) {
        self.accepted.fetch_add(1, Ordering::Relaxed);
        let k = key(frame);
        let genuine = self.counts.lock().is_ok_and(|mut c| {
            let sent = c.sent.get(&k).copied().unwrap_or(0);
            let taken = c.taken.entry((receiver, k)).or_default();
            *taken += 1;
            *taken <= sent
        });
        if !genuine {
            self.forged.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Messages receivers accepted that no genuine node sent (an intruder's forgeries and
    /// replays that got through), summed over receivers.
    pub fn forged_accepted(&self) -> u64 {
        self.forged.load(Ordering::Relaxed)
    }

    /// Messages receivers accepted, genuine or not, summed over receivers.
    pub fn accepted_total(&self) -> u64 {
        self.accepted.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_can::ExtendedId;

    fn frame(b: u8) -> FdFrame {
        let id = ExtendedId::new(0x18FF_1001).expect("29 bits");
        FdFrame::new(id, &[b; 8]).expect("8 bytes")
    }

    #[test]
    fn a_receiver_takes_a_frame_at_most_as_often_as_it_was_sent() {
        let l = Ledger::new();
        l.sent(&frame(1));
        // Two receivers, each once: genuine.
        l.accepted(&frame(1), 3);
        l.accepted(&frame(1), 4);
        assert_eq!(l.forged_accepted(), 0);
        // Receiver 3 again: a copy nobody genuine sent.
        l.accepted(&frame(1), 3);
        assert_eq!(l.forged_accepted(), 1);
        // Bytes no genuine node wrote.
        l.accepted(&frame(2), 3);
        assert_eq!(l.forged_accepted(), 2);
        // Sent again (a stopped vehicle's identical state), taken again: genuine.
        l.sent(&frame(1));
        l.accepted(&frame(1), 4);
        assert_eq!((l.forged_accepted(), l.accepted_total()), (2, 5));
        // A different identifier with the same data is another frame.
        let other = FdFrame::new(ExtendedId::new(0x18FF_1002).expect("29 bits"), &[1; 8]);
        l.accepted(&other.expect("8 bytes"), 4);
        assert_eq!(l.forged_accepted(), 3);
    }
}
