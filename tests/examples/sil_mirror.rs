//! The firmware's vehicle computer in the loop, mirrored on the host: replays the bytes
//! one `sil` image received over its serial line in a `host-sim run --firmware` (its
//! record, `firmware-ID.rx.slcan`) into the same node, built here from the firmware's own
//! source (`firmware-example/src/sil_node.rs`) in the same precision (f32), and requires
//! the bytes it sends back to be the image's (`firmware-ID.tx.slcan`), byte for byte. Its
//! commands are the MCU's, bit for bit, or it says at which period they part.
//!
//! `cargo run --release -p workspace-tests --example sil_mirror -- N RX TX [--steps]`
//!
//! N is the image's horizon (20 or 50). `--steps` prints every period's command with the
//! host's solver iterations (speed MPC, lateral QP): where a period's work on the MCU is
//! long, the host says why. Exit 0 if the bytes are equal, 1 if not, 2 for bad arguments.

// The board's loop reads the figures it times (periods, overruns); the host does not.
#[allow(dead_code)]
#[path = "../../firmware-example/src/sil_node.rs"]
mod sil_node;

use can_gateway::slcan::{Line, LineBuffer};
use can_gateway::wire::{Command, Message};
use can_gateway::{Instant, PlainFrame, Reassembler};
use planner_core::{LanePlanner, LanePlannerSlot};
use sil_node::{Event, Lost, Node, Port};
use std::process::ExitCode;

/// The host's end of the node's line: what it sends, kept.
#[derive(Default)]
struct Sent(Vec<u8>);

impl Port for Sent {
    fn send(&mut self, bytes: &[u8]) -> Result<(), Lost> {
        self.0.extend_from_slice(bytes);
        Ok(())
    }
}

/// One period as the host's node planned it.
struct Step {
    period: u32,
    iterations: (u32, u32),
}

/// Feeds `rx` to a fresh node with a horizon-`N` planner, as the board's loop does; what
/// it sent, and each period's solver iterations.
fn replay<const N: usize>(rx: &[u8]) -> (Vec<u8>, Vec<Step>) {
    let mut node = Box::new(Node::new());
    let mut slot = Box::new(LanePlannerSlot::<f32, N>::new());
    let mut slot = Some(&mut *slot);
    let mut planner: Option<&mut LanePlanner<f32, N>> = None;
    let mut sent = Sent::default();
    let mut steps = Vec::new();
    for &byte in rx {
        match node.take(byte, &mut sent) {
            Event::None => {}
            Event::Refused(id, e) => eprintln!("sil_mirror: frame {id:08x} refused: {e:?}"),
            Event::Ego => {
                if let Some(s) = slot.take() {
                    planner = node.start(s);
                }
                node.announce(&mut sent);
            }
            Event::Tick(period, _) => {
                if let Some(lp) = planner.as_deref_mut() {
                    node.plan(lp, period, &mut sent);
                    steps.push(Step {
                        period,
                        iterations: node.last_iterations,
                    });
                }
            }
        }
    }
    (sent.0, steps)
}

/// The commands in a node's sent bytes, in order.
fn commands(tx: &[u8]) -> Vec<Command<f32>> {
    let mut lines = LineBuffer::new();
    let mut rx = Reassembler::<2>::new();
    let mut out = Vec::new();
    for &byte in tx {
        let Some(Ok(Line::Frame(f))) = lines.push::<PlainFrame>(byte) else {
            continue;
        };
        if let Ok(Some(Message::Command(c))) = rx.push::<f32, _>(&f, Instant::EPOCH) {
            out.push(c);
        }
    }
    out
}

fn bits(c: &Command<f32>) -> (u16, u32, u32) {
    (c.period, c.v.to_bits(), c.omega.to_bits())
}

/// Compares the image's sent bytes with the host's; prints the verdict.
fn compare(mcu: &[u8], host: &[u8]) -> bool {
    let (a, b) = (commands(mcu), commands(host));
    if let Some((x, y)) = a.iter().zip(&b).find(|(x, y)| bits(x) != bits(y)) {
        eprintln!(
            "sil_mirror: period {}: the MCU commanded v {:08x} ω {:08x}, the host v {:08x} ω {:08x}",
            x.period,
            x.v.to_bits(),
            x.omega.to_bits(),
            y.v.to_bits(),
            y.omega.to_bits()
        );
        return false;
    }
    if a.len() != b.len() || mcu != host {
        eprintln!(
            "sil_mirror: the lines differ ({} commands and {} bytes from the MCU, {} and {} from the host)",
            a.len(),
            mcu.len(),
            b.len(),
            host.len()
        );
        return false;
    }
    println!(
        "sil_mirror: {} commands (v, ω as f32 bits) and {} bytes sent, equal on the MCU and the host",
        a.len(),
        mcu.len()
    );
    !a.is_empty()
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let steps_wanted = args.iter().any(|a| a == "--steps");
    let paths: Vec<&String> = args.iter().filter(|a| *a != "--steps").collect();
    let [n, rx, tx] = paths.as_slice() else {
        eprintln!("usage: sil_mirror 20|50 RX TX [--steps]");
        return ExitCode::from(2);
    };
    let read = |p: &str| std::fs::read(p).map_err(|e| eprintln!("error: {p}: {e}"));
    let (Ok(rx), Ok(tx)) = (read(rx), read(tx)) else {
        return ExitCode::from(2);
    };
    let (sent, steps) = match n.as_str() {
        "20" => replay::<20>(&rx),
        "50" => replay::<50>(&rx),
        other => {
            eprintln!("error: horizon must be 20 or 50, got {other}");
            return ExitCode::from(2);
        }
    };
    if steps_wanted {
        for (s, c) in steps.iter().zip(commands(&sent)) {
            println!(
                "step {} v {} ω {} {:?} iterations {} + {}",
                s.period, c.v, c.omega, c.status, s.iterations.0, s.iterations.1
            );
        }
    }
    if compare(&tx, &sent) {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
