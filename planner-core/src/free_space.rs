//! Free space in the forward direction (Fig. 4, Appendix B, SPEC §5): the arcs A_L and
//! A_H, their end points on the band, the angles (28), the turning-radius regions
//! (29)(30) and the angular-speed region Ω^k_t (31).
//!
//! All positions are of the vehicle's reference point; the band passed in is already
//! shrunk by W/2 (SPEC §1).

use crate::lanes::Band;
use crate::params::Params;
use crate::real::Real;
use crate::safety;
use crate::unicycle::Pose;

/// Curvature |ω/v| (1/m) below which the current motion counts as straight when
/// computing d̂H: a radius above 10⁶ m bends the path by < 0.1 mm over 100 m, below
/// anything the band test could resolve, while the circle formulas would lose precision.
pub const STRAIGHT_CURVATURE: f64 = 1e-6;

/// Choice (SPEC §5 leaves it open): on an open road (14) gives x̄ = ∞, hence dH = ∞
/// when driving straight and, by (30), ρ = ∞: no turn would ever be allowed. The radius
/// used for the turning regions is therefore capped at dS(v_{t−h}) + `D_TURN_M`. A smaller
/// arc of the same free space is still free, and the cap keeps dH > dL (Lemma 5), so the
/// construction stays valid; 10 m gives ρ ≈ 65 m at 15 m/s, a lane change of ~43 m.
pub const D_TURN_M: f64 = 10.0;

/// Why the free space could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum FreeSpaceError {
    /// The reference point is outside the band (or the band is empty).
    OutsideBand,
    /// An input is NaN or infinite.
    NotFinite,
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for FreeSpaceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::OutsideBand => {
                f.write_str("the reference point is outside the band (or the band is empty)")
            }
            Self::NotFinite => f.write_str("an input is NaN or infinite"),
        }
    }
}

impl core::error::Error for FreeSpaceError {}

/// One arc A_r (r ∈ {L, H}) and what (28)–(30) derive from it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Arc<F> {
    /// Radius d_r (m).
    pub radius: F,
    /// θ^{r+}_t (28): angle of the upper end point relative to the heading.
    pub theta_plus: F,
    /// θ^{r−}_t (28): angle of the lower end point relative to the heading.
    pub theta_minus: F,
    /// 1/ρ^{r+}_t (30): the largest counter-clockwise curvature allowed; 0 when
    /// θ^{r+} ≤ 0 (the heading already points past the upper end point: no left turn).
    pub kappa_plus: F,
    /// 1/ρ^{r−}_t (30): the largest clockwise curvature allowed; 0 when θ^{r−} ≥ 0.
    pub kappa_minus: F,
}

/// The free space of Fig. 4 at time t.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FreeSpace<F> {
    /// dL = dS(v_{t−h}).
    pub d_l: F,
    /// d̂H: distance to where the current turning radius meets the band (`None` = never).
    pub d_h_hat: Option<F>,
    /// dH = min{d̂H, x̄_t − x_t}.
    pub d_h: F,
    /// A_L.
    pub arc_l: Arc<F>,
    /// A_H, of radius min{dH, dL + [`D_TURN_M`]}.
    pub arc_h: Arc<F>,
}

impl<F: Real> FreeSpace<F> {
    /// Builds the free space for a vehicle at `pose` that applied (v_{t−h}, ω_{t−h}),
    /// within `band` (reference-point band), with x̄_t − x_t = `gap`.
    pub fn new(
        p: &Params<F>,
        pose: Pose<F>,
        v_prev: F,
        omega_prev: F,
        band: Band<F>,
        gap: F,
    ) -> Result<Self, FreeSpaceError> {
        let all = [
            pose.x, pose.y, pose.theta, v_prev, omega_prev, band.lo, band.hi, gap,
        ];
        if !all.iter().all(|v| v.is_finite()) {
            return Err(FreeSpaceError::NotFinite);
        }
        if !(band.lo <= pose.y && pose.y <= band.hi) {
            return Err(FreeSpaceError::OutsideBand);
        }
        let d_l = safety::d_s(p, v_prev);
        let d_h_hat = crossing_distance(pose, v_prev, omega_prev, band);
        let d_h = d_h_hat.map_or(gap, |d| d.min(gap));
        let turn_radius = d_h.min(d_l + F::from_f64(D_TURN_M));
        Ok(Self {
            d_l,
            d_h_hat,
            d_h,
            arc_l: arc(p, pose, band, d_l),
            arc_h: arc(p, pose, band, turn_radius),
        })
    }

    /// Ω^k_t (31) for a planned speed v_k: [−v_k/ρ^{H−}, v_k/ρ^{H+}].
    #[inline]
    pub fn omega_bounds(&self, v: F) -> (F, F) {
        (-v * self.arc_h.kappa_minus, v * self.arc_h.kappa_plus)
    }

    /// The condition (ii) of Lemmas 5 and 8: [θ^{H−}, θ^{H+}] ⊂ [θ^{L−}, θ^{L+}].
    pub fn lemma5_angles(&self) -> bool {
        self.arc_l.theta_minus <= self.arc_h.theta_minus
            && self.arc_h.theta_plus <= self.arc_l.theta_plus
    }
}

/// The arc of radius `d` centred at the pose, clipped by the band: its end points, the
/// angles (28) and the curvature limits (30).
fn arc<F: Real>(p: &Params<F>, pose: Pose<F>, band: Band<F>, d: F) -> Arc<F> {
    let end_angle = |dy: F| {
        // End point where the arc meets the line dy away, or (x, y ± d) if it does not
        // reach it: (28)'s ±π/2 case is atan2(d, 0).
        let rise = d.min(dy);
        let run = (d * d - rise * rise).max(F::ZERO).sqrt();
        rise.atan2(run)
    };
    let theta_plus = end_angle(band.hi - pose.y) - pose.theta;
    let theta_minus = -end_angle(pose.y - band.lo) - pose.theta;
    let kappa = |angle: F| {
        if angle > F::ZERO {
            // ρ = max{ρmin, d / (2 sin|θ|)}, as a curvature.
            let rho = (d / (F::TWO * angle.sin())).max(p.rho_min());
            F::ONE / rho
        } else {
            F::ZERO
        }
    };
    Arc {
        radius: d,
        theta_plus,
        theta_minus,
        kappa_plus: kappa(theta_plus),
        kappa_minus: kappa(-theta_minus),
    }
}

/// d̂H: the straight-line distance from the pose to where the path of constant turning
/// radius v/ω first meets ȳ or y̲; `None` if it never does.
pub fn crossing_distance<F: Real>(pose: Pose<F>, v: F, omega: F, band: Band<F>) -> Option<F> {
    let kappa = if v > F::ZERO { omega / v } else { F::ZERO };
    if !(kappa.abs() >= F::from_f64(STRAIGHT_CURVATURE)) {
        let s = pose.theta.sin();
        return if s > F::ZERO {
            Some((band.hi - pose.y) / s)
        } else if s < F::ZERO {
            Some((pose.y - band.lo) / -s)
        } else {
            None
        };
    }
    // Mirror a clockwise turn into a counter-clockwise one.
    let (y, theta, lo, hi, kappa) = if kappa > F::ZERO {
        (pose.y, pose.theta, band.lo, band.hi, kappa)
    } else {
        (-pose.y, -pose.theta, -band.hi, -band.lo, -kappa)
    };
    let rho = F::ONE / kappa;
    // Centre of the turning circle; at heading ψ the vehicle is at cy − ρ cos ψ.
    let cy = y + rho * theta.cos();
    let two_pi = F::from_f64(core::f64::consts::TAU);
    let mut best: Option<F> = None;
    for line in [lo, hi] {
        let c = (cy - line) / rho;
        if !(c.abs() <= F::ONE) {
            continue;
        }
        let a = (F::ONE - c * c).max(F::ZERO).sqrt().atan2(c);
        for psi in [a, -a, a + two_pi, two_pi - a] {
            if psi > theta {
                let turn = psi - theta;
                best = Some(best.map_or(turn, |b: F| b.min(turn)));
            }
        }
    }
    // Chord of the turn: 2ρ sin(Δψ/2).
    best.map(|turn| F::TWO * rho * (F::HALF * turn).sin().abs())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_in_the_middle_of_a_lane() {
        let p = Params::<f64>::table_i();
        let band = Band { lo: 0.85, hi: 2.75 };
        let pose = Pose {
            x: 0.0,
            y: 1.8,
            theta: 0.0,
        };
        let fs = FreeSpace::new(&p, pose, 15.0, 0.0, band, 30.0).unwrap();
        assert_eq!(fs.d_h_hat, None);
        assert!((fs.d_h - 30.0).abs() < 1e-12);
        // A_H radius min(30, dS(15) + 10) = 24.39...; end point 0.95 m up.
        let r = safety::d_s(&p, 15.0) + D_TURN_M;
        let ang = (0.95f64).atan2((r * r - 0.95 * 0.95).sqrt());
        assert!((fs.arc_h.theta_plus - ang).abs() < 1e-12);
        let rho = r / (2.0 * ang.sin());
        assert!((fs.arc_h.kappa_plus - 1.0 / rho).abs() < 1e-12);
        assert!(fs.lemma5_angles());
        // Heading up at 0.1 rad: straight line meets ȳ after 0.95 / sin 0.1.
        let up = Pose { theta: 0.1, ..pose };
        let d = crossing_distance(up, 15.0, 0.0, band).unwrap();
        assert!((d - 0.95 / 0.1f64.sin()).abs() < 1e-12);
        // Turning left on a 100 m circle from heading 0: meets ȳ where 100(1 − cos ψ) = 0.95.
        let d = crossing_distance(pose, 10.0, 0.1, band).unwrap();
        let psi = (1.0f64 - 0.0095).acos();
        assert!((d - 200.0 * (psi / 2.0).sin()).abs() < 1e-9);
        // Mirror image: turning right meets y̲ at the same distance.
        let d2 = crossing_distance(pose, 10.0, -0.1, band).unwrap();
        assert!((d - d2).abs() < 1e-9);
        assert_eq!(
            FreeSpace::new(&p, Pose { y: 3.0, ..pose }, 15.0, 0.0, band, 30.0),
            Err(FreeSpaceError::OutsideBand)
        );
    }
}
