//! Piecewise-linear coefficient tables (k1, k2, k3) that validate themselves
//! and serialise compactly for flash.
//!
//! A table holds 1 … [`MAX_POINTS`] points `(x, k)` with strictly increasing
//! `x` and every `k` in [`K_MIN`] … [`K_MAX`]. Evaluation interpolates
//! linearly between points and clamps at the ends (a one-point table is a
//! constant).
//!
//! Byte format (little endian), version [`TABLE_FORMAT_VERSION`]:
//! `[version, n, n × (x: u32 bits of U16F16, k: u32 bits of U2F30)]`, at most
//! [`TABLE_BYTES_MAX`] bytes. The firmware adds CRC and storage.
//!
//! ```
//! use kinematics::table::{CoeffTable, TablePoint};
//! use kinematics::units::Coefficient;
//! use fixed::types::U16F16;
//! let t = CoeffTable::new(&[
//!     TablePoint::new(U16F16::lit("0.32"), Coefficient::lit("1.031")),
//!     TablePoint::new(U16F16::lit("0.51"), Coefficient::lit("1.020")),
//! ])?;
//! // Half-way between the points: (1.031 + 1.020) / 2 = 1.0255.
//! let k = t.eval(U16F16::lit("0.415")).to_f64();
//! assert!((k - 1.0255).abs() < 1e-4);
//! // Clamped beyond the ends.
//! assert_eq!(t.eval(U16F16::lit("5")), Coefficient::lit("1.020"));
//! let (bytes, len) = t.to_array();
//! assert_eq!(CoeffTable::from_bytes(&bytes[..len])?.0, t);
//! # Ok::<(), kinematics::table::TableError>(())
//! ```

use fixed::types::U16F16;
use heapless::Vec;

use crate::fx;
use crate::units::Coefficient;

/// Most points a table may hold.
pub const MAX_POINTS: usize = 8;
/// Smallest accepted coefficient.
pub const K_MIN: Coefficient = Coefficient::lit("0.8");
/// Largest accepted coefficient.
pub const K_MAX: Coefficient = Coefficient::lit("1.2");
/// Version byte of the serialised table.
pub const TABLE_FORMAT_VERSION: u8 = 1;
/// Bytes per serialised point.
pub const POINT_BYTES: usize = 8;
/// Largest serialised table: version, count and 8 points.
pub const TABLE_BYTES_MAX: usize = 2 + MAX_POINTS * POINT_BYTES;

/// Why a table was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TableError {
    /// No points.
    Empty,
    /// More than [`MAX_POINTS`] points.
    TooManyPoints,
    /// The x values are not strictly increasing.
    NotIncreasing,
    /// A coefficient lies outside [`K_MIN`] … [`K_MAX`].
    CoefficientOutOfRange,
    /// Unknown version byte in serialised data.
    BadVersion,
    /// Serialised data too short or with a bad count.
    BadLength,
}

impl core::fmt::Display for TableError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            TableError::Empty => "table has no points",
            TableError::TooManyPoints => "table has more than 8 points",
            TableError::NotIncreasing => "table speeds are not strictly increasing",
            TableError::CoefficientOutOfRange => "coefficient outside 0.8 .. 1.2",
            TableError::BadVersion => "unknown table format version",
            TableError::BadLength => "table data has a bad length",
        })
    }
}

/// One point of a coefficient table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TablePoint {
    /// Abscissa: a speed (km/h for k1 and k2, r/min for k3), `U16F16`.
    pub x: U16F16,
    /// The coefficient at `x`.
    pub k: Coefficient,
}

impl TablePoint {
    /// A point.
    #[must_use]
    pub const fn new(x: U16F16, k: Coefficient) -> Self {
        Self { x, k }
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for TablePoint {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(f, "(x={=u32}/65536, k={})", self.x.to_bits(), self.k);
    }
}

/// A validated piecewise-linear coefficient table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CoeffTable {
    points: Vec<TablePoint, MAX_POINTS>,
}

#[cfg(feature = "defmt")]
impl defmt::Format for CoeffTable {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(f, "CoeffTable{}", self.points.as_slice());
    }
}

impl CoeffTable {
    /// Builds and validates a table.
    pub fn new(points: &[TablePoint]) -> Result<Self, TableError> {
        if points.is_empty() {
            return Err(TableError::Empty);
        }
        let mut v: Vec<TablePoint, MAX_POINTS> = Vec::new();
        for p in points {
            push_checked(&mut v, *p)?;
        }
        Ok(Self { points: v })
    }

    /// A constant table (one point at x = 0).
    pub fn constant(k: Coefficient) -> Result<Self, TableError> {
        Self::new(&[TablePoint::new(U16F16::ZERO, k)])
    }

    /// The identity table, k = 1 everywhere.
    #[must_use]
    pub fn one() -> Self {
        let mut points = Vec::new();
        // Cannot fail: capacity 8 > 1.
        let _ = points.push(TablePoint::new(U16F16::ZERO, Coefficient::ONE));
        Self { points }
    }

    /// The points, x ascending.
    #[must_use]
    pub fn points(&self) -> &[TablePoint] {
        &self.points
    }

    /// The coefficient at `x`: linear between points, clamped at the ends.
    #[must_use]
    pub fn eval(&self, x: U16F16) -> Coefficient {
        // The first point above x closes the segment that holds it; before
        // the first point and from the last one on, the end value holds.
        let mut below: Option<&TablePoint> = None;
        for p in &self.points {
            if x < p.x {
                return match below {
                    None => p.k,
                    Some(a) => interpolate(a, p, x).unwrap_or(a.k),
                };
            }
            below = Some(p);
        }
        below.map_or(Coefficient::ONE, |p| p.k)
    }

    /// Serialises into `out`; returns the number of bytes written.
    pub fn write_bytes(&self, out: &mut [u8]) -> Result<usize, TableError> {
        let n = self.points.len();
        let total = n
            .checked_mul(POINT_BYTES)
            .and_then(|b| b.checked_add(2))
            .ok_or(TableError::BadLength)?;
        let out = out.get_mut(..total).ok_or(TableError::BadLength)?;
        let (head, body) = out.split_at_mut(2);
        head.copy_from_slice(&[
            TABLE_FORMAT_VERSION,
            u8::try_from(n).map_err(|_| TableError::BadLength)?,
        ]);
        for (chunk, p) in body.chunks_exact_mut(POINT_BYTES).zip(self.points.iter()) {
            let (xb, kb) = chunk.split_at_mut(4);
            xb.copy_from_slice(&p.x.to_bits().to_le_bytes());
            kb.copy_from_slice(&p.k.to_bits().to_le_bytes());
        }
        Ok(total)
    }

    /// Serialises into a fixed array; returns it with the used length.
    #[must_use]
    pub fn to_array(&self) -> ([u8; TABLE_BYTES_MAX], usize) {
        let mut buf = [0u8; TABLE_BYTES_MAX];
        let len = self.write_bytes(&mut buf).unwrap_or(0);
        (buf, len)
    }

    /// Parses and validates serialised data; returns the table and the
    /// number of bytes consumed.
    pub fn from_bytes(bytes: &[u8]) -> Result<(Self, usize), TableError> {
        let mut table = Self::one();
        let used = table.read_from(bytes)?;
        Ok((table, used))
    }

    /// [`CoeffTable::from_bytes`] into `self`, without a second table on the
    /// stack (the settings are decoded in `init`); returns the number of
    /// bytes consumed. On an error `self` is
    /// the identity table ([`CoeffTable::one`]).
    pub fn read_from(&mut self, bytes: &[u8]) -> Result<usize, TableError> {
        let r = self.parse(bytes);
        if r.is_err() {
            *self = Self::one();
        }
        r
    }

    fn parse(&mut self, bytes: &[u8]) -> Result<usize, TableError> {
        let (&version, rest) = bytes.split_first().ok_or(TableError::BadLength)?;
        if version != TABLE_FORMAT_VERSION {
            return Err(TableError::BadVersion);
        }
        let (&n, rest) = rest.split_first().ok_or(TableError::BadLength)?;
        let n = usize::from(n);
        if n > MAX_POINTS {
            return Err(TableError::TooManyPoints);
        }
        if n == 0 {
            return Err(TableError::Empty);
        }
        let body_len = n.checked_mul(POINT_BYTES).ok_or(TableError::BadLength)?;
        let body = rest.get(..body_len).ok_or(TableError::BadLength)?;
        self.points.clear();
        for chunk in body.chunks_exact(POINT_BYTES) {
            let mut xb = [0u8; 4];
            let mut kb = [0u8; 4];
            let (xs, ks) = chunk.split_at(4);
            xb.copy_from_slice(xs);
            kb.copy_from_slice(ks);
            let p = TablePoint::new(
                U16F16::from_bits(u32::from_le_bytes(xb)),
                Coefficient::from_bits(u32::from_le_bytes(kb)),
            );
            push_checked(&mut self.points, p)?;
        }
        Ok(body_len.saturating_add(2))
    }
}

/// Appends `p` with the checks every table holds to: k within
/// [`K_MIN`]…[`K_MAX`], x strictly increasing, at most [`MAX_POINTS`].
fn push_checked(points: &mut Vec<TablePoint, MAX_POINTS>, p: TablePoint) -> Result<(), TableError> {
    if p.k < K_MIN || p.k > K_MAX {
        return Err(TableError::CoefficientOutOfRange);
    }
    if points.last().is_some_and(|last| p.x <= last.x) {
        return Err(TableError::NotIncreasing);
    }
    points.push(p).map_err(|_| TableError::TooManyPoints)
}

fn interpolate(a: &TablePoint, b: &TablePoint, x: U16F16) -> Result<Coefficient, crate::Error> {
    let span = fx::widen_bits(b.x.saturating_sub(a.x).to_bits(), 16);
    let off = fx::widen_bits(x.saturating_sub(a.x).to_bits(), 16);
    let frac = fx::div(off, span)?;
    let ka = a.k.w();
    let kb = b.k.w();
    let k = if kb >= ka {
        fx::add(ka, fx::mul(kb.saturating_sub(ka), frac)?)?
    } else {
        ka.saturating_sub(fx::mul(ka.saturating_sub(kb), frac)?)
    };
    Coefficient::try_from_w(k)
}

/// Convenience for building x values: `U16F16` from an `f64` (host tools).
#[must_use]
pub fn x_from_f64(v: f64) -> Option<U16F16> {
    U16F16::checked_from_num(v)
}

impl Default for CoeffTable {
    fn default() -> Self {
        Self::one()
    }
}

impl core::error::Error for TableError {}
