//! Where a vehicle is: on a segment in its frame, or in a junction along a route's path.
//! Below the vehicle and its sensors, so that both can name a place without naming each
//! other.

use super::network::{Network, Place};
use super::LANE_WIDTH_M;

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

/// Where a vehicle is in one segment's frame: its pose, its lane, and whether it is
/// mapped there from a junction's path (its centre along a route that continues onto the
/// segment) rather than driving on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnSegment {
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// Heading relative to the segment (rad).
    pub theta: f64,
    /// Lane.
    pub lane: u8,
    /// Mapped from a junction's path (centred and straight in its lane).
    pub mapped: bool,
}

impl At {
    /// Where it is in segment `seg`'s frame: on it, or in a junction on a path that
    /// continues onto it (centred and straight in the lane the path leads to); `None`
    /// elsewhere.
    pub fn on_segment(&self, net: &Network, seg: usize) -> Option<OnSegment> {
        match *self {
            At::Lane {
                seg: s,
                x,
                y,
                theta,
                lane,
                ..
            } if s == seg => Some(OnSegment {
                x,
                y,
                theta,
                lane,
                mapped: false,
            }),
            At::Crossing { junction, route, s } => {
                let (sg, x, lane) = net.on_segment(junction, route, s)?;
                (sg == seg).then(|| OnSegment {
                    x,
                    y: (f64::from(lane) + 0.5) * LANE_WIDTH_M,
                    theta: 0.0,
                    lane,
                    mapped: true,
                })
            }
            At::Lane { .. } => None,
        }
    }
}
