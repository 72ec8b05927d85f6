//! The attack experiment over the CAN hub — every attack on the Fig. 8
//! intersection and on the multi-lane road, every node authenticating.

use host_sim::experiments::attacks::{experiment, AttackRow, Settings};

fn row<'a>(rows: &'a [AttackRow], attack: &str, world: &str) -> &'a AttackRow {
    rows.iter()
        .find(|r| r.attack == attack && r.scenario == world)
        .unwrap_or_else(|| panic!("no row {attack} at the {world}"))
}

#[test]
fn no_forgery_or_replay_gets_through_and_no_attack_costs_safety() {
    let r = experiment(&Settings::default()).expect("runs");
    // 7 attacks at the intersection, 6 on the road (no manager there to crash).
    assert_eq!(r.results.len(), 13, "{r:#?}");
    assert!(r.authenticated);
    for x in &r.results {
        assert_eq!(x.unsafe_events(), 0, "{x:?}");
        assert_eq!(x.accepted, 0, "{x:?}");
        // The road has no manager: no grant to replay.
        if !(x.attack == "replayed-grant" && x.scenario == "multilane") {
            assert!(x.attempts > 0, "{x:?}");
        }
        // Refused frames are refused: every vehicle done, and on time.
        if x.attack != "lying-vehicle" {
            assert!(x.completed, "{x:?}");
            assert_eq!(x.done, x.vehicles as u64, "{x:?}");
        }
    }
    for world in ["intersection", "multilane"] {
        for attack in [
            "forged-grant",
            "replayed-grant",
            "replayed-state",
            "spoofed-id",
            "flood",
        ] {
            let x = row(&r.results, attack, world);
            assert_eq!(x.done_at_s, x.clean_done_at_s, "{x:?}");
            assert!(x.frames_rejected > 0 || x.attempts == 0, "{x:?}");
        }
        // Each lie heard is refused: first as implausible, then as the word of a suspect.
        let lies = row(&r.results, "lying-vehicle", world);
        assert!(lies.attempts > 100, "{lies:?}");
    }
    // The manager was down 3 s, granting nothing; all crossed after its restart.
    let crash = row(&r.results, "manager-crash", "intersection");
    assert_eq!(crash.attempts, 300);
    assert!(crash.done_at_s >= crash.clean_done_at_s, "{crash:?}");
}

#[test]
fn without_authentication_the_same_attacks_get_through() {
    // The oracle sees what gets through: without SecOC, the forged and spoofed messages
    // and the replayed grants are taken, and forged grants let vehicles into A_S.
    let s = Settings {
        authenticated: false,
        only: ["forged-grant", "replayed-grant", "spoofed-id"]
            .map(String::from)
            .to_vec(),
        worlds: vec!["intersection".into()],
        ..Settings::default()
    };
    let r = experiment(&s).expect("runs");
    assert_eq!(r.results.len(), 3);
    for x in &r.results {
        assert!(x.accepted > 0, "{x:?}");
    }
    let forged = row(&r.results, "forged-grant", "intersection");
    assert!(forged.unpermitted_entries > 0, "{forged:?}");
}

#[test]
fn on_can_fd_the_replays_and_forgeries_are_refused_too() {
    let s = Settings {
        fd: true,
        only: [
            "forged-grant",
            "replayed-grant",
            "replayed-state",
            "spoofed-id",
        ]
        .map(String::from)
        .to_vec(),
        worlds: vec!["intersection".into()],
        ..Settings::default()
    };
    let r = experiment(&s).expect("runs");
    assert!(r.can_fd);
    for x in &r.results {
        assert!(x.attempts > 0, "{x:?}");
        assert_eq!((x.accepted, x.unsafe_events()), (0, 0), "{x:?}");
        assert!(x.completed, "{x:?}");
    }
}
