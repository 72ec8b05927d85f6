//! Geometry of the monitor's judgements: the lateral span of a rectangle and the
//! separating-axis test of two oriented L × W rectangles.

use super::Truth;

/// The y-range [bottom, top] the rectangle covers.
pub fn lateral_span(c: &Truth) -> (f64, f64) {
    let ext = 0.5 * (c.length * c.theta.sin().abs() + c.width * c.theta.cos().abs());
    (c.y - ext, c.y + ext)
}

/// Separating-axis test for two oriented L × W rectangles (touching counts as overlap).
pub fn rectangles_overlap(a: &Truth, b: &Truth) -> bool {
    if far_apart(a, b) {
        return false;
    }
    let corners = |t: &Truth| {
        let (s, c) = t.theta.sin_cos();
        let (hl, hw) = (0.5 * t.length, 0.5 * t.width);
        [(hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw)]
            .map(|(u, w)| (t.x + u * c - w * s, t.y + u * s + w * c))
    };
    let (ca, cb) = (corners(a), corners(b));
    let axes = |t: &Truth| {
        let (s, c) = t.theta.sin_cos();
        [(c, s), (-s, c)]
    };
    for (ax, ay) in axes(a).into_iter().chain(axes(b)) {
        let project = |cs: &[(f64, f64); 4]| {
            cs.iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &(x, y)| {
                    let p = x * ax + y * ay;
                    (lo.min(p), hi.max(p))
                })
        };
        let (a0, a1) = project(&ca);
        let (b0, b1) = project(&cb);
        if a1 < b0 || b1 < a0 {
            return false;
        }
    }
    true
}

/// `true` when the centres are farther apart than the half-diagonals reach: a shortcut
/// for speed only (the separating-axis test decides alone; `.cargo/mutants.toml` says so).
fn far_apart(a: &Truth, b: &Truth) -> bool {
    let reach = 0.5 * (a.length.hypot(a.width) + b.length.hypot(b.width));
    (a.x - b.x).abs() > reach || (a.y - b.y).abs() > reach
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitor::Truth;

    fn car(x: f64, y: f64, theta: f64) -> Truth {
        Truth {
            x,
            y,
            theta,
            length: 4.5,
            width: 1.7,
            lane: 0,
            keeps_invariant: true,
            leader_aware: false,
            brake: 7.9,
            v: 0.0,
            v_before: 0.0,
            mapped: false,
        }
    }

    #[test]
    fn rectangle_overlap_cases() {
        assert!(rectangles_overlap(&car(0.0, 0.0, 0.0), &car(4.4, 0.0, 0.0)));
        assert!(!rectangles_overlap(
            &car(0.0, 0.0, 0.0),
            &car(4.6, 0.0, 0.0)
        ));
        assert!(!rectangles_overlap(
            &car(0.0, 0.0, 0.0),
            &car(0.0, 1.8, 0.0)
        ));
        assert!(rectangles_overlap(&car(0.0, 0.0, 0.0), &car(0.0, 1.6, 0.0)));
        // Rotated 90°: B spans 1.7 m in x, so they touch while |dx| ≤ 2.25 + 0.85 = 3.1.
        let r = car(3.0, 0.0, std::f64::consts::FRAC_PI_2);
        assert!(rectangles_overlap(&car(0.0, 0.0, 0.0), &r));
        let r = car(3.2, 0.0, std::f64::consts::FRAC_PI_2);
        assert!(!rectangles_overlap(&car(0.0, 0.0, 0.0), &r));
        // 45°: at (3.6, 2.2) B's edge crosses A near (2.25, 0.37); at (4.0, 2.6) it misses
        // A although the bounding boxes still overlap, so only B's own axes separate them.
        let d = car(3.6, 2.2, std::f64::consts::FRAC_PI_4);
        assert!(rectangles_overlap(&car(0.0, 0.0, 0.0), &d));
        let d = car(4.0, 2.6, std::f64::consts::FRAC_PI_4);
        assert!(!rectangles_overlap(&car(0.0, 0.0, 0.0), &d));
    }
}
