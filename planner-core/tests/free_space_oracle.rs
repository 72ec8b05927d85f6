//! d̂H of the lateral free space (`free_space::crossing_distance`) against an independent
//! oracle: the unicycle path of constant curvature ω/v integrated in small arc-length
//! steps until it first meets ȳ or y̲, and the straight-line distance to that point.

use planner_core::free_space::crossing_distance;
use planner_core::lanes::Band;
use planner_core::Pose;
use proptest::prelude::*;

/// Arc-length step of the oracle (m); its answers are good to about this.
const DS: f64 = 2e-3;

/// The oracle: where the path first leaves [lo, hi], as a distance from the start, or
/// `None` if it stays inside for a full turn (or `max_len` of straight road).
fn oracle(pose: Pose<f64>, kappa: f64, band: Band<f64>, max_len: f64) -> Option<f64> {
    let (mut x, mut y, mut psi) = (pose.x, pose.y, pose.theta);
    let len = if kappa.abs() > 1e-9 {
        (std::f64::consts::TAU / kappa.abs() + 1.0).min(max_len)
    } else {
        max_len
    };
    let steps = (len / DS) as usize;
    for _ in 0..steps {
        // Midpoint rule on the heading: exact for a circle up to O(DS³).
        let mid = psi + 0.5 * kappa * DS;
        x += DS * mid.cos();
        y += DS * mid.sin();
        psi += kappa * DS;
        if y >= band.hi || y <= band.lo {
            return Some((x - pose.x).hypot(y - pose.y));
        }
    }
    None
}

fn pose(y: f64, theta: f64) -> Pose<f64> {
    Pose { x: 3.0, y, theta }
}

const BAND: Band<f64> = Band { lo: -1.5, hi: 2.0 };

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn turning_paths_meet_the_band_where_the_oracle_says(
        y in -1.4f64..1.9,
        theta in -1.2f64..1.2,
        v in 0.5f64..20.0,
        // Turning radii from 2 m to 200 m, either way.
        radius in 2.0f64..200.0,
        left in any::<bool>(),
    ) {
        let kappa = if left { 1.0 / radius } else { -1.0 / radius };
        let got = crossing_distance(pose(y, theta), v, kappa * v, BAND);
        let want = oracle(pose(y, theta), kappa, BAND, 1e9);
        match (got, want) {
            (Some(g), Some(w)) => prop_assert!((g - w).abs() < 3.0 * DS, "{g} vs {w}"),
            // A circle that only grazes a line (within the oracle's resolution) may go
            // either way.
            (None, Some(_)) | (Some(_), None) => {
                let rho = radius;
                let cy = if left { y + rho * theta.cos() } else { y - rho * theta.cos() };
                let graze = ((cy + rho) - BAND.hi).abs().min(((cy - rho) - BAND.lo).abs());
                prop_assert!(graze < 1e-3, "got {got:?}, oracle {want:?}");
            }
            (None, None) => {}
        }
    }

    #[test]
    fn straight_paths_meet_the_band_where_the_oracle_says(
        y in -1.4f64..1.9,
        theta in prop_oneof![-1.2f64..-0.02, 0.02f64..1.2],
        v in 0.0f64..20.0,
    ) {
        // ω = 0, or a curvature below the straight threshold, or no speed at all.
        for omega in [0.0, 1e-8 * v, if v == 0.0 { 0.7 } else { 0.0 }] {
            let got = crossing_distance(pose(y, theta), v, omega, BAND).expect("meets a line");
            let want = oracle(pose(y, theta), 0.0, BAND, 200.0).expect("within 200 m");
            prop_assert!((got - want).abs() < 3.0 * DS, "{got} vs {want}");
        }
    }
}

#[test]
fn a_straight_path_along_the_road_never_meets_the_band() {
    assert_eq!(crossing_distance(pose(0.0, 0.0), 10.0, 0.0, BAND), None);
    // Standing still, whatever ω: treated as straight.
    assert_eq!(crossing_distance(pose(0.0, 0.0), 0.0, 0.5, BAND), None);
    let up = pose(0.5, 0.3);
    let d = crossing_distance(up, 0.0, 0.7, BAND).expect("straight up meets ȳ");
    assert!((d - 1.5 / 0.3f64.sin()).abs() < 1e-12, "{d}");
}

#[test]
fn a_tight_circle_inside_the_band_never_meets_it() {
    // Radius 0.5 m around a centre 0.5 m to the left: the circle spans y ∈ [0, 1].
    let d = crossing_distance(pose(0.0, 0.0), 1.0, 2.0, BAND);
    assert_eq!(d, None);
    assert_eq!(oracle(pose(0.0, 0.0), 2.0, BAND, 1e9), None);
    // Clockwise, likewise.
    assert_eq!(crossing_distance(pose(0.0, 0.0), 1.0, -2.0, BAND), None);
}

/// Lemma 5 (ii): A_H's angles lie within A_L's, edges included; either side sticking
/// out fails it.
#[test]
fn lemma5_angles_is_interval_inclusion() {
    use planner_core::free_space::{Arc, FreeSpace};
    let arc = |minus: f64, plus: f64| Arc {
        radius: 10.0,
        theta_plus: plus,
        theta_minus: minus,
        kappa_plus: 0.0,
        kappa_minus: 0.0,
    };
    let fs = |l: Arc<f64>, h: Arc<f64>| FreeSpace {
        d_l: 10.0,
        d_h_hat: None,
        d_h: 20.0,
        arc_l: l,
        arc_h: h,
    };
    assert!(fs(arc(-0.3, 0.3), arc(-0.2, 0.2)).lemma5_angles());
    assert!(fs(arc(-0.3, 0.3), arc(-0.3, 0.3)).lemma5_angles(), "equal");
    assert!(!fs(arc(-0.3, 0.3), arc(-0.4, 0.2)).lemma5_angles(), "below");
    assert!(!fs(arc(-0.3, 0.3), arc(-0.2, 0.4)).lemma5_angles(), "above");
    assert!(!fs(arc(-0.3, 0.3), arc(-0.4, 0.4)).lemma5_angles(), "both");
}

/// A circle that misses ȳ loops back to y̲: the crossing comes after more than half a
/// turn (the root 2π − a of the line behind the vehicle), both ways round.
#[test]
fn a_looping_path_meets_the_far_side_of_its_own_line() {
    for (y, theta, omega) in [(-0.92, 1.2, 0.5), (0.7, -1.0, -0.5), (-0.6, 0.9, 0.45)] {
        let kappa = omega / 1.0;
        let got = crossing_distance(pose(y, theta), 1.0, omega, BAND);
        let want = oracle(pose(y, theta), kappa, BAND, 1e9);
        match (got, want) {
            (Some(g), Some(w)) => assert!((g - w).abs() < 3.0 * DS, "{y} {theta}: {g} vs {w}"),
            _ => panic!("{y} {theta}: {got:?} vs {want:?}"),
        }
    }
}
