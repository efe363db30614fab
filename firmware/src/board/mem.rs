//! Compact memory routines for the code the compiler generates (struct
//! copies and zeroing, slice comparisons), in place of `compiler_builtins`'
//! speed-tuned ones.
//!
//! The compiler lowers a copy of a large value to `__aeabi_memcpy{,4,8}`, a
//! zeroing to `__aeabi_memclr{,4,8}` and a slice comparison to `memcmp`.
//! `compiler_builtins` defines them as weak symbols with unrolled, aligning
//! loops: 1.4 KB of the profile A image (`memcpy` alone 744 B). These
//! strong definitions take their place in ≈ 0.1 KB: one word at a time when
//! both pointers are word-aligned (every struct copy; the `4`/`8` variants
//! guarantee it), one byte at a time otherwise. They are slower per byte
//! than the originals on long unaligned copies, which this firmware does not
//! make on any periodic path (the largest copies are the settings and the
//! machine at boot), and they take 16 B of stack where `compiler_builtins`'
//! `memcpy` took ≈ 90 B (the QEMU board's boot path is near its stack
//! limit).
//!
//! The loads and stores are volatile so that the optimiser cannot recognise
//! the loops as a copy and turn them back into a call to these very
//! functions. Semantics are those of the AEABI run-time ABI (ARM IHI 0043,
//! §4.3.4) and of C's `memcmp`: the regions of a copy do not overlap (a
//! `memmove` is a separate routine, which the firmware never calls).

use core::ptr::{read_volatile, write_volatile};

/// Copies `n` bytes from `src` to `dest` (no overlap).
///
/// # Safety
/// `src` readable and `dest` writable for `n` bytes, not overlapping.
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memcpy(dest: *mut u8, src: *const u8, n: usize) {
    let mut i = 0;
    if (dest as usize | src as usize).is_multiple_of(4) {
        while n - i >= 4 {
            // SAFETY: both word-aligned, `i + 4 <= n`: inside the regions.
            unsafe {
                write_volatile(
                    dest.add(i).cast::<u32>(),
                    read_volatile(src.add(i).cast::<u32>()),
                );
            }
            i += 4;
        }
    }
    while i < n {
        // SAFETY: `i < n`: inside the regions.
        unsafe { write_volatile(dest.add(i), read_volatile(src.add(i))) };
        i += 1;
    }
}

/// [`__aeabi_memcpy`] with both pointers 4-byte aligned.
///
/// # Safety
/// As [`__aeabi_memcpy`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memcpy4(dest: *mut u8, src: *const u8, n: usize) {
    // SAFETY: the caller's guarantee.
    unsafe { __aeabi_memcpy(dest, src, n) }
}

/// [`__aeabi_memcpy`] with both pointers 8-byte aligned.
///
/// # Safety
/// As [`__aeabi_memcpy`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memcpy8(dest: *mut u8, src: *const u8, n: usize) {
    // SAFETY: the caller's guarantee.
    unsafe { __aeabi_memcpy(dest, src, n) }
}

/// Zeroes `n` bytes at `dest`.
///
/// # Safety
/// `dest` writable for `n` bytes.
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memclr(dest: *mut u8, n: usize) {
    let mut i = 0;
    if (dest as usize).is_multiple_of(4) {
        while n - i >= 4 {
            // SAFETY: word-aligned, `i + 4 <= n`: inside the region.
            unsafe { write_volatile(dest.add(i).cast::<u32>(), 0) };
            i += 4;
        }
    }
    while i < n {
        // SAFETY: `i < n`: inside the region.
        unsafe { write_volatile(dest.add(i), 0) };
        i += 1;
    }
}

/// [`__aeabi_memclr`] with `dest` 4-byte aligned.
///
/// # Safety
/// As [`__aeabi_memclr`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memclr4(dest: *mut u8, n: usize) {
    // SAFETY: the caller's guarantee.
    unsafe { __aeabi_memclr(dest, n) }
}

/// [`__aeabi_memclr`] with `dest` 8-byte aligned.
///
/// # Safety
/// As [`__aeabi_memclr`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memclr8(dest: *mut u8, n: usize) {
    // SAFETY: the caller's guarantee.
    unsafe { __aeabi_memclr(dest, n) }
}

/// Compares `n` bytes: 0 if equal, else the difference of the first
/// differing bytes (as unsigned), as C's `memcmp`.
///
/// # Safety
/// `a` and `b` readable for `n` bytes.
#[no_mangle]
pub unsafe extern "C" fn memcmp(a: *const u8, b: *const u8, n: usize) -> i32 {
    let mut i = 0;
    while i < n {
        // SAFETY: `i < n`: inside the regions.
        let (x, y) = unsafe { (read_volatile(a.add(i)), read_volatile(b.add(i))) };
        if x != y {
            return i32::from(x) - i32::from(y);
        }
        i += 1;
    }
    0
}

/// `n / d`, and `n % d` into `*rem` when not null: what
/// `__aeabi_uldivmod` (`compiler_builtins`' AEABI entry, which stays)
/// calls for every `u64` division ([`crate::div64`]).
///
/// # Safety
/// `rem` null or writable.
#[no_mangle]
pub unsafe extern "C" fn __udivmoddi4(n: u64, d: u64, rem: *mut u64) -> u64 {
    let (q, r) = crate::div64::div_rem_u64(n, d);
    if !rem.is_null() {
        // SAFETY: the caller's guarantee.
        unsafe { rem.write(r) };
    }
    q
}

/// `a / b`, and `a % b` into `*rem`: what `__aeabi_ldivmod` calls for
/// every `i64` division ([`crate::div64`]).
///
/// # Safety
/// `rem` writable.
#[no_mangle]
pub unsafe extern "C" fn __divmoddi4(a: i64, b: i64, rem: *mut i64) -> i64 {
    let (q, r) = crate::div64::div_rem_i64(a, b, |n, d| {
        let mut r = 0;
        // SAFETY: `r` is writable.
        let q = unsafe { __udivmoddi4(n, d, &mut r) };
        (q, r)
    });
    // SAFETY: the caller's guarantee.
    unsafe { rem.write(r) };
    q
}
