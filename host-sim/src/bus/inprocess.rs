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
use std::collections::{BinaryHeap, HashMap};

/// A delivery waiting in a node's heap: (time bits, send order), then the message.
#[derive(Debug, Clone, Copy)]
struct Pending {
    key: (u64, u64),
    r: Received,
}

impl PartialEq for Pending {
    fn eq(&self, o: &Self) -> bool {
        self.key == o.key
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
        self.key.cmp(&o.key)
    }
}

/// One node's deliveries still to come.
#[derive(Debug, Clone, Default)]
struct Queue {
    /// Deliveries in send order at the time of sending (a perfect bus).
    now: Vec<Received>,
    /// Deliveries at later times (a bus with faults), earliest first.
    later: BinaryHeap<Reverse<Pending>>,
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
        self.nodes
            .iter()
            .position(|&n| n == node)
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
        let at = self.at.clone();
        let cells = self.cells(range);
        let (cx, cy) = cells.cell(p);
        let mut out: Vec<usize> = cells.everywhere.clone();
        for dx in -1..=1 {
            for dy in -1..=1 {
                for &i in cells.cells.get(&(cx + dx, cy + dy)).into_iter().flatten() {
                    let Some(Some(q)) = at.get(i) else { continue };
                    if (q.0 - p.0).hypot(q.1 - p.1) <= range {
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
        if !self.nodes.contains(&node) {
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
                    // Delivery times are ≥ 0, so their bits order as the times do.
                    q.later.push(Reverse(Pending {
                        key: (t.to_bits(), self.sent),
                        r: Received { msg: *msg, at: t },
                    }));
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
        while let Some(Reverse(p)) = q.later.peek() {
            if !(p.r.at <= now) {
                break;
            }
            let r = p.r;
            q.later.pop();
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
