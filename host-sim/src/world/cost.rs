//! What planner steps cost in wall-clock time: a histogram of eighth-octave buckets
//! (each ±4.5 % wide around its centre), so that millions of steps over many worlds and
//! threads merge in constant memory and still give percentiles to a few per cent.

use serde::Serialize;

/// Buckets per octave.
const PER_OCTAVE: f64 = 8.0;
/// Buckets: eighth octaves from 1 ns to 2³² ns (4.3 s).
const BUCKETS: usize = 256;

/// Planner-step times, in eighth-octave buckets of nanoseconds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StepCosts {
    buckets: [u64; BUCKETS],
    count: u64,
    max_ns: u64,
}

impl Default for StepCosts {
    fn default() -> Self {
        Self {
            buckets: [0; BUCKETS],
            count: 0,
            max_ns: 0,
        }
    }
}

/// Percentiles of planner-step time (µs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct StepPercentiles {
    /// Steps measured.
    pub steps: u64,
    /// Median (µs).
    pub p50_us: f64,
    /// 90th percentile (µs).
    pub p90_us: f64,
    /// 99th percentile (µs).
    pub p99_us: f64,
    /// Largest (µs, exact).
    pub max_us: f64,
}

impl StepCosts {
    /// Records one step of `ns` nanoseconds.
    pub fn add(&mut self, ns: u64) {
        let i = (PER_OCTAVE * (ns.max(1) as f64).log2()) as usize;
        if let Some(b) = self.buckets.get_mut(i.min(BUCKETS - 1)) {
            *b += 1;
        }
        self.count += 1;
        self.max_ns = self.max_ns.max(ns);
    }

    /// Adds `o`'s steps.
    pub fn merge(&mut self, o: &StepCosts) {
        for (a, b) in self.buckets.iter_mut().zip(o.buckets.iter()) {
            *a += b;
        }
        self.count += o.count;
        self.max_ns = self.max_ns.max(o.max_ns);
    }

    /// The `q` quantile (µs): the geometric centre of the bucket holding it.
    pub fn quantile_us(&self, q: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let rank = ((self.count - 1) as f64 * q.clamp(0.0, 1.0)).round() as u64;
        let mut seen = 0;
        for (i, &n) in self.buckets.iter().enumerate() {
            seen += n;
            if seen > rank {
                let centre = 2f64.powf((i as f64 + 0.5) / PER_OCTAVE) / 1000.0;
                return centre.min(self.max_ns as f64 / 1000.0);
            }
        }
        self.max_ns as f64 / 1000.0
    }

    /// Its percentiles.
    pub fn percentiles(&self) -> StepPercentiles {
        StepPercentiles {
            steps: self.count,
            p50_us: self.quantile_us(0.5),
            p90_us: self.quantile_us(0.9),
            p99_us: self.quantile_us(0.99),
            max_us: self.max_ns as f64 / 1000.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_within_a_bucket_of_the_truth() {
        let mut c = StepCosts::default();
        // 1..=1000 µs, one step each.
        for us in 1..=1000u64 {
            c.add(us * 1000);
        }
        let p = c.percentiles();
        assert_eq!(p.steps, 1000);
        for (got, want) in [(p.p50_us, 500.0), (p.p90_us, 900.0), (p.p99_us, 990.0)] {
            assert!((got / want - 1.0).abs() < 0.05, "{got} vs {want}");
        }
        assert_eq!(p.max_us, 1000.0);
        // Merging two halves gives the whole.
        let (mut a, mut b) = (StepCosts::default(), StepCosts::default());
        for us in 1..=1000u64 {
            if us % 2 == 0 {
                a.add(us * 1000)
            } else {
                b.add(us * 1000)
            }
        }
        a.merge(&b);
        assert_eq!(a, c);
        assert_eq!(
            StepCosts::default().percentiles(),
            StepPercentiles::default()
        );
    }
}
