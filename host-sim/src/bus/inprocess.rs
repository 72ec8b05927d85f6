//! The in-process bus: a broadcast medium delivering in send order, deterministic,
//! injecting [`Faults`] when asked, and — once told where its nodes are — a radio of
//! limited range.
//!
//! **Range.** A real V2V/V2I radio reaches a few hundred metres; this medium, given a
//! range ([`InProcessBus::set_range`]) and the nodes' positions each period
//! ([`Bus::locate`]), delivers a message only to nodes within that range of its sender
//! when it is sent. The world sets the range to the relevance radius of the vehicles'
//! views plus what two vehicles can close in the notification bound, so every message
//! that can matter arrives: what the planners know is what they knew with a world-wide
//! broadcast. What it buys is cost: a world of N vehicles delivers O(N·k) messages per
//! period, k the vehicles in range, instead of O(N²). A node never located (a vehicle that
//! left the world and still repeats that it did) is heard, and hears, everywhere.
//!
//! **Delays.** Deliveries wait in a per-node heap ordered by (delivery time, send order),
//! so a bus that holds seconds of traffic (delays of up to 10 s) costs O(log n) per
//! message rather than a sorted insert.

use super::{Bus, BusError, FaultStats, Faults, Message, Received};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap, VecDeque};

/// When a delivery is due: (time bits, send order). Delivery times are ≥ 0, so their
/// bits order as the times do; the send order breaks ties.
type Due = (u64, u64);

/// A delivery waiting in a node's heap.
#[derive(Debug, Clone, Copy)]
struct Pending {
    due: Due,
    r: Received,
}

impl PartialEq for Pending {
    fn eq(&self, o: &Self) -> bool {
        self.due == o.due
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Pending {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.due.cmp(&o.due)
    }
}

/// One node's deliveries still to come.
#[derive(Debug, Clone, Default)]
struct Queue {
    /// Deliveries in send order at the time of sending (a perfect bus).
    now: Vec<Received>,
    /// Deliveries at later times (a bus with faults), earliest first — and deliveries
    /// dropped since (see `sent`), skipped when they come up and swept out when they
    /// outnumber the live ones.
    later: BinaryHeap<Reverse<Pending>>,
    /// Per (sender, subject), the live deliveries of `later` in the order they were sent,
    /// with their stamps. A delivery due after a newer one of the same sender and subject
    /// would be dropped on arrival (`newest`), so it is dropped when the newer one is
    /// sent: what a 10 s delay would otherwise keep is 10 s of every neighbour's messages
    /// per receiver, gigabytes in a world of hundreds.
    sent: HashMap<(u16, u16), VecDeque<(Due, planner_core::Instant)>>,
    /// Live deliveries (the entries of `sent`).
    live: usize,
}

impl Queue {
    /// Queues `r`, due at `due`, and drops what it makes useless; returns how many.
    fn push_later(&mut self, due: Due, r: Received) -> u64 {
        let (subject, stamp) = r.msg.subject();
        let mine = self.sent.entry((r.msg.sender(), subject)).or_default();
        let mut dropped = 0;
        while let Some(&(d, old)) = mine.back() {
            if !(d > due && old <= stamp) {
                break;
            }
            mine.pop_back();
            dropped += 1;
        }
        mine.push_back((due, stamp));
        self.live = self.live + 1 - dropped;
        self.later.push(Reverse(Pending { due, r }));
        if self.later.len() > 2 * self.live + 64 {
            let sent = &self.sent;
            self.later.retain(|Reverse(p)| is_live(sent, p));
        }
        dropped as u64
    }

    /// The earliest live delivery due at `now` or before, taken off.
    fn pop_due(&mut self, now: f64) -> Option<Received> {
        while let Some(Reverse(p)) = self.later.peek() {
            if !(p.r.at <= now) {
                return None;
            }
            let p = *p;
            self.later.pop();
            let (subject, _) = p.r.msg.subject();
            let key = (p.r.msg.sender(), subject);
            let Some(mine) = self.sent.get_mut(&key) else {
                continue;
            };
            let Some(i) = mine.iter().position(|&(d, _)| d == p.due) else {
                continue;
            };
            mine.remove(i);
            if mine.is_empty() {
                self.sent.remove(&key);
            }
            self.live -= 1;
            return Some(p.r);
        }
        None
    }
}

/// `true` if `p` is still to be delivered (not dropped as overtaken).
fn is_live(
    sent: &HashMap<(u16, u16), VecDeque<(Due, planner_core::Instant)>>,
    p: &Pending,
) -> bool {
    let (subject, _) = p.r.msg.subject();
    sent.get(&(p.r.msg.sender(), subject))
        .is_some_and(|mine| mine.iter().any(|&(d, _)| d == p.due))
}

/// The nodes' positions in a grid of cells of the range's size: the candidates within
/// range of a point are in its cell and the eight around it.
#[derive(Debug, Clone, Default)]
struct Cells {
    size: f64,
    cells: HashMap<(i64, i64), Vec<usize>>,
    /// Nodes with no position: every sender reaches them.
    everywhere: Vec<usize>,
}

impl Cells {
    fn cell(&self, (x, y): (f64, f64)) -> (i64, i64) {
        (
            (x / self.size).floor() as i64,
            (y / self.size).floor() as i64,
        )
    }
}

/// The in-process bus: zero delay, no loss, delivery in send order — unless built
/// [`InProcessBus::with_faults`] — and world-wide unless given a range.
#[derive(Debug, Clone)]
pub struct InProcessBus {
    nodes: Vec<u16>,
    /// Each node's index in `nodes` (every send and receive looks its node up).
    slot: HashMap<u16, usize>,
    queues: Vec<Queue>,
    /// Per node, newest stamp delivered per (sender, subject).
    newest: Vec<HashMap<(u16, u16), planner_core::Instant>>,
    /// Per node, where it is (if told).
    at: Vec<Option<(f64, f64)>>,
    /// Radio range (m), if limited.
    range: Option<f64>,
    /// The grid of positions, rebuilt after they change.
    cells: Option<Cells>,
    faults: Faults,
    rng: ChaCha8Rng,
    /// Period h, for duplicate spacing.
    h: f64,
    /// Messages sent so far (their send order, for ties in delivery time).
    sent: u64,
    /// Messages injected faults dropped (lost or silenced), duplicated, held back.
    stats: FaultStats,
}

impl Default for InProcessBus {
    fn default() -> Self {
        Self::new(&[])
    }
}

impl InProcessBus {
    /// A perfect bus with the given nodes attached.
    pub fn new(nodes: &[u16]) -> Self {
        Self::with_faults(nodes, Faults::NONE, 0, 0.01)
    }

    /// A bus injecting `faults` (validated by the caller), drawn from `seed`; `h` is the
    /// period (duplicates arrive up to one period late).
    pub fn with_faults(nodes: &[u16], faults: Faults, seed: u64, h: f64) -> Self {
        Self {
            nodes: nodes.to_vec(),
            slot: nodes.iter().enumerate().map(|(i, &n)| (n, i)).collect(),
            queues: nodes.iter().map(|_| Queue::default()).collect(),
            newest: nodes.iter().map(|_| HashMap::new()).collect(),
            at: nodes.iter().map(|_| None).collect(),
            range: None,
            cells: None,
            faults,
            rng: crate::reference::instances::rng(seed ^ 0xfa17),
            h,
            sent: 0,
            stats: FaultStats::default(),
        }
    }

    /// From now on a message reaches only the nodes within `range_m` of its sender when
    /// it is sent (nodes not located reach and are reached by all); `None`: everywhere.
    pub fn set_range(&mut self, range_m: Option<f64>) {
        self.range = range_m.filter(|r| r.is_finite() && *r > 0.0);
        self.cells = None;
    }

    fn index(&self, node: u16) -> Result<usize, BusError> {
        self.slot
            .get(&node)
            .copied()
            .ok_or(BusError::UnknownNode(node))
    }

    /// The grid of the nodes' positions, built if stale.
    fn cells(&mut self, range: f64) -> &Cells {
        if self.cells.is_none() {
            let mut c = Cells {
                size: range,
                ..Cells::default()
            };
            for (i, p) in self.at.iter().enumerate() {
                match p {
                    Some(p) => c.cells.entry(c.cell(*p)).or_default().push(i),
                    None => c.everywhere.push(i),
                }
            }
            self.cells = Some(c);
        }
        self.cells.get_or_insert_with(Cells::default)
    }

    /// The receivers of a message from node `me`: every other node, or those in range.
    fn receivers(&mut self, me: usize) -> Vec<usize> {
        let (Some(range), Some(Some(p))) = (self.range, self.at.get(me).copied()) else {
            return (0..self.nodes.len()).filter(|&i| i != me).collect();
        };
        self.cells(range);
        // Borrowed, not copied: a world of n nodes sends n messages a period.
        let (Some(cells), at) = (self.cells.as_ref(), &self.at) else {
            return Vec::new();
        };
        let (cx, cy) = cells.cell(p);
        let mut out: Vec<usize> = cells.everywhere.clone();
        // Squared distances: no square root per pair.
        let reach = range * range;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for &i in cells.cells.get(&(cx + dx, cy + dy)).into_iter().flatten() {
                    let Some(Some(q)) = at.get(i) else { continue };
                    let (ex, ey) = (q.0 - p.0, q.1 - p.1);
                    if ex * ex + ey * ey <= reach {
                        out.push(i);
                    }
                }
            }
        }
        // Send order of the receivers: the nodes' order, as a world-wide broadcast has it.
        out.sort_unstable();
        out.retain(|&i| i != me);
        out
    }
}

impl Bus for InProcessBus {
    fn fault_stats(&self) -> FaultStats {
        self.stats
    }

    fn attach(&mut self, node: u16) -> Result<(), BusError> {
        if !self.slot.contains_key(&node) {
            self.slot.insert(node, self.nodes.len());
            self.nodes.push(node);
            self.queues.push(Queue::default());
            self.newest.push(HashMap::new());
            self.at.push(None);
            self.cells = None;
        }
        Ok(())
    }

    fn detach(&mut self, node: u16) {
        if let Ok(i) = self.index(node) {
            self.nodes.remove(i);
            // The nodes after it moved down one.
            self.slot = self
                .nodes
                .iter()
                .enumerate()
                .map(|(i, &n)| (n, i))
                .collect();
            self.queues.remove(i);
            self.newest.remove(i);
            self.at.remove(i);
            self.cells = None;
        }
    }

    fn locate(&mut self, node: u16, x: f64, y: f64) {
        if let Ok(i) = self.index(node) {
            if let Some(p) = self.at.get_mut(i) {
                if *p != Some((x, y)) {
                    *p = Some((x, y));
                    self.cells = None;
                }
            }
        }
    }

    fn send(&mut self, from: u16, msg: &Message, now: f64) -> Result<(), BusError> {
        let me = self.index(from)?;
        let f = self.faults;
        if f.silent.is_some_and(|s| s.id == from && now >= s.from_s) {
            self.stats.silenced += 1;
            return Ok(());
        }
        let receivers = self.receivers(me);
        if f.is_none() {
            for i in receivers {
                if let Some(q) = self.queues.get_mut(i) {
                    q.now.push(Received { msg: *msg, at: now });
                }
            }
            return Ok(());
        }
        for i in receivers {
            if self.rng.random_bool(f.loss) {
                self.stats.lost += 1;
                continue;
            }
            let mut at = now + f.delay_s + self.rng.random_range(0.0..=f.jitter_s);
            if self.rng.random_bool(f.reorder) {
                at += f.reorder_s;
                self.stats.reordered += 1;
            }
            let dup = self.rng.random_bool(f.duplicate);
            let extra = self.rng.random_range(0.0..=f.jitter_s) + self.h;
            let mut later = vec![at];
            if dup {
                self.stats.duplicated += 1;
                later.push(at + extra);
            }
            for t in later {
                self.sent += 1;
                if let Some(q) = self.queues.get_mut(i) {
                    let r = Received { msg: *msg, at: t };
                    self.stats.dropped_old += q.push_later((t.to_bits(), self.sent), r);
                }
            }
        }
        Ok(())
    }

    fn receive(&mut self, node: u16, now: f64, out: &mut Vec<Received>) -> Result<(), BusError> {
        let i = self.index(node)?;
        let (Some(q), Some(newest)) = (self.queues.get_mut(i), self.newest.get_mut(i)) else {
            return Err(BusError::UnknownNode(node));
        };
        if self.faults.is_none() {
            // In order and unique by construction: nothing to drop.
            out.append(&mut q.now);
            return Ok(());
        }
        while let Some(r) = q.pop_due(now) {
            // Receivers do not know the sender of a broadcast beyond what it says about
            // itself; the subject is the sender for everything but grants (manager → id).
            let (subject, stamp) = r.msg.subject();
            let sender = r.msg.sender();
            match newest.get(&(sender, subject)) {
                Some(&last) if stamp <= last => self.stats.dropped_old += 1,
                _ => {
                    newest.insert((sender, subject), stamp);
                    out.push(r);
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use planner_core::Instant;

    /// What a receiver keeps of a delivery: the newest stamp per sender and subject.
    fn keep(newest: &mut HashMap<(u16, u16), Instant>, r: Received, out: &mut Vec<String>) {
        let (subject, stamp) = r.msg.subject();
        let key = (r.msg.sender(), subject);
        if newest.get(&key).is_some_and(|&last| stamp <= last) {
            return;
        }
        newest.insert(key, stamp);
        out.push(format!("{:?} at {}", r.msg, r.at));
    }

    /// Dropping a delivery when a newer one of its sender and subject that is due before
    /// it is sent changes nothing a receiver takes: random sends (three senders, stamps
    /// that rise with repeats, due times out of order, two kinds of message sharing a
    /// subject) and random receive times give, after the receiver's newest-stamp filter,
    /// exactly what keeping every delivery gives — with fewer held.
    #[test]
    fn dropping_overtaken_deliveries_changes_nothing_taken() {
        let mut rng = crate::reference::instances::rng(5);
        let (mut held, mut kept_all) = (0, 0);
        for case in 0..300 {
            let mut q = Queue::default();
            let mut all: Vec<(Due, Received)> = Vec::new();
            let (mut na, mut nb) = (HashMap::new(), HashMap::new());
            let (mut got, mut want) = (Vec::new(), Vec::new());
            let mut stamps = [0u64; 3];
            let mut now = 0.0;
            for seq in 0..400u64 {
                let id: u16 = rng.random_range(1..=3);
                let k = usize::from(id - 1);
                stamps[k] += rng.random_range(0..3);
                let at = Instant::from_micros(stamps[k] * 10_000);
                let msg = if rng.random_bool(0.5) {
                    Message::Gone { id, at }
                } else {
                    Message::Left {
                        id,
                        at,
                        junction: 0,
                    }
                };
                let t: f64 = now + rng.random_range(0.0..2.0);
                let r = Received { msg, at: t };
                q.push_later((t.to_bits(), seq), r);
                all.push(((t.to_bits(), seq), r));
                held = held.max(q.live);
                kept_all = kept_all.max(all.len());
                if rng.random_bool(0.2) {
                    now += rng.random_range(0.0..0.6);
                    while let Some(r) = q.pop_due(now) {
                        keep(&mut na, r, &mut got);
                    }
                    all.sort_by_key(|e| e.0);
                    let (due, rest): (Vec<_>, Vec<_>) = all.drain(..).partition(|e| e.1.at <= now);
                    all = rest;
                    for (_, r) in due {
                        keep(&mut nb, r, &mut want);
                    }
                }
            }
            assert_eq!(got, want, "case {case}");
            assert_eq!(q.live, q.sent.values().map(VecDeque::len).sum::<usize>());
            assert!(q.live <= all.len() && q.later.len() <= 2 * q.live + 64);
        }
        assert!(
            held * 2 < kept_all,
            "held at most {held}, against {kept_all}"
        );
    }
}
