//! Internal fixed-point helpers: every computation widens to [`W`]
//! (`U32F32`, 64-bit) and narrows back to the storage type with a checked
//! conversion. No operator here can panic.

use fixed::traits::{Fixed, ToFixed};
use fixed::types::U32F32;

use crate::Error;

/// The working type: `U32F32` (0 … 4.3e9, resolution 2.3e-10).
pub(crate) type W = U32F32;

/// Widens any storage value into [`W`] (saturating; all storage types fit).
pub(crate) fn widen<S: ToFixed>(v: S) -> W {
    W::saturating_from_num(v)
}

/// Narrows, saturating at the storage type's limits.
pub(crate) fn narrow<T: Fixed>(w: W) -> T {
    T::saturating_from_num(w)
}

/// Narrows, failing with [`Error::Overflow`] if the value does not fit.
pub(crate) fn try_narrow<T: Fixed>(w: W) -> Result<T, Error> {
    T::checked_from_num(w).ok_or(Error::Overflow)
}

pub(crate) fn mul(a: W, b: W) -> Result<W, Error> {
    a.checked_mul(b).ok_or(Error::Overflow)
}

pub(crate) fn div(a: W, b: W) -> Result<W, Error> {
    if b == W::ZERO {
        return Err(Error::DivisionByZero);
    }
    a.checked_div(b).ok_or(Error::Overflow)
}

pub(crate) fn mul_int(a: W, b: u64) -> Result<W, Error> {
    a.checked_mul_int(b).ok_or(Error::Overflow)
}

pub(crate) fn div_int(a: W, b: u64) -> Result<W, Error> {
    a.checked_div_int(b).ok_or(Error::DivisionByZero)
}

pub(crate) fn add(a: W, b: W) -> Result<W, Error> {
    a.checked_add(b).ok_or(Error::Overflow)
}

/// π with the precision of [`W`].
pub(crate) const PI: W = W::lit("3.14159265358979323846");
