//! Random instances of problem (10) and receding-horizon sequences from a simulated drive,
//! shared by the cross-check tests and `bench-planner`.

use planner_core::planner::free_road_gap;
use planner_core::safety::d_s;
use planner_core::{CostWeights, Params, Real, SingleLaneProblem};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Raw scalars of an instance, so that the same instance can be built in f64 and f32.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InstanceSpec {
    /// v_{t−h}.
    pub v_prev: f64,
    /// x̄ − x_t (before the margin).
    pub gap: f64,
    /// Cost weights (w_x, w_v, w_Δ).
    pub weights: [f64; 3],
    /// x^f − x_t.
    pub target: f64,
    /// v_ref.
    pub v_ref: f64,
}

impl InstanceSpec {
    /// Builds the problem in precision `F` with horizon `N` and `F`'s safety margin.
    pub fn build<F: Real, const N: usize>(&self) -> Option<SingleLaneProblem<F, N>> {
        self.build_with_margin(F::SAFETY_MARGIN_M)
    }

    /// Builds the problem with an explicit safety margin (to compare precisions on the
    /// same tightened problem).
    pub fn build_with_margin<F: Real, const N: usize>(
        &self,
        margin: F,
    ) -> Option<SingleLaneProblem<F, N>> {
        let p = Params::<F>::table_i();
        let [wx, wv, wd] = self.weights;
        SingleLaneProblem::new(
            &p,
            F::from_f64(self.v_prev),
            F::from_f64(self.gap),
            margin,
            CostWeights {
                target_position: F::from_f64(wx),
                reference_speed: F::from_f64(wv),
                smoothness: F::from_f64(wd),
            },
            F::from_f64(self.target),
            F::from_f64(self.v_ref),
        )
        .ok()
    }
}

fn log_uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    (rng.random_range(lo.ln()..hi.ln())).exp()
}

/// Smallest slack (m) of the gap over dS(v_{t−h}) + margins in [`random_instance`]: with
/// it the feasible set has an interior (Slater's condition), which the reference solver
/// needs to certify an optimum to 1e-10.
pub const MIN_SLACK_M: f64 = 0.05;

/// A random feasible instance for horizon `n`: the invariant holds with at least
/// [`MIN_SLACK_M`] to spare (so Lemma 2 makes it feasible, with an interior), and the
/// obstacle is near enough in about two cases of three that the safety constraints bind.
pub fn random_instance(rng: &mut ChaCha8Rng, n: usize) -> InstanceSpec {
    random_with_slack(rng, n, MIN_SLACK_M, 5.0)
}

/// A near-degenerate instance: the gap exceeds dS(v_{t−h}) + margins by 1 mm to
/// [`MIN_SLACK_M`], so little more than the max-braking sequence is feasible. The
/// planner meets these right after a fallback.
pub fn random_degenerate_instance(rng: &mut ChaCha8Rng, n: usize) -> InstanceSpec {
    let mut spec = random_with_slack(rng, n, 1e-3, MIN_SLACK_M);
    let p = Params::<f64>::table_i();
    spec.gap = d_s(&p, spec.v_prev) + margins() + log_uniform(rng, 1e-3, MIN_SLACK_M);
    spec
}

fn margins() -> f64 {
    f64::SAFETY_MARGIN_M.max(f32::SAFETY_MARGIN_M as f64)
}

fn random_with_slack(rng: &mut ChaCha8Rng, n: usize, lo: f64, hi: f64) -> InstanceSpec {
    let p = Params::<f64>::table_i();
    let v_prev = if rng.random_bool(0.1) {
        0.0
    } else {
        rng.random_range(0.0..p.v_max())
    };
    let need = d_s(&p, v_prev) + margins();
    let gap = match rng.random_range(0..3) {
        0 => need + log_uniform(rng, lo, hi),
        1 => need + lo + rng.random_range(0.0..(n as f64 * p.h() * p.v_max())),
        _ => free_road_gap(&p, n),
    };
    let wx = if rng.random_bool(0.5) {
        log_uniform(rng, 1e-3, 10.0)
    } else {
        0.0
    };
    let weights = [
        wx,
        log_uniform(rng, 1e-2, 10.0),
        log_uniform(rng, 1e-2, 100.0),
    ];
    InstanceSpec {
        v_prev,
        gap,
        weights,
        target: rng.random_range(0.0..60.0),
        v_ref: rng.random_range(0.0..p.v_max()),
    }
}

/// `count` random instances from `seed`.
pub fn random_instances(seed: u64, count: usize, n: usize) -> Vec<InstanceSpec> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count).map(|_| random_instance(&mut rng, n)).collect()
}

/// A seeded RNG (ChaCha8), the one every host-side experiment uses.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}
