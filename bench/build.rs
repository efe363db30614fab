//! The bench runs on the QEMU board: use its memory map.
use std::{env, fs, path::PathBuf};

fn main() -> Result<(), String> {
    let out = PathBuf::from(env::var_os("OUT_DIR").ok_or("cargo did not set OUT_DIR")?);
    fs::copy("../firmware/memory-qemu.x", out.join("memory.x"))
        .map_err(|e| format!("copy memory-qemu.x: {e}"))?;
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=../firmware/memory-qemu.x");
    Ok(())
}
