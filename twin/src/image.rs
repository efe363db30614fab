//! The real board's release image, built for the twin in the firmware's
//! one target directory (`target/firmware`, `qemu_tests::images`: never a
//! host build's, so they never fight it for cargo's lock), and the flash a
//! probe leaves when it programs that image onto a board.
//!
//! One image runs every machine: the saved settings choose the machine
//! (profile A or B) and the drum driver's link, so a test sets up a machine
//! by writing a settings record into the board's settings pages.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use crate::periph::{FLASH_BASE, FLASH_PAGE as PAGE_BYTES, FLASH_SIZE};

/// Environment variable that names a prebuilt ELF instead of the build
/// (another branch's image, or `cargo xtask`'s).
pub const ELF_VAR: &str = "TWIN_ELF";

/// The workspace root (this crate lives in `<root>/twin`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// The real board's image: `cargo build -p firmware --release --target
/// thumbv7m-none-eabi` (the default feature, `board-stm32f103`), built once
/// per process, or the ELF `TWIN_ELF` names.
pub fn elf() -> io::Result<PathBuf> {
    static BUILT: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    if let Some(p) = std::env::var_os(ELF_VAR) {
        return Ok(PathBuf::from(p));
    }
    BUILT
        .get_or_init(|| {
            qemu_tests::images::build(
                "twin",
                &["--no-default-features", "--features", "board-stm32f103"],
            )
            .map_err(|e| e.to_string())
        })
        .clone()
        .map_err(io::Error::other)
}

/// The board's 128 KB of flash after a probe (probe-rs, cargo-flash)
/// programmed `elf` onto it: every 1 KB page that one of the ELF's loadable
/// segments touches is erased, then the segments are written; every other
/// page keeps what `before` held (`None`: an erased chip).
pub fn programmed(elf: &Path, before: Option<&[u8]>) -> io::Result<Vec<u8>> {
    use object::read::elf::{ElfFile32, ProgramHeader};
    let data = std::fs::read(elf)?;
    let file = ElfFile32::<object::Endianness>::parse(&*data).map_err(io::Error::other)?;
    let endian = file.endian();
    let mut flash = before
        .map(<[u8]>::to_vec)
        .unwrap_or_else(|| vec![0xFF; FLASH_SIZE as usize]);
    flash.resize(FLASH_SIZE as usize, 0xFF);
    let mut segments = Vec::new();
    for ph in file.elf_program_headers() {
        let size = ph.p_filesz(endian);
        if ph.p_type(endian) != object::elf::PT_LOAD || size == 0 {
            continue;
        }
        let at = ph.p_paddr(endian);
        if at < FLASH_BASE || at + size > FLASH_BASE + FLASH_SIZE {
            continue;
        }
        let bytes = ph
            .data(endian, &*data)
            .map_err(|_| io::Error::other("segment data"))?;
        segments.push((at - FLASH_BASE, bytes));
    }
    for &(off, bytes) in &segments {
        let first = off / PAGE_BYTES;
        let last = (off + bytes.len() as u32 - 1) / PAGE_BYTES;
        for page in first..=last {
            let p = (page * PAGE_BYTES) as usize;
            flash[p..p + PAGE_BYTES as usize].fill(0xFF);
        }
    }
    for (off, bytes) in segments {
        let off = off as usize;
        flash[off..off + bytes.len()].copy_from_slice(bytes);
    }
    Ok(flash)
}
