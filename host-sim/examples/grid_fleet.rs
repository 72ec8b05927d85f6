//! Prints a `[grid]` network file with vehicles placed on its segments at the start (no
//! arrivals): the red team's "4×4 grid with 2,000 vehicles", and worlds of any size like
//! it (`host_sim::experiments::worlds::grid_fleet`, what `host-sim worlds` runs).
//!
//! `cargo run --release -p host-sim --example grid_fleet -- ROWS COLS VEHICLES [BLOCK_M]
//! [DURATION_S] > grid.toml`, then `host-sim run grid.toml`.

use host_sim::experiments::worlds::{grid_fleet, BLOCK_M};
use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let num = |i: usize, default: Option<f64>| -> Option<f64> {
        args.get(i).map_or(default, |s| s.parse().ok())
    };
    let (Some(rows), Some(cols), Some(n), Some(block), Some(duration)) = (
        num(0, None),
        num(1, None),
        num(2, None),
        num(3, Some(BLOCK_M)),
        num(4, Some(60.0)),
    ) else {
        eprintln!("usage: grid_fleet ROWS COLS VEHICLES [BLOCK_M] [DURATION_S]");
        return ExitCode::from(2);
    };
    match grid_fleet((rows as u8, cols as u8), n as usize, block, duration) {
        Ok(text) => {
            print!("{text}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
