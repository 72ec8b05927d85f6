//! Puts memory.x where cortex-m-rt's link.x finds it, and the node's SecOC key — fixed at
//! build time from `FW_SECOC_KEY` (32 hex digits) — into `$OUT_DIR/secoc_key.rs`.
use std::{env, fs, path::PathBuf};

/// The development key used when `FW_SECOC_KEY` is unset: public, for QEMU runs only.
const DEV_KEY: &str = "000102030405060708090a0b0c0d0e0f";

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("memory.x is readable");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
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
