//! Picks the linker memory map of the board being built.
use std::{env, fs, path::PathBuf};

fn main() -> Result<(), String> {
    let out = PathBuf::from(env::var_os("OUT_DIR").ok_or("cargo did not set OUT_DIR")?);
    let qemu = env::var_os("CARGO_FEATURE_BOARD_QEMU").is_some();
    let stm32 = env::var_os("CARGO_FEATURE_BOARD_STM32F103").is_some();
    let memory = match (stm32, qemu) {
        (true, false) => "memory-stm32f103.x",
        (false, true) => "memory-qemu.x",
        (true, true) => {
            return Err("two boards selected: build the QEMU board with \
                 `--no-default-features --features board-qemu`"
                .into())
        }
        (false, false) => {
            return Err("no board selected: enable `board-stm32f103` or `board-qemu`".into())
        }
    };
    fs::copy(memory, out.join("memory.x")).map_err(|e| format!("copy {memory}: {e}"))?;
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory-stm32f103.x");
    println!("cargo:rerun-if-changed=memory-qemu.x");
    println!("cargo:rerun-if-changed=build.rs");
    Ok(())
}
