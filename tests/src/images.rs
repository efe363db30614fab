//! Where the firmware's release images are built: one target directory for
//! all of them (`target/firmware`), so that the dependencies (the HAL, RTIC,
//! defmt and their proc macros) compile once, not once per image; each
//! image's ELF is then copied to `target/images/<name>/firmware`, where it
//! stays while the next image is built.
//!
//! Cargo keeps every feature set's artefacts side by side in one target
//! directory but links each into the same path
//! (`thumbv7m-none-eabi/release/firmware`): a build and the copy of its ELF
//! therefore run under an exclusive file lock (`target/firmware/.image-lock`),
//! which also orders builds started by two test threads or two processes.

use std::fs::{self, File, OpenOptions};
use std::io;
use std::path::PathBuf;
use std::process::Command;

use crate::workspace_root;

/// The firmware's target triple.
pub const TARGET: &str = "thumbv7m-none-eabi";

/// The one target directory of every firmware image (`cargo clippy` of the
/// firmware uses it too).
pub fn target_dir() -> PathBuf {
    workspace_root().join("target").join("firmware")
}

/// Where the image called `name` is kept once built.
pub fn elf_path(name: &str) -> PathBuf {
    workspace_root()
        .join("target")
        .join("images")
        .join(name)
        .join("firmware")
}

/// Held while an image is built and copied out (released on drop).
pub struct BuildLock(File);

impl Drop for BuildLock {
    fn drop(&mut self) {
        let _ = self.0.unlock();
    }
}

/// Waits for, and takes, the exclusive right to build an image.
pub fn lock() -> io::Result<BuildLock> {
    let dir = target_dir();
    fs::create_dir_all(&dir)?;
    let file = OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(dir.join(".image-lock"))?;
    file.lock()?;
    Ok(BuildLock(file))
}

/// The release build of the firmware with `features_args` (for example
/// `["--no-default-features", "--features", "board-qemu"]`), in
/// [`target_dir`]; run it while holding [`lock`], then [`keep`] the ELF.
pub fn build_command(features_args: &[&str]) -> Command {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(workspace_root())
        .args([
            "build",
            "--package",
            "firmware",
            "--release",
            "--target",
            TARGET,
        ])
        .args(features_args)
        .arg("--target-dir")
        .arg(target_dir());
    cmd
}

/// Copies the ELF just built to [`elf_path`]`(name)` and returns that path.
pub fn keep(_lock: &BuildLock, name: &str) -> io::Result<PathBuf> {
    let built = target_dir().join(TARGET).join("release").join("firmware");
    let kept = elf_path(name);
    if let Some(dir) = kept.parent() {
        fs::create_dir_all(dir)?;
    }
    // Copy to a temporary name and rename: a reader never sees half a file.
    let partial = kept.with_extension("partial");
    fs::copy(&built, &partial)?;
    fs::rename(&partial, &kept)?;
    Ok(kept)
}

/// Builds the image called `name` with `features_args` and returns its kept
/// ELF ([`lock`], [`build_command`], [`keep`]).
pub fn build(name: &str, features_args: &[&str]) -> io::Result<PathBuf> {
    let lock = lock()?;
    let status = build_command(features_args).status()?;
    if !status.success() {
        return Err(io::Error::other(format!(
            "building the firmware image {name} ({}) failed: {status}",
            features_args.join(" ")
        )));
    }
    keep(&lock, name)
}
