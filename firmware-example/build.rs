//! Puts the board's memory map (`boards/*.x`, picked by the board feature) where
//! cortex-m-rt's link.x finds it, as `memory.x`, and the node's SecOC key — fixed at build
//! time from `FW_SECOC_KEY` (32 hex digits) — into `$OUT_DIR/secoc_key.rs`. A board built
//! for the wrong target stops the build with a message saying which target it needs.
use std::{env, fs, path::PathBuf};

/// The development key used when `FW_SECOC_KEY` is unset: public, for QEMU runs only.
const DEV_KEY: &str = "000102030405060708090a0b0c0d0e0f";

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let (board, map, target) = board();
    let built_for = env::var("TARGET").expect("cargo sets TARGET");
    if built_for != target {
        panic!("board {board} runs {target} code: build with --target {target} (not {built_for})");
    }
    fs::copy(map, out.join("memory.x")).expect("the board's memory map is readable");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=boards");
    println!("cargo:rerun-if-env-changed=FW_SECOC_KEY");
    let hex = match env::var("FW_SECOC_KEY") {
        Ok(k) => k,
        Err(_) => {
            println!(
                "cargo:warning=FW_SECOC_KEY is unset: building with the public development key"
            );
            DEV_KEY.to_string()
        }
    };
    let key = parse(hex.trim()).unwrap_or_else(|e| panic!("FW_SECOC_KEY: {e}"));
    let bytes: Vec<String> = key.iter().map(|b| format!("0x{b:02x}")).collect();
    fs::write(
        out.join("secoc_key.rs"),
        format!(
            "/// This node's AES-128 key (build time, `FW_SECOC_KEY`).\nconst KEY: [u8; 16] = [{}];\n",
            bytes.join(", ")
        ),
    )
    .expect("OUT_DIR is writable");
}

/// The board the features pick (none: the MPS2 AN386): its name, memory map and target.
fn board() -> (&'static str, &'static str, &'static str) {
    let an500 = env::var_os("CARGO_FEATURE_AN500").is_some();
    let an505 = env::var_os("CARGO_FEATURE_AN505").is_some();
    match (an500, an505) {
        (false, false) => ("an386", "boards/mps2.x", "thumbv7em-none-eabihf"),
        (true, false) => ("an500", "boards/mps2.x", "thumbv7em-none-eabihf"),
        (false, true) => ("an505", "boards/an505.x", "thumbv8m.main-none-eabihf"),
        (true, true) => panic!("features an500 and an505 are two boards: pick one"),
    }
}

/// 16 bytes from 32 hex digits.
fn parse(hex: &str) -> Result<[u8; 16], String> {
    if hex.len() != 32 || !hex.bytes().all(|c| c.is_ascii_hexdigit()) {
        return Err(format!("expected 32 hex digits, got {:?}", hex));
    }
    let mut key = [0u8; 16];
    for (i, b) in key.iter_mut().enumerate() {
        *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).map_err(|e| e.to_string())?;
    }
    Ok(key)
}
