//! What a vehicle's view keeps when more vehicles are in radio range than it holds: the
//! ones that may matter to its plan, judged by distance *and speed* (`heard::slack`), so
//! that a jam — hundreds standing within the fixed radius of two vehicles at vmax — is no
//! overflow, and a view that truly cannot hold every vehicle that may matter says so.

use crate::common::lane_state;
use host_sim::bus::Message;
use host_sim::world::heard::{reach, slack, Here, Record, View, VIEW_CAP};
use host_sim::world::network::Network;
use host_sim::world::{Body, Fleet};

fn net() -> Network {
    Network::road(2, None, 27.8)
}

/// The relevance radius of Table I on a road (twice dS(vmax) and a second at vmax, and
/// 20 m): the radio's range, within which a fixed radius once judged every vehicle.
const RADIUS_M: f64 = 195.0;

/// The receiver (vehicle 0): at x = 0 in the centre of lane 0, at `v`.
fn receiver(v: f64) -> Here {
    Here { at: (0.0, 1.8), v }
}

/// Vehicle `id` at `x` on lane `lane` at `v`, stamped 1 s.
fn state(id: u16, x: f64, lane: u8, v: f64) -> Message {
    let mut state = lane_state(id, x, v, 1.0);
    state.lane = lane;
    state.y = 1.8 + 3.6 * f64::from(lane);
    Message::State { state, segment: 0 }
}

fn ids(view: &View) -> Vec<u16> {
    view.records()
        .iter()
        .map(|r| match *r {
            Record::Lane { state, .. } => state.id,
            Record::Crossing { report, .. } => report.id,
        })
        .collect()
}

/// The reach of Table I's vehicle: 77.0 m at vmax, 4.75 m standing (a second from rest
/// at amax, and the safe distance at the speed reached). With trucks in the fleet: dS at
/// their 4.5 m/s² and half their extra 12 m, 120.0 m at vmax.
#[test]
fn reach_is_a_second_and_a_safe_distance_at_the_speed_within_reach() {
    let cars = Fleet::default();
    let reach = |v| reach(v, cars);
    let slack = |d, v, w| slack(d, (v, w), cars);
    assert!((reach(27.8) - 76.99).abs() < 0.01, "{}", reach(27.8));
    assert!((reach(0.0) - 4.752).abs() < 0.01, "{}", reach(0.0));
    assert!(reach(10.0) > reach(5.0));
    assert_eq!(slack(29.51, 0.0, 0.0).signum(), 1.0);
    assert_eq!(slack(29.49, 0.0, 0.0).signum(), -1.0);
    let trucks = Fleet::of([Body::TRUCK]);
    let truck = host_sim::world::heard::reach(27.8, trucks);
    assert!((truck - 119.95).abs() < 0.01, "{truck}");
}

/// 1,000 vehicles standing 6 m apart on both lanes, the receiver standing among them:
/// more than 256 within the old fixed radius (195 m), about twenty within reach. Every
/// vehicle within reach is kept, and nothing overflows.
#[test]
fn a_jam_fills_no_view() {
    let (net, me, mut view) = (net(), receiver(0.0), View::new(0, RADIUS_M));
    let mut near = Vec::new();
    for k in 0..1000u16 {
        let x = -1500.0 + 6.0 * f64::from(k / 2);
        let lane = (k % 2) as u8;
        let id = k + 1;
        let _ = view.take(&state(id, x, lane, 0.0), &net, me);
        let dy = 3.6 * f64::from(lane);
        if slack((x * x + dy * dy).sqrt(), (0.0, 0.0), Fleet::default()) <= 0.0 {
            near.push(id);
        }
    }
    assert!(!view.take_overflow(), "no overflow");
    assert!(near.len() >= 16, "{} within reach", near.len());
    let held = ids(&view);
    assert_eq!(held.len(), VIEW_CAP);
    for id in near {
        assert!(held.contains(&id), "vehicle {id} within reach is kept");
    }
}

/// A vehicle at speed matters farther than one standing: a full view of standing vehicles
/// takes a fast one 90 m away (its slack is negative) in place of the least relevant.
#[test]
fn a_fast_vehicle_displaces_standing_ones_that_cannot_matter() {
    let (net, me, mut view) = (net(), receiver(0.0), View::new(0, RADIUS_M));
    for k in 0..VIEW_CAP as u16 {
        let _ = view.take(&state(k + 1, 40.0 + 6.0 * f64::from(k), 0, 0.0), &net, me);
    }
    assert_eq!(view.records().len(), VIEW_CAP);
    assert!(slack(90.0, (0.0, 27.8), Fleet::default()) < 0.0);
    assert_eq!(view.take(&state(999, -90.0, 1, 27.8), &net, me), Ok(()));
    assert!(ids(&view).contains(&999));
    assert!(
        !ids(&view).contains(&(VIEW_CAP as u16)),
        "the farthest went"
    );
    assert!(!view.take_overflow(), "what went could not matter");
}

/// With trucks in the world a record matters from farther: a full view of vehicles at
/// vmax 106 to 150 m away, beyond every car's reach but within a truck's, gives one up for
/// a standing vehicle close by — without loss among cars, and, in a fleet with trucks,
/// saying that what went may have mattered.
#[test]
fn with_trucks_about_a_view_keeps_vehicles_from_farther() {
    let trucks = Fleet::of([Body::TRUCK]);
    assert!(slack(106.0, (0.0, 27.8), Fleet::default()) > 0.0);
    assert!(slack(150.0, (0.0, 27.8), trucks) < 0.0);
    for (fleet, lost) in [(Fleet::default(), false), (trucks, true)] {
        let (net, me) = (net(), receiver(0.0));
        let mut view = View::new(0, RADIUS_M).for_fleet(fleet);
        for k in 0..VIEW_CAP as u16 {
            let x = 106.0 + 44.0 * f64::from(k) / f64::from(VIEW_CAP as u16 - 1);
            let _ = view.take(&state(k + 1, x, 0, 27.8), &net, me);
        }
        assert!(!view.take_overflow());
        assert_eq!(view.take(&state(999, 10.0, 1, 0.0), &net, me), Ok(()));
        assert_eq!(view.take_overflow(), lost, "{fleet:?}");
    }
}

/// Where more vehicles may matter than a view holds — 300 at vmax within 150 m — the view
/// says so: the receiver cannot know it has every vehicle that matters.
#[test]
fn a_view_that_cannot_hold_what_matters_overflows() {
    let (net, me, mut view) = (net(), receiver(27.8), View::new(0, RADIUS_M));
    for k in 0..300u16 {
        let x = -150.0 + f64::from(k);
        let _ = view.take(&state(k + 1, x, (k % 2) as u8, 27.8), &net, me);
    }
    assert!(view.take_overflow(), "an overflow is reported");
}
