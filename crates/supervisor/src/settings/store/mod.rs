//! A two-slot (A/B) settings record store in the MCU's own flash, safe under
//! power loss at any point of a save.
//!
//! The store owns two erase pages: slot 0 at `[base, base + ERASE_SIZE)` and
//! slot 1 at `[base + ERASE_SIZE, base + 2·ERASE_SIZE)`. Each slot holds at
//! most one record, at the start of the page (little endian):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic [`MAGIC`] = `"TPS1"` |
//! | 4 | 4 | sequence, u32; the newer record has the higher sequence, compared with wrap-around |
//! | 8 | 2 | payload length `n`, u16 ([`SETTINGS_BYTES`] = 317 for settings format 7; 311, 283, 252, 250, 243 and 209 for formats 6, 5, 4, 3, 2 and 1) |
//! | 10 | 2 | `!n` (guards the length before the CRC is known) |
//! | 12 | `n` | payload: [`Settings::encode`] |
//! | 12 + n | 0–3 | zero padding to a multiple of 4 |
//! | `c` = 12 + ⌈n⌉₄ | 4 | CRC-32 ([`super::crc`]) of bytes 4 .. `c`: sequence, length, `!n`, payload, padding |
//! | ⌈c + 4⌉_W | max(4, W) | commit word [`COMMIT`] = `"DONE"` (then zeros up to `W`, the flash's `WRITE_SIZE`) |
//!
//! With the STM32F1 (`WRITE_SIZE` = 2) a record of settings format 7 is 340
//! bytes: header at 0, payload at 12, CRC at 332, commit word at 336.
//!
//! A save ([`SettingsStore::save`]) targets the slot that does **not** hold
//! the newest valid record: it erases that page, programs everything up to
//! and including the CRC, reads it back, and programs the commit word last.
//! A slot is valid only if magic, commit word, length and CRC check and the
//! payload decodes; on load the newest valid slot wins. Until the commit word
//! is completely programmed the new record is invalid and the other slot,
//! which the save never touches, still holds the previous settings; once it
//! is, the new record is valid and newer. A power cut therefore leaves either
//! the previous or the new settings, never a mix. `docs/settings-store.md`
//! has the argument, the power-cut test and the wear figures.
//!
//! ```
//! use embedded_storage::nor_flash::{
//!     ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash,
//! };
//! use supervisor::settings::Settings;
//! use supervisor::settings::store::{DefaultsReason, Loaded, SettingsStore};
//! use hmi_proto::screen::Spacing;
//!
//! /// 2 KB of RAM pretending to be two STM32F1 flash pages.
//! struct Ram([u8; 2048]);
//! impl ErrorType for Ram { type Error = NorFlashErrorKind; }
//! impl ReadNorFlash for Ram {
//!     const READ_SIZE: usize = 1;
//!     fn read(&mut self, off: u32, buf: &mut [u8]) -> Result<(), Self::Error> {
//!         let o = off as usize;
//!         let src = self.0.get(o..o + buf.len()).ok_or(NorFlashErrorKind::OutOfBounds)?;
//!         buf.copy_from_slice(src);
//!         Ok(())
//!     }
//!     fn capacity(&self) -> usize { self.0.len() }
//! }
//! impl NorFlash for Ram {
//!     const WRITE_SIZE: usize = 2;
//!     const ERASE_SIZE: usize = 1024;
//!     fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
//!         self.0[from as usize..to as usize].fill(0xFF);
//!         Ok(())
//!     }
//!     fn write(&mut self, off: u32, data: &[u8]) -> Result<(), Self::Error> {
//!         for (d, s) in self.0[off as usize..].iter_mut().zip(data) { *d &= *s; }
//!         Ok(())
//!     }
//! }
//!
//! let mut store = SettingsStore::new(Ram([0xFF; 2048]), 0)?;
//! // First boot: nothing stored, the defaults and the reason for the screen.
//! let first = store.load();
//! assert_eq!(first.defaults_reason(), Some(DefaultsReason::Blank));
//!
//! let mut s = Settings::default();
//! s.spacing = Spacing::new(150).unwrap();
//! assert_eq!(store.save(&s)?, 1); // first record: sequence 1, in slot 0
//! assert_eq!(store.save(&s)?, 1); // unchanged: nothing written
//! assert_eq!(store.load(), Loaded::Saved { settings: s.clone(), sequence: 1 });
//!
//! // The bytes in flash follow the documented layout.
//! let flash = store.into_inner();
//! assert_eq!(&flash.0[0..12], b"TPS1\x01\x00\x00\x00\x3D\x01\xC2\xFE"); // magic, seq 1, n = 317, !n
//! assert_eq!(flash.0[12], 7); // settings format version
//! assert_eq!(&flash.0[336..340], b"DONE");
//! assert_eq!(flash.0[340], 0xFF); // the record ends there
//! # Ok::<(), supervisor::settings::store::StoreError<NorFlashErrorKind>>(())
//! ```

mod outcome;

pub use outcome::{DefaultsReason, LoadStatus, Loaded, SlotStatus, StoreError};

use embedded_storage::nor_flash::NorFlash;

use super::crc::Crc32;
use super::{
    decode_into_unchecked_link, Settings, SettingsError, SETTINGS_BYTES, SETTINGS_FORMAT_VERSION,
    SETTINGS_V1_BYTES, SETTINGS_V2_BYTES, SETTINGS_V3_BYTES, SETTINGS_V4_BYTES, SETTINGS_V5_BYTES,
};

/// Record magic at offset 0: `"TPS1"` (transplanter settings, record format 1).
pub const MAGIC: [u8; 4] = *b"TPS1";
/// Commit word, programmed last: `"DONE"`.
pub const COMMIT: [u8; 4] = *b"DONE";
/// Bytes before the payload: magic, sequence, length, inverted length.
pub const HEADER_BYTES: usize = 12;
/// Largest `READ_SIZE` / `WRITE_SIZE` the store supports; reads go through
/// chunks of this size.
pub const MAX_ACCESS_SIZE: usize = 32;

const CRC_BYTES: usize = 4;
/// Write buffer: header + padded payload + CRC, rounded up for any supported
/// `WRITE_SIZE` (12 + 320 + 4 = 336 → 352 for format 7's 317 bytes).
const BODY_BUF: usize = (HEADER_BYTES + SETTINGS_BYTES.next_multiple_of(4) + CRC_BYTES)
    .next_multiple_of(MAX_ACCESS_SIZE);

/// Where the parts of a record with an `len`-byte payload lie for a flash
/// with `WRITE_SIZE` = `write`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Layout {
    len: usize,
    crc_off: usize,
    commit_off: usize,
    commit_len: usize,
    end: usize,
}

fn layout(len: usize, write: usize) -> Option<Layout> {
    let crc_off = HEADER_BYTES.checked_add(len.checked_next_multiple_of(4)?)?;
    let commit_off = crc_off
        .checked_add(CRC_BYTES)?
        .checked_next_multiple_of(write)?;
    let commit_len = write.max(COMMIT.len());
    let end = commit_off.checked_add(commit_len)?;
    Some(Layout {
        len,
        crc_off,
        commit_off,
        commit_len,
        end,
    })
}

/// `a` is newer than `b` in wrap-around (serial number) order: `a` is 1 to
/// 2³¹ − 1 steps after `b`.
#[must_use]
pub const fn is_newer(a: u32, b: u32) -> bool {
    let d = a.wrapping_sub(b);
    d != 0 && d < 0x8000_0000
}

/// A slot as read, with the data the store needs (`S`: its settings, or
/// `()` when they went to a caller's value).
// `Valid` carries a whole `Settings` (~280 bytes); there is no heap to box
// it in, and at most two `Slot`s live at a time, on the stack (in `save`;
// `load` decodes into one value of its own).
#[allow(clippy::large_enum_variant)]
enum Slot<E, S = Settings> {
    Blank,
    Corrupt,
    Unsupported(u32),
    Valid(u32, S),
    Unreadable(E),
}

impl<E, S> Slot<E, S> {
    fn status(&self) -> SlotStatus {
        match self {
            Self::Blank => SlotStatus::Blank,
            Self::Corrupt => SlotStatus::Corrupt,
            Self::Unsupported(s) => SlotStatus::UnsupportedVersion { sequence: *s },
            Self::Valid(s, _) => SlotStatus::Valid { sequence: *s },
            Self::Unreadable(_) => SlotStatus::FlashError,
        }
    }

    /// Sequence of a complete (CRC-checked) record, valid or not decodable.
    fn intact_sequence(&self) -> Option<u32> {
        match self {
            Self::Unsupported(s) | Self::Valid(s, _) => Some(*s),
            _ => None,
        }
    }
}

/// Reading inside a slot failed: the driver, or an offset outside the page
/// (only from a corrupt length, which the layout check already rejects).
enum ReadFail<E> {
    Flash(E),
    Bounds,
}

impl<E> From<E> for ReadFail<E> {
    fn from(e: E) -> Self {
        Self::Flash(e)
    }
}

/// Which of the two slots; index 0 or 1.
type SlotIndex = usize;

/// The other slot.
const fn other(slot: SlotIndex) -> SlotIndex {
    if slot == 0 {
        1
    } else {
        0
    }
}

/// The two-slot settings store over a NOR flash `F`.
///
/// It keeps no state besides the flash and its geometry: [`load`](Self::load)
/// and [`save`](Self::save) both read the two slots afresh.
#[derive(Debug)]
pub struct SettingsStore<F> {
    flash: F,
    base: u32,
    page: u32,
    layout: Layout,
}

impl<F: NorFlash> SettingsStore<F> {
    /// A store on pages `[base_offset, base_offset + 2·ERASE_SIZE)` of
    /// `flash` (offsets relative to the flash driver's origin). Reads nothing.
    pub fn new(flash: F, base_offset: u32) -> Result<Self, StoreError<F::Error>> {
        let pow2_le = |s: usize| s.is_power_of_two() && s <= MAX_ACCESS_SIZE;
        if !pow2_le(F::READ_SIZE) || !pow2_le(F::WRITE_SIZE) {
            return Err(StoreError::UnsupportedGeometry);
        }
        let layout =
            layout(SETTINGS_BYTES, F::WRITE_SIZE).ok_or(StoreError::UnsupportedGeometry)?;
        if !F::ERASE_SIZE.is_multiple_of(MAX_ACCESS_SIZE)
            || F::ERASE_SIZE < layout.end
            || layout.commit_off > BODY_BUF
        {
            return Err(StoreError::UnsupportedGeometry);
        }
        let page = u32::try_from(F::ERASE_SIZE).map_err(|_| StoreError::UnsupportedGeometry)?;
        if !base_offset.is_multiple_of(page) {
            return Err(StoreError::Misaligned);
        }
        let end = page
            .checked_mul(2)
            .and_then(|two| base_offset.checked_add(two))
            .ok_or(StoreError::OutOfBounds)?;
        if usize::try_from(end).map_or(true, |e| e > flash.capacity()) {
            return Err(StoreError::OutOfBounds);
        }
        Ok(Self {
            flash,
            base: base_offset,
            page,
            layout,
        })
    }

    /// Gives the flash back.
    pub fn into_inner(self) -> F {
        self.flash
    }

    /// The flash, for another store on other pages of it
    /// ([`crate::migrate`]).
    pub fn flash_mut(&mut self) -> &mut F {
        &mut self.flash
    }

    /// Erases both slots, slot 0 first: the store is blank afterwards.
    pub fn erase(&mut self) -> Result<(), StoreError<F::Error>> {
        for slot in [0, 1] {
            let start = self.page_offset(slot).ok_or(StoreError::OutOfBounds)?;
            let end = start
                .checked_add(self.page)
                .ok_or(StoreError::OutOfBounds)?;
            self.flash.erase(start, end)?;
        }
        Ok(())
    }

    /// Reads both slots and returns the newest valid settings, or the
    /// defaults with the reason. Never writes.
    #[inline(never)]
    pub fn load(&mut self) -> Loaded {
        let mut settings = Settings::default();
        match self.load_into(&mut settings) {
            LoadStatus::Saved { sequence } => Loaded::Saved { settings, sequence },
            LoadStatus::Defaults { reason } => Loaded::Defaults { settings, reason },
        }
    }

    /// [`SettingsStore::load`] into the caller's `settings` (the defaults
    /// when no record is valid): no second record on the caller's stack
    /// (the firmware's boot builds the machine from it, on the QEMU
    /// board's few KB of stack). Out of line: its frame and the defaults'
    /// temporaries stay off the caller's.
    #[inline(never)]
    pub fn load_into(&mut self, settings: &mut Settings) -> LoadStatus {
        // Statuses first, then the newest valid slot once more: each decode
        // goes into the one `settings` value (in place, table by table), so
        // no second decoded record is ever on the stack (this runs in
        // `init`). Nothing writes the flash in between.
        let slots = [
            self.scan_into(0, settings).status(),
            self.scan_into(1, settings).status(),
        ];
        let newest = slots
            .iter()
            .enumerate()
            .filter_map(|(i, s)| match s {
                SlotStatus::Valid { sequence } => Some((i, *sequence)),
                _ => None,
            })
            .reduce(|a, b| if is_newer(b.1, a.1) { b } else { a });
        if let Some((slot, _)) = newest {
            if let Slot::Valid(sequence, ()) = self.scan_into(slot, settings) {
                return LoadStatus::Saved { sequence };
            }
        }
        let any = |f: fn(&SlotStatus) -> bool| slots.iter().any(f);
        let reason = if any(|s| matches!(s, SlotStatus::UnsupportedVersion { .. })) {
            DefaultsReason::UnsupportedVersion
        } else if any(|s| matches!(s, SlotStatus::FlashError)) {
            DefaultsReason::FlashError
        } else if any(|s| matches!(s, SlotStatus::Corrupt)) {
            DefaultsReason::Corrupt
        } else {
            DefaultsReason::Blank
        };
        *settings = Settings::default();
        LoadStatus::Defaults { reason }
    }

    /// What each slot holds, slot 0 first (diagnostics and tests).
    pub fn slots(&mut self) -> [SlotStatus; 2] {
        [self.scan(0).status(), self.scan(1).status()]
    }

    /// Persists `settings`; returns the sequence number of the record that
    /// now holds them.
    ///
    /// When the newest valid record already holds these settings, byte for
    /// byte in today's format, nothing is written and its sequence is
    /// returned (a record of an older format is rewritten once in today's). Otherwise the slot that does not
    /// hold the newest valid record is erased and the new record is
    /// programmed there (one erase and `end / WRITE_SIZE` programs: 1 + 132
    /// on the STM32F1), with a sequence one above the newest complete record.
    /// If a slot cannot be read, nothing is written.
    pub fn save(&mut self, settings: &Settings) -> Result<u32, StoreError<F::Error>> {
        // The decision reads the slots through one scratch decode; the
        // records are compared as bytes (the encoding is canonical), so that
        // no two decoded records add up in one frame.
        let (target, sequence) = match self.plan_save(settings)? {
            Ok(unchanged) => return Ok(unchanged),
            Err(plan) => plan,
        };
        self.write_record(target, sequence, settings)?;
        // The record must now scan as valid under its sequence (CRC and
        // commit word read back, the payload decoded and validated) and hold
        // exactly these settings' bytes.
        let mut scratch = Settings::default();
        match self.scan_into(target, &mut scratch) {
            Slot::Valid(seq, ()) if seq == sequence => {}
            Slot::Unreadable(e) => return Err(StoreError::Flash(e)),
            _ => return Err(StoreError::Verify),
        }
        match self.holds(target, settings) {
            Ok(true) => Ok(sequence),
            Ok(false) | Err(ReadFail::Bounds) => Err(StoreError::Verify),
            Err(ReadFail::Flash(e)) => Err(StoreError::Flash(e)),
        }
    }

    /// Where and with which sequence `settings` go: `Ok(Ok(seq))` when
    /// they are already the newest record, `Ok(Err((slot, sequence)))`
    /// otherwise. Out of line, see [`SettingsStore::save`].
    #[inline(never)]
    #[allow(clippy::type_complexity)]
    fn plan_save(
        &mut self,
        settings: &Settings,
    ) -> Result<Result<u32, (SlotIndex, u32)>, StoreError<F::Error>> {
        let mut scratch = Settings::default();
        let slots = [
            self.scan_into(0, &mut scratch),
            self.scan_into(1, &mut scratch),
        ];
        if let Some(i) = slots.iter().position(|s| matches!(s, Slot::Unreadable(_))) {
            let [a, b] = slots;
            if let Slot::Unreadable(e) = if i == 0 { a } else { b } {
                return Err(StoreError::Flash(e));
            }
            return Err(StoreError::Verify);
        }
        let newest = newest_valid(&slots);
        if let Some((slot, seq, ())) = newest {
            match self.holds(slot, settings) {
                Ok(true) => return Ok(Ok(seq)),
                Ok(false) | Err(ReadFail::Bounds) => {}
                Err(ReadFail::Flash(e)) => return Err(StoreError::Flash(e)),
            }
        }
        let target = match newest {
            Some((slot, _, ())) => other(slot),
            None => least_valuable(&slots),
        };
        let sequence = newest_intact(&slots).map_or(1, |s| s.wrapping_add(1));
        Ok(Err((target, sequence)))
    }

    /// Whether a slot's payload is byte for byte `settings`' encoding in
    /// today's format (a record of an older format never is: its first
    /// byte, the format version, differs). The slot's record must be
    /// complete (checked by the caller).
    fn holds(&mut self, slot: SlotIndex, settings: &Settings) -> Result<bool, ReadFail<F::Error>> {
        self.same_as(slot, HEADER_BYTES, &settings.encode())
    }

    /// Whether the bytes at `off` within a slot are `expected`.
    fn same_as(
        &mut self,
        slot: SlotIndex,
        off: usize,
        expected: &[u8],
    ) -> Result<bool, ReadFail<F::Error>> {
        let end = off.checked_add(expected.len()).ok_or(ReadFail::Bounds)?;
        self.walk(slot, off, end, &mut |at, got| {
            expected.get(at..at.wrapping_add(got.len())) == Some(got)
        })
    }

    /// Out of line, see [`SettingsStore::save`].
    #[inline(never)]
    fn write_record(
        &mut self,
        slot: SlotIndex,
        sequence: u32,
        settings: &Settings,
    ) -> Result<(), StoreError<F::Error>> {
        let lay = self.layout;
        let geometry = || StoreError::UnsupportedGeometry;
        let mut body = [0u8; BODY_BUF];
        let len = u16::try_from(lay.len).map_err(|_| geometry())?;
        let header = body.get_mut(..HEADER_BYTES).ok_or_else(geometry)?;
        let [m0, m1, m2, m3] = MAGIC;
        let [s0, s1, s2, s3] = sequence.to_le_bytes();
        let [l0, l1] = len.to_le_bytes();
        let [i0, i1] = (!len).to_le_bytes();
        header.copy_from_slice(&[m0, m1, m2, m3, s0, s1, s2, s3, l0, l1, i0, i1]);
        let payload_end = HEADER_BYTES.checked_add(lay.len).ok_or_else(geometry)?;
        body.get_mut(HEADER_BYTES..payload_end)
            .ok_or_else(geometry)?
            .copy_from_slice(&settings.encode());
        let crc = Crc32::new()
            .update(body.get(4..lay.crc_off).ok_or_else(geometry)?)
            .finish();
        let crc_end = lay.crc_off.checked_add(CRC_BYTES).ok_or_else(geometry)?;
        body.get_mut(lay.crc_off..crc_end)
            .ok_or_else(geometry)?
            .copy_from_slice(&crc.to_le_bytes());
        let body = body.get(..lay.commit_off).ok_or_else(geometry)?;

        let start = self.page_offset(slot).ok_or_else(geometry)?;
        let page_end = start.checked_add(self.page).ok_or_else(geometry)?;
        self.flash.erase(start, page_end)?;
        self.flash.write(start, body)?;
        // Read back before committing: a record that did not program
        // correctly must never become valid.
        match self.same_as(slot, 0, body) {
            Ok(true) => {}
            Ok(false) => return Err(StoreError::Verify),
            Err(ReadFail::Flash(e)) => return Err(StoreError::Flash(e)),
            Err(ReadFail::Bounds) => return Err(geometry()),
        }
        let mut commit = [0u8; MAX_ACCESS_SIZE];
        commit
            .get_mut(..COMMIT.len())
            .ok_or_else(geometry)?
            .copy_from_slice(&COMMIT);
        let commit_at = u32::try_from(lay.commit_off)
            .ok()
            .and_then(|o| start.checked_add(o))
            .ok_or_else(geometry)?;
        self.flash.write(
            commit_at,
            commit.get(..lay.commit_len).ok_or_else(geometry)?,
        )?;
        Ok(())
    }

    /// Flash offset of a slot's page.
    fn page_offset(&self, slot: SlotIndex) -> Option<u32> {
        let k = u32::try_from(slot).ok()?;
        self.base.checked_add(self.page.checked_mul(k)?)
    }

    /// Reads `out.len()` bytes at `off` within a slot, through aligned
    /// [`MAX_ACCESS_SIZE`] chunks (so any supported `READ_SIZE` works).
    fn read(
        &mut self,
        slot: SlotIndex,
        off: usize,
        out: &mut [u8],
    ) -> Result<(), ReadFail<F::Error>> {
        let start = self.page_offset(slot).ok_or(ReadFail::Bounds)?;
        let page = usize::try_from(self.page).map_err(|_| ReadFail::Bounds)?;
        let mut pos = off;
        let mut done = 0usize;
        let mut chunk = [0u8; MAX_ACCESS_SIZE];
        while done < out.len() {
            let within = pos % MAX_ACCESS_SIZE;
            let chunk_start = pos.checked_sub(within).ok_or(ReadFail::Bounds)?;
            let chunk_end = chunk_start
                .checked_add(MAX_ACCESS_SIZE)
                .ok_or(ReadFail::Bounds)?;
            if chunk_end > page {
                return Err(ReadFail::Bounds);
            }
            let at = u32::try_from(chunk_start)
                .ok()
                .and_then(|c| start.checked_add(c))
                .ok_or(ReadFail::Bounds)?;
            self.flash.read(at, &mut chunk)?;
            let avail = chunk.get(within..).ok_or(ReadFail::Bounds)?;
            let dst = out.get_mut(done..).ok_or(ReadFail::Bounds)?;
            let n = avail.len().min(dst.len());
            dst.get_mut(..n)
                .ok_or(ReadFail::Bounds)?
                .copy_from_slice(avail.get(..n).ok_or(ReadFail::Bounds)?);
            done = done.checked_add(n).ok_or(ReadFail::Bounds)?;
            pos = pos.checked_add(n).ok_or(ReadFail::Bounds)?;
        }
        Ok(())
    }

    /// Reads `[from, to)` of a slot in [`MAX_ACCESS_SIZE`] chunks and
    /// hands each to `visit` with its offset, until `visit` says stop
    /// (`false`): one loop for the CRC, the blank check and the byte
    /// comparisons. Out of line, so that its chunk buffer does not add to
    /// `scan`'s frame (it runs in `init`).
    #[inline(never)]
    fn walk(
        &mut self,
        slot: SlotIndex,
        from: usize,
        to: usize,
        visit: &mut dyn FnMut(usize, &[u8]) -> bool,
    ) -> Result<bool, ReadFail<F::Error>> {
        let mut pos = from;
        let mut buf = [0u8; MAX_ACCESS_SIZE];
        while pos < to {
            let n = to.saturating_sub(pos).min(MAX_ACCESS_SIZE);
            let b = buf.get_mut(..n).ok_or(ReadFail::Bounds)?;
            self.read(slot, pos, b)?;
            if !visit(pos.wrapping_sub(from), b) {
                return Ok(false);
            }
            pos = pos.checked_add(n).ok_or(ReadFail::Bounds)?;
        }
        Ok(true)
    }

    /// CRC-32 of `[from, to)` within a slot.
    fn crc(&mut self, slot: SlotIndex, from: usize, to: usize) -> Result<u32, ReadFail<F::Error>> {
        let mut crc = Crc32::new();
        self.walk(slot, from, to, &mut |_, b| {
            crc.feed(b);
            true
        })?;
        Ok(crc.finish())
    }

    /// Whether `[0, to)` of a slot reads erased.
    fn blank(&mut self, slot: SlotIndex, to: usize) -> Result<bool, ReadFail<F::Error>> {
        self.walk(slot, 0, to, &mut |_, b| b.iter().all(|&x| x == 0xFF))
    }

    /// A slot with its settings (for `save`, which compares them).
    fn scan(&mut self, slot: SlotIndex) -> Slot<F::Error> {
        let mut settings = Settings::default();
        match self.scan_into(slot, &mut settings) {
            Slot::Blank => Slot::Blank,
            Slot::Corrupt => Slot::Corrupt,
            Slot::Unsupported(q) => Slot::Unsupported(q),
            Slot::Valid(q, ()) => Slot::Valid(q, settings),
            Slot::Unreadable(e) => Slot::Unreadable(e),
        }
    }

    /// A slot, its settings decoded into `out` (meaningful only when it is
    /// `Valid`).
    fn scan_into(&mut self, slot: SlotIndex, out: &mut Settings) -> Slot<F::Error, ()> {
        match self.try_scan(slot, out) {
            // The drive link block is checked here, the read buffer off
            // the stack (`decode_into_unchecked_link`).
            Ok(Slot::Valid(..)) if out.drive_link.check().is_err() => Slot::Corrupt,
            Ok(s) => s,
            Err(ReadFail::Flash(e)) => Slot::Unreadable(e),
            Err(ReadFail::Bounds) => Slot::Corrupt,
        }
    }

    fn try_scan(
        &mut self,
        slot: SlotIndex,
        out: &mut Settings,
    ) -> Result<Slot<F::Error, ()>, ReadFail<F::Error>> {
        let mut head = [0u8; HEADER_BYTES];
        self.read(slot, 0, &mut head)?;
        let [m0, m1, m2, m3, s0, s1, s2, s3, l0, l1, i0, i1] = head;
        if [m0, m1, m2, m3] != MAGIC {
            let end = self.layout.end;
            return Ok(if self.blank(slot, end)? {
                Slot::Blank
            } else {
                Slot::Corrupt
            });
        }
        let sequence = u32::from_le_bytes([s0, s1, s2, s3]);
        let len = u16::from_le_bytes([l0, l1]);
        if len != !u16::from_le_bytes([i0, i1]) {
            return Ok(Slot::Corrupt);
        }
        let page = usize::try_from(self.page).map_err(|_| ReadFail::Bounds)?;
        let Some(lay) = layout(usize::from(len), F::WRITE_SIZE).filter(|l| l.end <= page) else {
            return Ok(Slot::Corrupt);
        };
        let mut word = [0u8; 4];
        self.read(slot, lay.commit_off, &mut word)?;
        if word != COMMIT {
            return Ok(Slot::Corrupt);
        }
        self.read(slot, lay.crc_off, &mut word)?;
        if self.crc(slot, 4, lay.crc_off)? != u32::from_le_bytes(word) {
            return Ok(Slot::Corrupt);
        }
        // This format, format 5 (before the link's timing), format 4
        // (before the drive link), format 3 (before the work switch),
        // format 2 (before the drive model) or format 1 (before profile
        // B): the decoder reads them all.
        if lay.len == SETTINGS_BYTES
            || lay.len == SETTINGS_V5_BYTES
            || lay.len == SETTINGS_V4_BYTES
            || lay.len == SETTINGS_V3_BYTES
            || lay.len == SETTINGS_V2_BYTES
            || lay.len == SETTINGS_V1_BYTES
        {
            return self.decode_slot(slot, sequence, lay.len, out);
        }
        // Another length: a different format version, or garbage.
        let mut version = [0u8; 1];
        if lay.len == 0 {
            return Ok(Slot::Corrupt);
        }
        self.read(slot, HEADER_BYTES, &mut version)?;
        Ok(if version == [SETTINGS_FORMAT_VERSION] {
            Slot::Corrupt
        } else {
            Slot::Unsupported(sequence)
        })
    }
}

impl<F: NorFlash> SettingsStore<F> {
    /// Reads and decodes the `len` payload bytes of a slot whose record is
    /// complete (magic, commit word, CRC checked) into `out`. Out of line:
    /// its buffer must not add to `try_scan`'s frame.
    #[inline(never)]
    fn decode_slot(
        &mut self,
        slot: SlotIndex,
        sequence: u32,
        len: usize,
        out: &mut Settings,
    ) -> Result<Slot<F::Error, ()>, ReadFail<F::Error>> {
        let mut buf = [0u8; SETTINGS_BYTES];
        let payload = buf.get_mut(..len).ok_or(ReadFail::Bounds)?;
        self.read(slot, HEADER_BYTES, payload)?;
        Ok(match decode_into_unchecked_link(payload, out) {
            Ok(()) => Slot::Valid(sequence, ()),
            Err(SettingsError::UnsupportedVersion(_)) => Slot::Unsupported(sequence),
            Err(_) => Slot::Corrupt,
        })
    }
}

/// The newest valid slot: (index, sequence, settings).
fn newest_valid<E, S>(slots: &[Slot<E, S>; 2]) -> Option<(SlotIndex, u32, &S)> {
    let mut best: Option<(SlotIndex, u32, &S)> = None;
    for (i, s) in slots.iter().enumerate() {
        if let Slot::Valid(seq, settings) = s {
            if best.is_none_or(|(_, b, _)| is_newer(*seq, b)) {
                best = Some((i, *seq, settings));
            }
        }
    }
    best
}

/// The newest sequence among complete records (valid or of another version).
fn newest_intact<E, S>(slots: &[Slot<E, S>; 2]) -> Option<u32> {
    slots
        .iter()
        .filter_map(Slot::intact_sequence)
        .reduce(|a, b| if is_newer(b, a) { b } else { a })
}

/// With no valid record: the slot to overwrite. A blank or corrupt slot
/// rather than a complete record of another version; of two such records,
/// the older.
fn least_valuable<E, S>(slots: &[Slot<E, S>; 2]) -> SlotIndex {
    match (slots[0].intact_sequence(), slots[1].intact_sequence()) {
        (Some(_), None) => 1,
        (Some(a), Some(b)) if is_newer(a, b) => 1,
        _ => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrapping_order() {
        assert!(is_newer(2, 1));
        assert!(!is_newer(1, 2));
        assert!(!is_newer(5, 5));
        // 0 follows u32::MAX.
        assert!(is_newer(0, u32::MAX));
        assert!(!is_newer(u32::MAX, 0));
        // Half the circle apart: 2³¹ steps is "older".
        assert!(!is_newer(0x8000_0000, 0));
        assert!(is_newer(0x7FFF_FFFF, 0));
    }

    #[test]
    fn f1_layout() {
        // 317-byte payload (format 7), WRITE_SIZE 2: CRC at 12 + 320 (the
        // payload padded to a word) = 332, commit at 336, end 340 = 170
        // half-words.
        let l = layout(SETTINGS_BYTES, 2).unwrap();
        assert_eq!(
            (l.crc_off, l.commit_off, l.commit_len, l.end),
            (332, 336, 4, 340)
        );
        // WRITE_SIZE 8: the commit gets its own double word at 336.
        let l = layout(SETTINGS_BYTES, 8).unwrap();
        assert_eq!((l.commit_off, l.commit_len, l.end), (336, 8, 344));
    }

    #[test]
    fn messages_fit_the_screen() {
        for r in [
            DefaultsReason::Blank,
            DefaultsReason::Corrupt,
            DefaultsReason::UnsupportedVersion,
            DefaultsReason::FlashError,
        ] {
            assert!(r.message().len() <= 40 && r.message().is_ascii());
        }
        for e in [
            StoreError::Flash(()),
            StoreError::Misaligned,
            StoreError::Verify,
        ] {
            assert!(e.message().len() <= 40 && e.message().is_ascii());
        }
    }
}
