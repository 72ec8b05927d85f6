//! Senders that lie: a state physically impossible after the sender's last
//! accepted one is refused with its reason and changes nothing; the sender becomes a
//! suspect whose later messages (states, `Left`, `Gone`) are refused too, and the planner
//! is handed its last trusted record, ageing, as a vehicle that does not cooperate.

use host_sim::bus::Message;
use host_sim::world::heard::{Here, Reject, View};
use host_sim::world::network::Network;
use host_sim::world::plausible::Implausible;
use planner_core::VehicleState;

/// The receiver: at the origin, standing.
const HERE: Here = Here {
    at: (0.0, 0.0),
    v: 0.0,
};

fn net() -> Network {
    Network::road(2, None, 27.8)
}

use crate::common::lane_state as state;

fn hear(view: &mut View, net: &Network, s: VehicleState<f64>) -> Result<(), Reject> {
    view.take(
        &Message::State {
            state: s,
            segment: 0,
        },
        net,
        HERE,
    )
}

fn others(view: &View, net: &Network, now: f64) -> Vec<planner_core::Other<f64>> {
    let mut out = heapless::Vec::new();
    view.others_on(net, 0, common::secs(now), 4.5, &mut out);
    out.into_iter().collect()
}

#[test]
fn a_liar_is_refused_and_then_taken_at_its_last_trusted_state() {
    let net = net();
    let mut view = View::new(1, 1e9);
    // An honest vehicle 7 at 20 m/s, heard every 10 ms.
    for k in 0..10 {
        let t = 0.01 * f64::from(k);
        hear(&mut view, &net, state(7, 100.0 + 20.0 * t, 20.0, t)).expect("honest");
    }
    let before = view.records().to_vec();
    // At 0.1 s it claims to be 3 m further on: refused, nothing changes.
    let lie = state(7, 102.0 + 3.0, 20.0, 0.1);
    assert_eq!(
        hear(&mut view, &net, lie),
        Err(Reject::Implausible(Implausible::Jump))
    );
    // From then on nothing of it is taken, though the lie is now within vmax·Δt of the
    // last trusted state, nor its claim to have left the network.
    let later = state(7, 105.0 + 20.0 * 0.1, 20.0, 0.2);
    assert_eq!(hear(&mut view, &net, later), Err(Reject::Distrusted));
    let gone = Message::Gone {
        id: 7,
        at: common::secs(0.3),
    };
    assert_eq!(view.take(&gone, &net, HERE), Err(Reject::Distrusted));
    // The record is the last trusted one, now marked as not cooperating.
    let kept = view.records().to_vec();
    assert_eq!(kept.len(), before.len());
    let seen = others(&view, &net, 0.5);
    assert_eq!(seen.len(), 1);
    assert_eq!(seen[0].x, 100.0 + 20.0 * 0.09);
    assert!(!seen[0].cooperative);
    assert!(
        (seen[0].age - (0.5 - 0.09)).abs() < 1e-12,
        "ageing: {}",
        seen[0].age
    );
    // Others are unaffected.
    hear(&mut view, &net, state(8, 50.0, 10.0, 0.0)).expect("honest");
    hear(&mut view, &net, state(8, 50.1, 10.0, 0.01)).expect("honest");
}

#[test]
fn each_kind_of_lie_has_its_reason() {
    let net = net();
    let cases: [(VehicleState<f64>, Implausible); 4] = [
        (state(7, 90.0, 20.0, 0.1), Implausible::Jump),
        (state(7, 101.0, 30.0, 0.1), Implausible::Speed),
        (state(7, 101.0, 12.0, 0.1), Implausible::Acceleration),
        (
            VehicleState {
                lane: 1,
                ..state(7, 101.0, 20.0, 0.1)
            },
            Implausible::LaneJump,
        ),
    ];
    for (lie, why) in cases {
        let mut view = View::new(1, 1e9);
        hear(&mut view, &net, state(7, 100.0, 20.0, 0.05)).expect("honest");
        assert_eq!(hear(&mut view, &net, lie), Err(Reject::Implausible(why)));
    }
}

use crate::common;

/// The multi-lane experiment's file with vehicle `liar` claiming to be `offset` m further on
/// from 2 s, sensors on or off.
fn lying(liar: u16, offset: f64, sensing: bool) -> host_sim::world::summary::Summary {
    let base = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/multilane.toml"),
    )
    .expect("the file");
    let text = format!(
        "{base}\n[faults.liar]\nid = {liar}\nfrom_s = 2.0\noffset_m = {offset}\n\n[sensing]\nenabled = {sensing}\n"
    );
    common::run_world(common::parse(&text, "multilane-liar"))
}

#[test]
fn a_vehicle_lying_about_its_position_is_refused_and_costs_no_safety() {
    for (liar, offset) in [(1, 5.0), (1, -5.0), (2, 3.0)] {
        for sensing in [true, false] {
            let s = lying(liar, offset, sensing);
            common::assert_safe(&s);
            assert!(
                s.messages_implausible > 0,
                "vehicle {liar} lying by {offset} m (sensing {sensing}): {s:?}"
            );
            // One refusal per receiver (5), then nothing of it is taken.
            assert_eq!(s.messages_implausible, 5, "{s:?}");
            println!(
                "liar {liar} offset {offset} sensing {sensing}: in target lane {}/{} implausible {} rejected {}",
                s.lane_changes.in_target_lane, s.vehicles, s.messages_implausible, s.messages_rejected
            );
        }
    }
}

/// The Fig. 8 intersection under `alg` with its manager down over [from, until): per
/// vehicle, the times its permission (a live lease, or being inside A_S) turned on.
fn manager_outage(
    alg: &str,
    from: f64,
    until: f64,
) -> (host_sim::world::summary::Summary, Vec<(u16, f64)>) {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/intersection.toml");
    let text = std::fs::read_to_string(path).expect("the file");
    let text =
        text.replace(
            "algorithm = \"concurrent\"",
            &format!("algorithm = \"{alg}\""),
        ) + &format!("\n[faults.manager_down]\njunction = 0\nfrom_s = {from}\nuntil_s = {until}\n");
    let spec = common::parse(&text, "intersection-outage");
    let mut w = host_sim::world::World::<20>::new(spec, host_sim::world::SolverChoice::Ours, None);
    let mut was = std::collections::HashMap::new();
    let mut on = Vec::new();
    while !w.finished() {
        w.step(&mut |r| {
            if let Some(g) = r.granted {
                if g && was.insert(r.id, g) == Some(false) {
                    on.push((r.id, r.t));
                }
                was.insert(r.id, g);
            }
        })
        .expect("the in-process bus does not fail");
    }
    (w.summary(0.0), on)
}

#[test]
fn a_manager_that_stops_mid_crossing_and_restarts_loses_no_safety_and_no_vehicle() {
    for alg in ["fifo", "pipelined", "stop"] {
        for (from, until) in [(3.0, 6.0), (6.0, 9.0), (9.0, 9.5)] {
            let (s, on) = manager_outage(alg, from, until);
            // Safe, nobody in A_S without a permission, and every vehicle crossed.
            common::assert_all_crossed_safely(&s, 8);

            // Once the leases given before the stop have run out, no vehicle gets a
            // permission until the restart: none enters A_S on its own.
            let late = on
                .iter()
                .filter(|&&(_, t)| t > from + 0.15 && t < until)
                .count();
            assert_eq!(late, 0, "{alg} down over [{from}, {until}): {on:?}");
        }
    }
}

#[test]
fn a_lie_or_an_outage_the_world_cannot_have_is_refused() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let junction = std::fs::read_to_string(dir.join("intersection.toml")).expect("the file");
    let road = std::fs::read_to_string(dir.join("multilane.toml")).expect("the file");
    for (text, says) in [
        (
            junction + "\n[faults.manager_down]\njunction = 1\nfrom_s = 1.0\nuntil_s = 2.0\n",
            "faults.manager_down.junction = 1: no junction has that id (the scenario's: 0)",
        ),
        (
            road.clone() + "\n[faults.liar]\nid = 1\nfrom_s = 1.0\noffset_m = 500.0\n",
            "faults.liar.offset_m = 500: must be within ±100 m",
        ),
        (
            road + "\n[faults.manager_down]\njunction = 0\nfrom_s = 2.0\nuntil_s = 1.0\n",
            "need 0 ≤ from_s < until_s",
        ),
    ] {
        let err =
            host_sim::scenario::parse(&text, std::path::Path::new("x.toml")).expect_err("refused");
        assert!(err.to_string().contains(says), "{err}");
    }
}
