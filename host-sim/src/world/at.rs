//! Where a vehicle is: on a segment in its frame, or in a junction along a route's path.
//! Below the vehicle and its sensors, so that both can name a place without naming each
//! other.

use super::network::Place;

/// Where a vehicle is and its pose there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum At {
    /// On a segment, in its frame.
    Lane {
        /// Segment index.
        seg: usize,
        /// x (m).
        x: f64,
        /// y (m).
        y: f64,
        /// Heading relative to the segment (rad).
        theta: f64,
        /// ℓ.
        lane: u8,
        /// α.
        alpha: Option<u8>,
        /// β.
        beta: Option<u8>,
    },
    /// In a junction, along a route's path.
    Crossing {
        /// Junction index.
        junction: usize,
        /// Route.
        route: u8,
        /// Centre's distance along the route's path (m).
        s: f64,
    },
}

impl At {
    /// The place.
    pub fn place(&self) -> Place {
        match *self {
            At::Lane { seg, .. } => Place::Segment(seg),
            At::Crossing { junction, .. } => Place::Junction(junction),
        }
    }
}
