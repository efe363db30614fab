//! Semihosting file calls (ARM semihosting specification 2.0).
use cortex_m_semihosting::{nr, syscall};

/// Opens `path` (with `suffix` appended, if any).
pub fn open(path: &[u8], mode: usize, suffix: Option<u8>) -> Option<usize> {
    // SYS_OPEN wants a NUL-terminated name.
    let mut name = [0u8; 98];
    let dst = name.get_mut(..path.len())?;
    dst.copy_from_slice(path);
    let mut len = path.len();
    if let Some(c) = suffix {
        *name.get_mut(len)? = c;
        len += 1;
    }
    let block = [name.as_ptr() as usize, mode, len];
    // SAFETY: the block describes a live NUL-terminated buffer.
    let h = unsafe { syscall(nr::OPEN, &block) };
    (h != usize::MAX).then_some(h)
}

pub fn seek(h: usize, pos: u32) -> bool {
    let block = [h, pos as usize];
    // SAFETY: plain values.
    unsafe { syscall(nr::SEEK, &block) == 0 }
}

pub fn read(h: usize, buf: &mut [u8]) -> bool {
    let block = [h, buf.as_mut_ptr() as usize, buf.len()];
    // SAFETY: the block describes a live, writable buffer.
    unsafe { syscall(nr::READ, &block) == 0 }
}

pub fn write(h: usize, buf: &[u8]) -> bool {
    let block = [h, buf.as_ptr() as usize, buf.len()];
    // SAFETY: the block describes a live buffer.
    unsafe { syscall(nr::WRITE, &block) == 0 }
}

pub fn flen(h: usize) -> usize {
    let block = [h];
    // SAFETY: plain value.
    unsafe { syscall(nr::FLEN, &block) }
}
