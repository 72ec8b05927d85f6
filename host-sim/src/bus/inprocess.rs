//! The in-process bus: a broadcast medium delivering in send order, deterministic,
//! injecting [`Faults`] when asked.

use super::{Bus, BusError, FaultStats, Faults, Message, Received};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;

/// The in-process bus: zero delay, no loss, delivery in send order — unless built
/// [`InProcessBus::with_faults`].
#[derive(Debug, Clone)]
pub struct InProcessBus {
    nodes: Vec<u16>,
    /// Per node, pending deliveries sorted by time (ties in send order).
    queues: Vec<Vec<Received>>,
    /// Per node, newest stamp delivered per (sender, subject).
    newest: Vec<HashMap<(u16, u16), planner_core::Instant>>,
    faults: Faults,
    rng: ChaCha8Rng,
    /// Period h, for duplicate spacing.
    h: f64,
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
            queues: nodes.iter().map(|_| Vec::new()).collect(),
            newest: nodes.iter().map(|_| HashMap::new()).collect(),
            faults,
            rng: crate::reference::instances::rng(seed ^ 0xfa17),
            h,
            stats: FaultStats::default(),
        }
    }

    fn index(&self, node: u16) -> Result<usize, BusError> {
        self.nodes
            .iter()
            .position(|&n| n == node)
            .ok_or(BusError::UnknownNode(node))
    }

    fn enqueue(q: &mut Vec<Received>, r: Received) {
        let at = q.partition_point(|p| p.at <= r.at);
        q.insert(at, r);
    }
}

impl Bus for InProcessBus {
    fn fault_stats(&self) -> FaultStats {
        self.stats
    }

    fn attach(&mut self, node: u16) -> Result<(), BusError> {
        if !self.nodes.contains(&node) {
            self.nodes.push(node);
            self.queues.push(Vec::new());
            self.newest.push(HashMap::new());
        }
        Ok(())
    }

    fn detach(&mut self, node: u16) {
        if let Ok(i) = self.index(node) {
            self.nodes.remove(i);
            self.queues.remove(i);
            self.newest.remove(i);
        }
    }

    fn send(&mut self, from: u16, msg: &Message, now: f64) -> Result<(), BusError> {
        let me = self.index(from)?;
        let f = self.faults;
        if f.silent.is_some_and(|s| s.id == from && now >= s.from_s) {
            self.stats.silenced += 1;
            return Ok(());
        }
        if f.is_none() {
            for (i, q) in self.queues.iter_mut().enumerate() {
                if i != me {
                    q.push(Received { msg: *msg, at: now });
                }
            }
            return Ok(());
        }
        for i in 0..self.queues.len() {
            if i == me {
                continue;
            }
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
            if let Some(q) = self.queues.get_mut(i) {
                Self::enqueue(q, Received { msg: *msg, at });
                if dup {
                    self.stats.duplicated += 1;
                    Self::enqueue(
                        q,
                        Received {
                            msg: *msg,
                            at: at + extra,
                        },
                    );
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
        let ready = q.partition_point(|r| r.at <= now);
        if self.faults.is_none() {
            // In order and unique by construction: nothing to drop.
            out.extend(q.drain(..ready));
            return Ok(());
        }
        for r in q.drain(..ready) {
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
