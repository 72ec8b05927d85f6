//! Lane bookkeeping on a multi-lane road (Sec. IV–V, SPEC §5–6): lane geometry, the
//! lateral band (11)(12), the inter-vehicle ordering of Definition 1, and the vehicle
//! sets the protocols use: the front sets (15) and (21) and the set behind (18).
//!
//! Lanes are absolute indices, 0 = rightmost; lane j spans y ∈ [j Wl, (j+1) Wl]. The
//! paper's relative lanes (0 = own, m = ±1 target) map to ℓ(c0) and ℓ(c0) + m.

use crate::real::Real;
use core::cmp::Ordering;

/// The road: how many lanes, how wide, and where it ends (dead end x_R, (22)).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Road<F> {
    /// Number of lanes (≥ 1).
    pub lanes: u8,
    /// Lane width Wl (m).
    pub lane_width: F,
    /// x_R: where the road ends, if it does (m).
    pub end_x: Option<F>,
}

impl<F: Real> Road<F> {
    /// Right edge (smallest y) of lane `j`.
    #[inline]
    pub fn lane_bottom(&self, j: u8) -> F {
        F::from_usize(usize::from(j)) * self.lane_width
    }
    /// Left edge (largest y) of lane `j`.
    #[inline]
    pub fn lane_top(&self, j: u8) -> F {
        F::from_usize(usize::from(j) + 1) * self.lane_width
    }
    /// Centre line of lane `j`.
    #[inline]
    pub fn lane_centre(&self, j: u8) -> F {
        (F::from_usize(usize::from(j)) + F::HALF) * self.lane_width
    }
    /// `true` if `j` is a lane of this road.
    #[inline]
    pub fn has_lane(&self, j: u8) -> bool {
        j < self.lanes
    }
    /// The lane whose span contains `y` (clamped to the road).
    pub fn lane_of(&self, y: F) -> u8 {
        let mut j = 0u8;
        while j + 1 < self.lanes && y >= self.lane_top(j) {
            j += 1;
        }
        j
    }
    /// The lateral band (11)(12) of a vehicle in lane `lane` changing to `alpha` (if
    /// any): the edges of the lanes it may occupy, [y̲, ȳ] (not yet shrunk by the
    /// vehicle's extent; see [`Band::shrunk`]).
    pub fn band(&self, lane: u8, alpha: Option<u8>) -> Band<F> {
        let other = alpha.unwrap_or(lane);
        Band {
            lo: self.lane_bottom(lane.min(other)),
            hi: self.lane_top(lane.max(other)),
        }
    }
}

/// A lateral band [lo, hi] (m).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Band<F> {
    /// y̲ (12).
    pub lo: F,
    /// ȳ (11).
    pub hi: F,
}

impl<F: Real> Band<F> {
    /// The band for the reference point of a vehicle of width W heading along the road
    /// (shrunk by W/2 on each side, SPEC §1).
    pub fn shrunk(&self, half_width: F) -> Self {
        Self {
            lo: self.lo + half_width,
            hi: self.hi - half_width,
        }
    }
}

/// Another vehicle as the ego knows it from its last message.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Other<F> {
    /// Its id (breaks the last tie of the ordering).
    pub id: u16,
    /// Centre x (m).
    pub x: F,
    /// v_{t−h}: the speed it applied over the last period (m/s).
    pub v: F,
    /// Length L(c) (m).
    pub length: F,
    /// ℓ(c).
    pub lane: u8,
    /// α(c): lane being changed to.
    pub alpha: Option<u8>,
    /// β(c): intended lane, before the change starts.
    pub beta: Option<u8>,
    /// Age of the information (s): now − the sender's time stamp; 0 when fresh.
    pub age: F,
    /// It follows the protocols: it hears intentions and yields (the paper's vehicles).
    /// `false` for a vehicle that does not (scripted, legacy, or whose messages were
    /// rejected): it may accelerate at amax and never yields to an intention, though it
    /// brakes for what is physically in its lane (RSS-style), and keeps its lane.
    pub cooperative: bool,
    /// A return of the ego's own range sensor ([`crate::sensing`]), not a message: x and
    /// v are measurements within the sensing error bounds, `lane`/`alpha` the lanes its
    /// rectangle overlaps (lowest, and the other one if it straddles two), age 0, and no
    /// intention (β) is known from it.
    pub sensed: bool,
    /// Its braking limit |amin| (m/s², > 0) as it declared it over V2V, when that bounds
    /// where it can stop: declared by a vehicle that cooperated, in a message the
    /// receiver trusted. It stays when the vehicle is distrusted later (`cooperative`
    /// turns `false`): the bound its last trusted message gives is still valid, and a
    /// follower close behind on that bound must keep it ([`crate::WorldView::others`]
    /// fills it so). `None` if it declared none, does not cooperate, or is a sensor
    /// return: then it is a wall under either invariant.
    pub brake: Option<crate::safety::BrakeLimit>,
}

impl<F: Real> Other<F> {
    /// A cooperative vehicle known from its V2V message: at `x` in `lane` with speed `v`,
    /// `length` long, data `age` old, no change declared or under way.
    pub fn v2v(id: u16, x: F, v: F, length: F, lane: u8, age: F) -> Self {
        Self {
            id,
            x,
            v,
            length,
            lane,
            alpha: None,
            beta: None,
            age,
            cooperative: true,
            sensed: false,
            brake: None,
        }
    }
}

/// What the ordering and the sets need to know of a vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Key<F> {
    /// x (m).
    pub x: F,
    /// v (m/s).
    pub v: F,
    /// Lane.
    pub lane: u8,
    /// Id.
    pub id: u16,
}

/// Definition 1, the inter-vehicle ordering ≺_t: by x, then speed, then lane; the id
/// breaks what is left (two vehicles cannot share x, v and lane without colliding, but
/// the order must be total on any input).
pub fn order<F: Real>(a: &Key<F>, b: &Key<F>) -> Ordering {
    let by = |p: F, q: F| p.partial_cmp(&q).unwrap_or(Ordering::Equal);
    by(a.x, b.x)
        .then(by(a.v, b.v))
        .then(a.lane.cmp(&b.lane))
        .then(a.id.cmp(&b.id))
}

/// `true` if a ≺_t b.
#[inline]
pub fn precedes<F: Real>(a: &Key<F>, b: &Key<F>) -> bool {
    order(a, b) == Ordering::Less
}

/// The lanes a vehicle occupies or is entering: {ℓ, α}.
#[inline]
fn occupies(c: &Other<impl Real>, lanes: &[Option<u8>]) -> bool {
    lanes
        .iter()
        .flatten()
        .any(|&j| c.lane == j || c.alpha == Some(j))
}

/// Membership in the front set (15): c is at or ahead of the ego (x(c0) ≤ x(c)) and
/// is in, or changing to, the ego's lane ℓ or target α.
pub fn in_front_set<F: Real>(ego_x: F, ego_lane: u8, ego_alpha: Option<u8>, c: &Other<F>) -> bool {
    ego_x <= c.x && occupies(c, &[Some(ego_lane), ego_alpha])
}

/// Membership in the yield front set (21): c0 ≺ c, and c is in, changing to, or intends
/// to change to one of the ego's lanes {ℓ, α, β}. A vehicle ahead (in ≺) that wants my
/// lane is my leader: this is how the Yield Protocol (20) is carried out.
pub fn in_yield_set<F: Real>(
    ego: &Key<F>,
    alpha: Option<u8>,
    beta: Option<u8>,
    c: &Other<F>,
) -> bool {
    let key = Key {
        x: c.x,
        v: c.v,
        lane: c.lane,
        id: c.id,
    };
    if !precedes(ego, &key) {
        return false;
    }
    let mine = [Some(ego.lane), alpha, beta];
    mine.iter()
        .flatten()
        .any(|&j| c.lane == j || c.alpha == Some(j) || c.beta == Some(j))
}

/// Membership in the set behind (18) for a change into lane `m`: c is at or behind the
/// ego and is in lane m or changing to it.
pub fn in_behind_set<F: Real>(ego_x: F, m: u8, c: &Other<F>) -> bool {
    c.x <= ego_x && (c.lane == m || c.alpha == Some(m))
}

/// `true` if c is in lane `m`, changing to it, or — when its intention is not known
/// (`intent_known` false: its data is older than the notification bound, or it is known
/// only from the ego's sensor) — next to `m`, so that it may have started a change into
/// `m` the ego has not heard of. A vehicle that does not cooperate keeps its lane.
pub fn may_occupy<F: Real>(m: u8, c: &Other<F>, intent_known: bool) -> bool {
    c.lane == m || c.alpha == Some(m) || (!intent_known && c.cooperative && c.lane.abs_diff(m) == 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn other(x: f64, lane: u8, alpha: Option<u8>, beta: Option<u8>) -> Other<f64> {
        Other {
            alpha,
            beta,
            ..Other::v2v(9, x, 10.0, 4.5, lane, 0.0)
        }
    }

    #[test]
    fn sets_follow_the_definitions() {
        // Ego in lane 1 at x = 50, changing to lane 2.
        assert!(in_front_set(50.0, 1, Some(2), &other(60.0, 2, None, None)));
        assert!(in_front_set(
            50.0,
            1,
            Some(2),
            &other(60.0, 0, Some(1), None)
        ));
        assert!(!in_front_set(
            50.0,
            1,
            Some(2),
            &other(60.0, 0, None, Some(1))
        ));
        assert!(!in_front_set(50.0, 1, Some(2), &other(40.0, 1, None, None)));
        let ego = Key {
            x: 50.0,
            v: 10.0,
            lane: 1,
            id: 1,
        };
        // (21) also takes intentions into account, and uses ≺.
        assert!(in_yield_set(
            &ego,
            None,
            None,
            &other(60.0, 0, None, Some(1))
        ));
        assert!(in_yield_set(
            &ego,
            None,
            Some(2),
            &other(60.0, 2, None, None)
        ));
        assert!(!in_yield_set(
            &ego,
            None,
            None,
            &other(60.0, 2, None, Some(3))
        ));
        // Same x and speed: the higher lane is ahead.
        assert!(in_yield_set(
            &ego,
            None,
            None,
            &other(50.0, 2, None, Some(1))
        ));
        assert!(!in_yield_set(
            &ego,
            None,
            None,
            &other(50.0, 0, None, Some(1))
        ));
        assert!(in_behind_set(50.0, 2, &other(40.0, 2, None, None)));
        assert!(in_behind_set(50.0, 2, &other(40.0, 3, Some(2), None)));
        assert!(!in_behind_set(50.0, 2, &other(40.0, 3, None, Some(2))));
    }

    #[test]
    fn geometry() {
        let r = Road {
            lanes: 3,
            lane_width: 3.6,
            end_x: None,
        };
        assert_eq!(r.lane_of(5.0), 1);
        assert_eq!(r.lane_of(-1.0), 0);
        assert_eq!(r.lane_of(50.0), 2);
        let b = r.band(1, Some(0));
        assert!((b.lo - 0.0).abs() < 1e-12 && (b.hi - 7.2).abs() < 1e-12);
    }
}
