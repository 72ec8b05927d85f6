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
//! **Delays.** A delivery due later waits in its *stream* — the deliveries from one sender,
//! about one subject, to one receiver — and a delivery that a newer one of its stream will
//! overtake is dropped when that one is sent (the receiver would drop it on arrival: it
//! takes only what is newer than what it has). The streams are kept by sender, so that a
//! sender's period — one message to each of the k nodes in range — works in its own small
//! table rather than in k receivers' tables scattered through memory; each receiver has a
//! heap of *wake-ups*, (due time, send order) of the earliest delivery of each stream
//! that comes to it. A 10 s delay with 10 s of jitter on 400 vehicles cost 13.6× the
//! clean bus per simulated second with per-receiver tables (two cache misses per
//! delivery, 85 % of the run in them); see docs/redteam.md for what it costs now.

use super::{Bus, BusError, FaultStats, Faults, Message, Received};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use smallvec::SmallVec;
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};
use std::rc::Rc;

/// When a delivery is due: (time bits, send order). Delivery times are ≥ 0, so their
/// bits order as the times do; the send order breaks ties.
type Due = (u64, u64);

/// One node's deliveries due at once (a perfect bus), in send order.
#[derive(Debug, Clone, Default)]
struct Queue {
    now: Vec<Received>,
}

/// A receiver's wake-up: the due time of the earliest delivery of one of its streams,
/// and the stream's (sender, subject). A wake-up whose delivery was dropped since, or
/// came already, is skipped when it comes up (nothing matches its due time, unique by
/// its send order).
type Wake = Reverse<(Due, u16, u16)>;

/// One delivery still to come: when it is due, the sender's stamp (what overtaking
/// compares), and the message — shared by every delivery of one send, so that a stream
/// holds a pointer where it held a copy of the message in a table of its own (a second
/// cache miss, and an allocation, per delivery).
#[derive(Debug, Clone)]
struct Step {
    due: Due,
    stamp: planner_core::Instant,
    msg: Rc<Message>,
}

impl Step {
    /// The delivery: the message, at its due time (the bits it was queued with).
    fn received(&self) -> Received {
        Received {
            msg: *self.msg,
            at: f64::from_bits(self.due.0),
        }
    }
}

/// One stream's deliveries still to come, in send order, inline, so that what every send
/// reads and drops — the last due times, and the earliest — lies in the sender's own
/// table (a stream holds a handful: with a delay jittered over J seconds, about the
/// logarithm of J / h).
#[derive(Debug, Clone, Default)]
struct Stream {
    steps: SmallVec<[Step; 8]>,
    /// The earliest due time of `steps`, if any.
    first: Option<Due>,
}

impl Stream {
    /// The earliest due time, computed again.
    fn earliest(&self) -> Option<Due> {
        self.steps.iter().map(|e| e.due).min()
    }
}

/// One sender's streams (its messages as [`Message::sender`] names it), by (receiver,
/// subject): the keys sorted apart from the streams, so that finding one reads a few
/// bytes of a table the sender's period keeps in cache.
#[derive(Debug, Clone, Default)]
struct Outgoing {
    keys: Vec<(u16, u16)>,
    streams: Vec<Stream>,
}

impl Outgoing {
    /// Queues `r`, due at `due`, on its stream to `to` and drops the deliveries of that
    /// stream it overtakes; returns how many it dropped and, if the stream's earliest
    /// delivery changed, when that one is due (a wake-up for the receiver).
    ///
    /// `next` is where the stream to the previous receiver of this message was, plus one:
    /// receivers come in the order of the nodes, which is the order of their ids but
    /// after an id wraps, so the stream sought is usually the next one — the table is
    /// walked in order, which the processor prefetches, rather than searched.
    fn push(
        &mut self,
        next: &mut usize,
        to: u16,
        due: Due,
        msg: &Rc<Message>,
    ) -> (u64, Option<Due>) {
        let (subject, stamp) = msg.subject();
        let key = (to, subject);
        let i = match self.keys.get(*next) {
            Some(&k) if k == key => *next,
            _ => match self.keys.binary_search(&key) {
                Ok(i) => i,
                Err(i) => {
                    self.keys.insert(i, key);
                    self.streams.insert(i, Stream::default());
                    i
                }
            },
        };
        *next = i + 1;
        let Some(stream) = self.streams.get_mut(i) else {
            return (0, None);
        };
        let before = stream.first;
        let (mut dropped, mut lost_first) = (0, false);
        while let Some(last) = stream.steps.last() {
            if !(last.due > due && last.stamp <= stamp) {
                break;
            }
            lost_first |= Some(last.due) == before;
            stream.steps.pop();
            dropped += 1;
        }
        stream.steps.push(Step {
            due,
            stamp,
            msg: Rc::clone(msg),
        });
        stream.first = if lost_first {
            stream.earliest()
        } else {
            Some(before.map_or(due, |b| b.min(due)))
        };
        (dropped, stream.first.filter(|_| stream.first != before))
    }

    /// Takes off the delivery due at `due` on the stream to `to` about `subject`, if it is
    /// still there, with the due time of the stream's next earliest delivery.
    fn take(&mut self, to: u16, subject: u16, due: Due) -> Option<(Received, Option<Due>)> {
        let i = self.keys.binary_search(&(to, subject)).ok()?;
        let stream = self.streams.get_mut(i)?;
        let at = stream.steps.iter().position(|e| e.due == due)?;
        let r = stream.steps.remove(at).received();
        stream.first = stream.earliest();
        let next = stream.first;
        if stream.steps.is_empty() {
            self.remove(i);
        }
        Some((r, next))
    }

    /// Forgets the stream to `to` about `subject` (its receiver left the bus).
    fn forget(&mut self, to: u16, subject: u16) {
        if let Ok(i) = self.keys.binary_search(&(to, subject)) {
            self.remove(i);
        }
    }

    /// Removes stream `i` and its key.
    fn remove(&mut self, i: usize) {
        self.keys.remove(i);
        self.streams.remove(i);
    }
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
    /// Per sender (as [`Message::sender`] names it), its streams of deliveries due later.
    outgoing: HashMap<u16, Outgoing>,
    /// Per node, the wake-ups of the streams that come to it, earliest first.
    wakes: Vec<BinaryHeap<Wake>>,
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
            outgoing: HashMap::new(),
            wakes: nodes.iter().map(|_| BinaryHeap::new()).collect(),
            newest: nodes.iter().map(|_| HashMap::new()).collect(),
            at: nodes.iter().map(|_| None).collect(),
            range: None,
            cells: None,
            faults,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0xfa17),
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
            self.wakes.push(BinaryHeap::new());
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
            // Every stream to it has a wake-up in its heap: their deliveries go with it.
            for Reverse((_, sender, subject)) in self.wakes.remove(i) {
                if let Some(o) = self.outgoing.get_mut(&sender) {
                    o.forget(node, subject);
                }
            }
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
        let sender = msg.sender();
        let subject = msg.subject().0;
        let out = self.outgoing.entry(sender).or_default();
        let shared = Rc::new(*msg);
        let mut next = 0;
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
            if dup {
                self.stats.duplicated += 1;
            }
            let later = std::iter::once(at).chain(dup.then_some(at + extra));
            let (Some(&to), Some(wakes)) = (self.nodes.get(i), self.wakes.get_mut(i)) else {
                continue;
            };
            for t in later {
                self.sent += 1;
                let (dropped, wake) = out.push(&mut next, to, (t.to_bits(), self.sent), &shared);
                self.stats.dropped_old += dropped;
                if let Some(due) = wake {
                    wakes.push(Reverse((due, sender, subject)));
                }
            }
        }
        Ok(())
    }

    fn receive(&mut self, node: u16, now: f64, out: &mut Vec<Received>) -> Result<(), BusError> {
        let i = self.index(node)?;
        let (Some(q), Some(newest), Some(wakes)) = (
            self.queues.get_mut(i),
            self.newest.get_mut(i),
            self.wakes.get_mut(i),
        ) else {
            return Err(BusError::UnknownNode(node));
        };
        if self.faults.is_none() {
            // In order and unique by construction: nothing to drop.
            out.append(&mut q.now);
            return Ok(());
        }
        while let Some(r) = pop_due(wakes, &mut self.outgoing, node, now) {
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

/// The earliest delivery to `node` due at `now` or before, taken off its stream (and the
/// wake-up of that stream's next one queued).
fn pop_due(
    wakes: &mut BinaryHeap<Wake>,
    outgoing: &mut HashMap<u16, Outgoing>,
    node: u16,
    now: f64,
) -> Option<Received> {
    while let Some(&Reverse((due, sender, subject))) = wakes.peek() {
        if !(f64::from_bits(due.0) <= now) {
            return None;
        }
        wakes.pop();
        let Some(o) = outgoing.get_mut(&sender) else {
            continue;
        };
        let Some((r, next)) = o.take(node, subject, due) else {
            continue;
        };
        if let Some(next) = next {
            wakes.push(Reverse((next, sender, subject)));
        }
        if o.keys.is_empty() {
            outgoing.remove(&sender);
        }
        return Some(r);
    }
    None
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
    /// exactly what keeping every delivery gives — with fewer held, and the receiver's
    /// wake-ups as few.
    #[test]
    fn dropping_overtaken_deliveries_changes_nothing_taken() {
        const ME: u16 = 99;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (mut held, mut woken, mut kept_all) = (0, 0, 0);
        for case in 0..300 {
            let mut outgoing: HashMap<u16, Outgoing> = HashMap::new();
            let mut wakes: BinaryHeap<Wake> = BinaryHeap::new();
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
                let due = (t.to_bits(), seq);
                let (_, wake) =
                    outgoing
                        .entry(id)
                        .or_default()
                        .push(&mut 0, ME, due, &Rc::new(msg));
                if let Some(w) = wake {
                    wakes.push(Reverse((w, id, msg.subject().0)));
                }
                all.push((due, r));
                let live: usize = outgoing
                    .values()
                    .flat_map(|o| o.streams.iter())
                    .map(|s| s.steps.len())
                    .sum();
                held = held.max(live);
                woken = woken.max(wakes.len());
                kept_all = kept_all.max(all.len());
                if rng.random_bool(0.2) {
                    now += rng.random_range(0.0..0.6);
                    while let Some(r) = pop_due(&mut wakes, &mut outgoing, ME, now) {
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
        }
        assert!(
            held * 2 < kept_all && woken * 2 < kept_all,
            "held at most {held}, {woken} wake-ups, against {kept_all}"
        );
    }

    /// A receiver that leaves the bus takes its deliveries still to come with it: its
    /// senders' streams to it are gone, and a node attached later under its id hears
    /// only what is sent after it came.
    #[test]
    fn a_receiver_that_leaves_takes_its_deliveries_with_it() {
        let faults = Faults {
            delay_s: 1.0,
            jitter_s: 1.0,
            ..Faults::NONE
        };
        let mut bus = InProcessBus::with_faults(&[1, 2, 3], faults, 7, 0.01);
        let gone = |id, ms| Message::Gone {
            id,
            at: Instant::from_millis(ms),
        };
        for k in 0..100u64 {
            bus.send(1, &gone(1, k * 10), k as f64 * 0.01)
                .expect("sent");
        }
        let streams = |bus: &InProcessBus| bus.outgoing.get(&1).map_or(0, |o| o.keys.len());
        assert_eq!(streams(&bus), 2, "one stream to each of nodes 2 and 3");
        bus.detach(2);
        assert_eq!(streams(&bus), 1, "node 2's went with it");
        bus.attach(2).expect("attached");
        bus.send(1, &gone(1, 5_000), 5.0).expect("sent");
        let mut got = Vec::new();
        bus.receive(2, 100.0, &mut got).expect("received");
        assert_eq!(got.len(), 1, "only what was sent after it came: {got:?}");
        let mut all = Vec::new();
        bus.receive(3, 100.0, &mut all).expect("received");
        assert!(
            !all.is_empty() && all.len() <= 101,
            "node 3 still hears: {}",
            all.len()
        );
        assert!(bus.outgoing.is_empty(), "every stream delivered or gone");
    }
}
