//! The real board's release images, built for the twin in the firmware's
//! one target directory (`target/firmware`, `qemu_tests::images`: never a
//! host build's, so they never fight it for cargo's lock).

use std::io;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A real-board image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Image {
    /// `cargo build -p firmware --release --target thumbv7m-none-eabi`
    /// (the default features: `board-stm32f103,profile-a`).
    ProfileA,
    /// `… --no-default-features --features board-stm32f103,profile-b`.
    ProfileB,
    /// `… --features drive-link`: profile A with the drum driver's link,
    /// linked for the 128 KB parts (firmware/memory-stm32f103-128k.x).
    ProfileALink,
}

/// The workspace root (this crate lives in `<root>/twin`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

impl Image {
    /// The firmware's cargo features.
    pub fn features(self) -> &'static str {
        match self {
            // The default features, as `cargo xtask size` builds the image.
            Image::ProfileA => "board-stm32f103,profile-a",
            Image::ProfileB => "board-stm32f103,profile-b",
            Image::ProfileALink => "board-stm32f103,profile-a,drive-link",
        }
    }

    /// Environment variable that names a prebuilt ELF instead (another
    /// branch's image, or `cargo xtask`'s).
    pub fn env_var(self) -> &'static str {
        match self {
            Image::ProfileA => "TWIN_ELF_A",
            Image::ProfileB => "TWIN_ELF_B",
            Image::ProfileALink => "TWIN_ELF_A_LINK",
        }
    }

    /// The name its ELF is kept under (`target/images/<name>/firmware`,
    /// built in the one firmware target directory: `qemu_tests::images`).
    pub fn name(self) -> &'static str {
        match self {
            Image::ProfileA => "twin-a",
            Image::ProfileB => "twin-b",
            Image::ProfileALink => "twin-a-link",
        }
    }

    /// Builds the image once per process (or takes `TWIN_ELF_A`/`_B`/`_A_LINK`) and
    /// returns the ELF path.
    pub fn elf(self) -> io::Result<PathBuf> {
        static BUILT: [OnceLock<Result<PathBuf, String>>; 3] =
            [OnceLock::new(), OnceLock::new(), OnceLock::new()];
        if let Some(p) = std::env::var_os(self.env_var()) {
            return Ok(PathBuf::from(p));
        }
        let slot = &BUILT[self as usize];
        slot.get_or_init(|| self.build().map_err(|e| e.to_string()))
            .clone()
            .map_err(io::Error::other)
    }

    /// Runs the release build (`qemu_tests::images::build`).
    pub fn build(self) -> io::Result<PathBuf> {
        qemu_tests::images::build(
            self.name(),
            &["--no-default-features", "--features", self.features()],
        )
    }
}
