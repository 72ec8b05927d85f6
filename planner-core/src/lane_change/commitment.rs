//! The commitment distance (23) and its terms (24): how far before a dead end a vehicle
//! needing m lane changes must start making them.

use crate::params::Params;
use crate::real::Real;
use crate::safety;

/// LC(ρ) of (24): the x-distance of Lemma 12's S-curve over one lane at radius ρ,
/// 2 sqrt(Wl (2ρ − Wl)) − ρ θ_t.
pub fn lane_change_length<F: Real>(p: &Params<F>, rho: F, theta: F) -> F {
    let wl = p.spec().lane_width;
    F::TWO * (wl * (F::TWO * rho - wl)).max(F::ZERO).sqrt() - rho * theta
}

/// dC(v) = max{dS(v), LC(ρ_t)}, eq. (24).
pub fn d_c<F: Real>(p: &Params<F>, v: F, rho: F, theta: F) -> F {
    safety::d_s(p, v).max(lane_change_length(p, rho, theta))
}

/// The commitment distance (23): a vehicle needing `m` lane changes can make them before
/// x_R if x_R − x_t ≥ M (dS(v) + dC(v)); the paper takes v = vmax.
pub fn commitment_distance<F: Real>(p: &Params<F>, m: u8, v: F, rho: F, theta: F) -> F {
    F::from_usize(usize::from(m)) * (safety::d_s(p, v) + d_c(p, v, rho, theta))
}
