//! Time on a node's clock: integer microseconds since the fleet's epoch.
//!
//! Every absolute time the planners exchange or compare — a state's stamp, an arrival
//! τ(c), a lease's end, the time of a step — is an [`Instant`]; floating point appears
//! only for a [`Duration`] relative to now (an age, a notification bound), computed
//! exactly in integers first and converted last. So a vehicle decides bit for bit the
//! same after 60 days of uptime as after 60 seconds.
//!
//! Why: seconds in `f32` lose a bit of resolution every doubling. At 131,072 s (36.4 h)
//! the spacing of representable `f32` values is 15.6 ms — more than a period h = 10 ms —
//! so consecutive stamps collide and fresh states are refused as stale; `f64` only moves
//! the cliff out. A `u64` of microseconds lasts 584,000 years.
//!
//! # The epoch and how clocks stay in step
//!
//! An [`Instant`] counts microseconds since an epoch that every node of one fleet shares:
//! a time master's clock (GNSS time, or an infrastructure node's) from which each
//! vehicle's and each intersection manager's clock is disciplined, as AUTOSAR's CAN time
//! synchronisation does (a SYNC message with the master's time, a follow-up with its
//! send-time correction) — on this project's fleets, the time master's
//! `can_gateway::wire::Message::Sync`. Between syncs a node counts with its own
//! monotonic timer (a 1 MHz counter extended to 64 bits on a microcontroller). Which
//! instant is the epoch does not matter to the planners: they only ever subtract
//! instants. What matters is that two nodes' readings of the same moment differ by at
//! most a bound ε, the **clock error**: the timer's drift times the sync interval plus
//! the SYNC's time-stamping jitter (50 ppm × 1 s + 100 µs = 150 µs, say).
//!
//! Where ε enters: an age computed by a receiver (`now − stamp`) is off by at most ε, so
//! the bound on how late a message may arrive that the planners are given
//! (`LanePlanner::set_notify_latency`, `CrossingPlanner::set_notify_latency`) must be the
//! bus's delay bound plus ε, and a manager's lease must outlive that bound plus ε
//! ([`crate::crossing::Lease`]). A stamp that lies ahead of the receiver's clock (a
//! sender whose clock runs up to ε ahead) is taken as age zero, never as negative.
//!
//! On the wire, can-gateway carries times as the low 32 bits of milliseconds (wrapping
//! every 49.7 days) and a receiver restores the full instant as the one nearest its own
//! clock, so no uptime is too long for the bus either.

use crate::real::Real;

/// Microseconds per second.
const MICROS_PER_S: u64 = 1_000_000;

/// A moment on a node's clock: microseconds since the fleet's epoch (see the module
/// docs). Totally ordered, `Copy`, 8 bytes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Instant(u64);

/// A non-negative span of time, in microseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Duration(u64);

impl Instant {
    /// The epoch.
    pub const EPOCH: Instant = Instant(0);

    /// `us` microseconds after the epoch.
    pub const fn from_micros(us: u64) -> Self {
        Self(us)
    }

    /// `ms` milliseconds after the epoch (saturating at the largest instant).
    pub const fn from_millis(ms: u64) -> Self {
        Self(ms.saturating_mul(1_000))
    }

    /// `s` seconds after the epoch (saturating at the largest instant).
    pub const fn from_secs(s: u64) -> Self {
        Self(s.saturating_mul(MICROS_PER_S))
    }

    /// Microseconds since the epoch.
    pub const fn as_micros(self) -> u64 {
        self.0
    }

    /// Whole milliseconds since the epoch (rounded down).
    pub const fn as_millis(self) -> u64 {
        self.0 / 1_000
    }

    /// `d` later (saturating at the largest instant).
    pub const fn saturating_add(self, d: Duration) -> Self {
        Self(self.0.saturating_add(d.0))
    }

    /// `d` earlier (saturating at the epoch).
    pub const fn saturating_sub(self, d: Duration) -> Self {
        Self(self.0.saturating_sub(d.0))
    }

    /// How long after `earlier` this is; zero if `earlier` is not earlier (a sender whose
    /// clock runs ahead of the receiver's).
    pub const fn since(self, earlier: Instant) -> Duration {
        Duration(self.0.saturating_sub(earlier.0))
    }
}

impl Duration {
    /// Zero.
    pub const ZERO: Duration = Duration(0);

    /// `us` microseconds.
    pub const fn from_micros(us: u64) -> Self {
        Self(us)
    }

    /// `ms` milliseconds (saturating).
    pub const fn from_millis(ms: u64) -> Self {
        Self(ms.saturating_mul(1_000))
    }

    /// `s` seconds (saturating).
    pub const fn from_secs(s: u64) -> Self {
        Self(s.saturating_mul(MICROS_PER_S))
    }

    /// `s` seconds in a floating-point type, rounded to the nearest microsecond; `None`
    /// if `s` is NaN, infinite, negative or beyond 10⁹ s.
    pub fn from_secs_real<F: Real>(s: F) -> Option<Self> {
        let s = s.to_f64();
        if !(s.is_finite() && (0.0..=1e9).contains(&s)) {
            return None;
        }
        // Within [0, 1e15] µs, `as` is exact after rounding.
        Some(Self(libm::round(s * 1e6) as u64))
    }

    /// Microseconds.
    pub const fn as_micros(self) -> u64 {
        self.0
    }

    /// Seconds in a floating-point type: the integer count of microseconds converted and
    /// then divided, so equal durations give equal bits whatever the clocks read.
    pub fn as_secs<F: Real>(self) -> F {
        F::from_u64(self.0) / F::from_f64(1e6)
    }

    /// The sum (saturating).
    pub const fn saturating_add(self, o: Duration) -> Self {
        Self(self.0.saturating_add(o.0))
    }
}

impl From<core::time::Duration> for Duration {
    /// Whole microseconds (rounded down, saturating).
    fn from(d: core::time::Duration) -> Self {
        Self(u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
    }
}

impl From<Duration> for core::time::Duration {
    fn from(d: Duration) -> Self {
        core::time::Duration::from_micros(d.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ages_are_the_same_bits_whatever_the_clock_reads() {
        let sixty_days = Instant::from_secs(60 * 86_400);
        let wrap = Instant::from_millis(1 << 32);
        for base in [
            Instant::EPOCH,
            sixty_days,
            wrap,
            Instant::from_micros(u64::MAX / 2),
        ] {
            for age_us in [0u64, 1, 9_999, 10_000, 123_456, 86_400_000_000] {
                let stamp = base;
                let now = base.saturating_add(Duration::from_micros(age_us));
                let a32: f32 = now.since(stamp).as_secs();
                let a64: f64 = now.since(stamp).as_secs();
                assert_eq!(a32.to_bits(), (age_us as f32 / 1e6f32).to_bits());
                assert_eq!(a64.to_bits(), (age_us as f64 / 1e6).to_bits());
            }
        }
    }

    #[test]
    fn a_stamp_ahead_of_the_clock_is_age_zero_and_nothing_wraps() {
        let now = Instant::from_millis(5);
        assert_eq!(now.since(Instant::from_millis(6)), Duration::ZERO);
        assert_eq!(
            Instant::from_micros(u64::MAX).saturating_add(Duration::from_secs(1)),
            Instant::from_micros(u64::MAX)
        );
        assert_eq!(
            Instant::EPOCH.saturating_sub(Duration::from_secs(1)),
            Instant::EPOCH
        );
        assert_eq!(Instant::from_secs(u64::MAX).as_micros(), u64::MAX);
    }

    #[test]
    fn durations_from_seconds_are_validated_and_rounded() {
        assert_eq!(
            Duration::from_secs_real(0.01f64),
            Some(Duration::from_millis(10))
        );
        assert_eq!(
            Duration::from_secs_real(0.1f32),
            Some(Duration::from_millis(100))
        );
        for bad in [f64::NAN, f64::INFINITY, -0.5, 2e9] {
            assert_eq!(Duration::from_secs_real(bad), None);
        }
        let d: core::time::Duration = Duration::from_millis(1500).into();
        assert_eq!(d, core::time::Duration::from_millis(1500));
        assert_eq!(
            Duration::from(core::time::Duration::from_nanos(2_500)),
            Duration::from_micros(2)
        );
    }
}
