//! One verdict for every command: what was unsafe, counted by kind, and whether the run
//! was live. Every report ([`Judged`]) gives one; the command line turns it into its exit
//! code (1 unsafe, 3 not live, 0 both fine), and `host-sim merge` judges merged shards
//! with the same function as the unsharded run.

use core::iter::Sum;
use core::ops::Add;

/// The safety findings of a run, a sweep or an experiment, by kind. Any one of them makes
/// it unsafe.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Safety {
    /// Ground-truth overlaps of two vehicles.
    pub collisions: u64,
    /// Steps at which a pair was out of the invariant it is under (Lemma 3, or the
    /// leader-aware one).
    pub invariant_violations: u64,
    /// Commands outside the vehicle's limits (speed, acceleration, turn rate).
    pub limit_violations: u64,
    /// Vehicles past a road's end.
    pub road_end_overruns: u64,
    /// Entries into A_S without permission.
    pub unpermitted_entries: u64,
    /// The bus's trust broken: a forgery or replay accepted, a new vehicle given a node's
    /// id.
    pub breaches: u64,
}

impl Safety {
    /// Collisions, invariant and limit violations and unpermitted entries (the four
    /// counts most reports keep).
    pub fn of(collisions: u64, invariant: u64, limits: u64, unpermitted: u64) -> Self {
        Self {
            collisions,
            invariant_violations: invariant,
            limit_violations: limits,
            unpermitted_entries: unpermitted,
            ..Self::default()
        }
    }

    /// Every finding, of every kind.
    pub fn events(&self) -> u64 {
        self.collisions
            + self.invariant_violations
            + self.limit_violations
            + self.road_end_overruns
            + self.unpermitted_entries
            + self.breaches
    }

    /// No finding of any kind.
    pub fn is_safe(&self) -> bool {
        self.events() == 0
    }
}

impl Add for Safety {
    type Output = Self;

    fn add(self, o: Self) -> Self {
        Self {
            collisions: self.collisions + o.collisions,
            invariant_violations: self.invariant_violations + o.invariant_violations,
            limit_violations: self.limit_violations + o.limit_violations,
            road_end_overruns: self.road_end_overruns + o.road_end_overruns,
            unpermitted_entries: self.unpermitted_entries + o.unpermitted_entries,
            breaches: self.breaches + o.breaches,
        }
    }
}

impl Sum for Safety {
    fn sum<I: Iterator<Item = Self>>(iter: I) -> Self {
        iter.fold(Self::default(), Add::add)
    }
}

/// What a command concludes: its safety findings, and whether it was live (every goal
/// met, no deadlock — as each report defines its liveness).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Verdict {
    /// The safety findings.
    pub safety: Safety,
    /// Every liveness goal met.
    pub live: bool,
}

impl Verdict {
    /// `safety`, and `live`.
    pub fn new(safety: Safety, live: bool) -> Self {
        Self { safety, live }
    }

    /// No safety finding.
    pub fn is_safe(&self) -> bool {
        self.safety.is_safe()
    }

    /// Both verdicts at once: findings added, live only if both are.
    pub fn and(self, o: Self) -> Self {
        Self {
            safety: self.safety + o.safety,
            live: self.live && o.live,
        }
    }
}

/// A result that can be judged.
pub trait Judged {
    /// Its verdict.
    fn verdict(&self) -> Verdict;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn any_finding_is_unsafe() {
        assert!(Safety::default().is_safe());
        let one = [
            Safety::of(1, 0, 0, 0),
            Safety::of(0, 1, 0, 0),
            Safety::of(0, 0, 1, 0),
            Safety::of(0, 0, 0, 1),
            Safety {
                road_end_overruns: 1,
                ..Safety::default()
            },
            Safety {
                breaches: 1,
                ..Safety::default()
            },
        ];
        for s in one {
            assert_eq!(s.events(), 1);
            assert!(!s.is_safe());
        }
        let all: Safety = one.into_iter().sum();
        assert_eq!(all.events(), 6);
        let v = Verdict::new(Safety::default(), true).and(Verdict::new(one[5], false));
        assert!(!v.is_safe() && !v.live);
    }
}
