//! The settings store against a simulated STM32F1 flash that enforces the
//! F1's programming rules and cuts power after any number of operations.
//!
//! The must-show is [`power_cut_at_every_step_recovers_old_or_new`].
// A host test: panics are how it fails.
#![allow(
    clippy::unwrap_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_possible_wrap,
    missing_docs
)]

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use hmi_proto::screen::{Brightness, DrumSpeed, Mode, MotorCoefficient, Spacing};
use kinematics::consts::Gear;
use kinematics::profile_b::ProfileBSettings;
use kinematics::table::{CoeffTable, K_MAX, K_MIN, MAX_POINTS};
use kinematics::travel::Calibration;
use proptest::prelude::*;
use supervisor::planter::ProfileBConfig;
use supervisor::settings::store::{DefaultsReason, Loaded, SettingsStore, SlotStatus, StoreError};
use supervisor::settings::{Profile, Settings, SETTINGS_BYTES};

// ---------------------------------------------------------------------------
// Simulated flash
// ---------------------------------------------------------------------------

const PAGE: usize = 1024;
/// Four pages: the store gets pages 1 and 2; pages 0 and 3 are sentinels it
/// must never touch.
const PAGES: usize = 4;
const BASE: u32 = PAGE as u32;
const SENTINEL: u8 = 0xA5;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SimError {
    NotAligned,
    OutOfBounds,
    /// F1 `PGERR`: programming a half-word that does not read 0xFFFF.
    ProgramError,
    /// The power went off (this operation and every later one fail).
    PowerCut,
    /// Injected read failure.
    ReadError,
}

impl NorFlashError for SimError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            Self::NotAligned => NorFlashErrorKind::NotAligned,
            Self::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// What the operation under way when the power goes does to the flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum EraseTear {
    /// Nothing.
    NoEffect,
    /// The first half of the page erased, the rest old content.
    FirstHalf,
    /// The second half erased, the first half old content (header intact).
    SecondHalf,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ProgramTear {
    /// Nothing.
    NoEffect,
    /// Only some of the bits to be cleared are cleared (`old & (new | 0x55)`).
    SomeBits,
}

/// NOR flash with STM32F1 semantics: `W`-byte program units (2 on the F1)
/// that may be programmed only when they read all `0xFF`, 1 KB pages erased
/// to `0xFF`. Each program unit and each page erase is one operation; after
/// `budget` operations the power is cut: the next operation is torn as
/// configured and fails, and everything fails until [`power_on`](Self::power_on).
#[derive(Debug, Clone)]
struct SimFlash<const W: usize = 2> {
    mem: Vec<u8>,
    ops: usize,
    budget: Option<usize>,
    dead: bool,
    erase_tear: EraseTear,
    program_tear: ProgramTear,
    erases: [u32; PAGES],
    fail_reads: bool,
    /// Completed operations: (`true` = erase, offset).
    log: Vec<(bool, usize)>,
}

impl<const W: usize> SimFlash<W> {
    fn new() -> Self {
        let mut mem = vec![0xFF; PAGE * PAGES];
        mem[..PAGE].fill(SENTINEL);
        mem[PAGE * (PAGES - 1)..].fill(SENTINEL);
        Self {
            mem,
            ops: 0,
            budget: None,
            dead: false,
            erase_tear: EraseTear::FirstHalf,
            program_tear: ProgramTear::SomeBits,
            erases: [0; PAGES],
            fail_reads: false,
            log: Vec::new(),
        }
    }

    /// Cut the power after `k` more operations.
    fn cut_after(&mut self, k: usize, erase_tear: EraseTear, program_tear: ProgramTear) {
        self.budget = Some(k);
        self.erase_tear = erase_tear;
        self.program_tear = program_tear;
    }

    fn power_on(&mut self) {
        self.budget = None;
        self.dead = false;
    }

    /// Spends one operation; `false` = the power goes now (tear this op).
    fn spend(&mut self) -> Result<bool, SimError> {
        if self.dead {
            return Err(SimError::PowerCut);
        }
        if let Some(b) = self.budget.as_mut() {
            if *b == 0 {
                self.dead = true;
                return Ok(false);
            }
            *b -= 1;
        }
        self.ops += 1;
        Ok(true)
    }

    fn store_area(&self) -> &[u8] {
        &self.mem[PAGE..PAGE * 3]
    }

    fn sentinels_intact(&self) -> bool {
        self.mem[..PAGE].iter().all(|&b| b == SENTINEL)
            && self.mem[PAGE * (PAGES - 1)..]
                .iter()
                .all(|&b| b == SENTINEL)
    }
}

impl<const W: usize> ErrorType for SimFlash<W> {
    type Error = SimError;
}

impl<const W: usize> ReadNorFlash for SimFlash<W> {
    const READ_SIZE: usize = W;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), SimError> {
        if self.dead {
            return Err(SimError::PowerCut);
        }
        if self.fail_reads {
            return Err(SimError::ReadError);
        }
        let o = offset as usize;
        if !o.is_multiple_of(W) || !bytes.len().is_multiple_of(W) {
            return Err(SimError::NotAligned);
        }
        let src = self
            .mem
            .get(o..o + bytes.len())
            .ok_or(SimError::OutOfBounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.mem.len()
    }
}

impl<const W: usize> NorFlash for SimFlash<W> {
    const WRITE_SIZE: usize = W;
    const ERASE_SIZE: usize = PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), SimError> {
        let (from, to) = (from as usize, to as usize);
        if !from.is_multiple_of(PAGE) || !to.is_multiple_of(PAGE) {
            return Err(SimError::NotAligned);
        }
        if from > to || to > self.mem.len() {
            return Err(SimError::OutOfBounds);
        }
        for p in (from..to).step_by(PAGE) {
            if !self.spend()? {
                match self.erase_tear {
                    EraseTear::NoEffect => {}
                    EraseTear::FirstHalf => self.mem[p..p + PAGE / 2].fill(0xFF),
                    EraseTear::SecondHalf => self.mem[p + PAGE / 2..p + PAGE].fill(0xFF),
                }
                return Err(SimError::PowerCut);
            }
            self.mem[p..p + PAGE].fill(0xFF);
            self.erases[p / PAGE] += 1;
            self.log.push((true, p));
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), SimError> {
        let o = offset as usize;
        if !o.is_multiple_of(W) || !bytes.len().is_multiple_of(W) {
            return Err(SimError::NotAligned);
        }
        if o + bytes.len() > self.mem.len() {
            return Err(SimError::OutOfBounds);
        }
        for (i, unit) in bytes.chunks_exact(W).enumerate() {
            let at = o + i * W;
            // RM0008: a half-word is programmed only if it reads erased
            // (the hardware's 0x0000 exception is not relied upon).
            if self.mem[at..at + W].iter().any(|&b| b != 0xFF) {
                return Err(SimError::ProgramError);
            }
            if !self.spend()? {
                if self.program_tear == ProgramTear::SomeBits {
                    for (d, s) in self.mem[at..at + W].iter_mut().zip(unit) {
                        *d &= *s | 0x55;
                    }
                }
                return Err(SimError::PowerCut);
            }
            self.mem[at..at + W].copy_from_slice(unit);
            self.log.push((false, at));
        }
        Ok(())
    }
}

fn store<const W: usize>(f: SimFlash<W>) -> SettingsStore<SimFlash<W>> {
    SettingsStore::new(f, BASE).unwrap()
}

/// Boot: a fresh store over (a copy of) the flash, after power-on.
fn boot<const W: usize>(f: &SimFlash<W>) -> Loaded {
    let mut f = f.clone();
    f.power_on();
    store(f).load()
}

// ---------------------------------------------------------------------------
// Settings fixtures
// ---------------------------------------------------------------------------

/// A: the defaults (Speed-Adaptive, 70 mm, Low 1, paper tables).
fn settings_a() -> Settings {
    Settings::default()
}

/// B: every field different from A, including the calibration tables.
fn settings_b() -> Settings {
    Settings {
        mode: Mode::Fixed,
        spacing: Spacing::new(250).unwrap(),
        fixed_drum_speed: DrumSpeed::new(1000).unwrap(),
        motor_coefficient: MotorCoefficient::new(150).unwrap(),
        gear: Gear::High2,
        brightness: Brightness::new(40).unwrap(),
        calibration: Calibration::identity(),
        profile: Profile::SeedlingBelt,
        belt: ProfileBConfig::new(ProfileBSettings {
            plant_spacing: kinematics::units::Metres::from_mm(300),
            ..ProfileBSettings::default()
        })
        .unwrap(),
        drum_encoder_reversed: true,
        drive: supervisor::drive::DriveModel::new(5000, 400, 200).unwrap(),
        placement: supervisor::settings::Placement::SpeedFollowing,
        work_switch_fitted: true,
        first_plant_distance: hmi_proto::screen::FirstPlantDistance::new(250).unwrap(),
        drive_link: supervisor::drive_link::DriveLinkSettings {
            feedback: supervisor::drive_link::FeedbackSource::Driver,
            command: supervisor::drive_link::CommandPath::Modbus,
            kind: supervisor::drive_link::DriverKind::Zlac8015d,
            // A 20:1 gearbox behind the driver's 0.1 r/min (100 000 / 20).
            generic: drive_link::profile::GenericSettings {
                micro_rpm_per_count: 5000,
                ..supervisor::drive_link::GENERIC_DEFAULT
            },
            timing: drive_link::link::LinkTiming {
                reply_timeout_ms: 45,
                retry_gap_ms: 15,
                offline_time_ms: 800,
            },
        },
        ground_wheel: supervisor::settings::wheel::GroundWheelSettings {
            source: hmi_proto::screen::TravelSource::Both,
            counts_per_m_x1000: 3_001_000,
            reversed: true,
        },
    }
}

/// X: an older record, different from both.
fn settings_x() -> Settings {
    Settings {
        spacing: Spacing::new(30).unwrap(),
        gear: Gear::Low3,
        calibration: Calibration::for_gear(Gear::Low3),
        ..Settings::default()
    }
}

/// Independent bitwise CRC-32/ISO-HDLC for hand-built records.
fn crc_ref(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A record built by hand from the layout in docs/settings-store.md
/// (WRITE_SIZE 2): magic, sequence, n, !n, payload, zero pad to 4, CRC of
/// bytes 4..c, "DONE".
fn raw_record(seq: u32, payload: &[u8]) -> Vec<u8> {
    let n = payload.len() as u16;
    let mut r = b"TPS1".to_vec();
    r.extend_from_slice(&seq.to_le_bytes());
    r.extend_from_slice(&n.to_le_bytes());
    r.extend_from_slice(&(!n).to_le_bytes());
    r.extend_from_slice(payload);
    while !r.len().is_multiple_of(4) {
        r.push(0);
    }
    let crc = crc_ref(&r[4..]);
    r.extend_from_slice(&crc.to_le_bytes());
    r.extend_from_slice(b"DONE");
    r
}

/// Puts a hand-built record into slot `slot` (page erased first).
fn put_raw(f: &mut SimFlash, slot: usize, rec: &[u8]) {
    let p = PAGE * (1 + slot);
    f.mem[p..p + PAGE].fill(0xFF);
    f.mem[p..p + rec.len()].copy_from_slice(rec);
}

fn slot_bytes(f: &SimFlash, slot: usize) -> &[u8] {
    &f.mem[PAGE * (1 + slot)..PAGE * (2 + slot)]
}

// ---------------------------------------------------------------------------
// The must-show: power cut at every operation of a save
// ---------------------------------------------------------------------------

/// For a save of `new` over flash `before` (whose newest valid record holds
/// `old`), cut the power after every k = 0 … total operations and boot.
/// Returns the operation count of the save.
fn sweep<const W: usize>(before: &SimFlash<W>, old: &Settings, new: &Settings) -> usize {
    let Loaded::Saved {
        settings,
        sequence: old_seq,
    } = boot(before)
    else {
        panic!("fixture must hold a record");
    };
    assert_eq!(&settings, old);

    // The uninterrupted save: its operation count and resulting sequence.
    let mut st = store(before.clone());
    let new_seq = st.save(new).unwrap();
    assert_eq!(new_seq, old_seq.wrapping_add(1));
    let done = st.into_inner();
    let total = done.ops - before.ops;
    assert!(done.sentinels_intact());

    for erase_tear in [
        EraseTear::NoEffect,
        EraseTear::FirstHalf,
        EraseTear::SecondHalf,
    ] {
        for program_tear in [ProgramTear::NoEffect, ProgramTear::SomeBits] {
            for k in 0..=total {
                let mut f = before.clone();
                f.cut_after(k, erase_tear, program_tear);
                let mut st = store(f);
                let r = st.save(new);
                let f = st.into_inner();
                let ctx = format!("cut after {k}/{total} ops, {erase_tear:?}, {program_tear:?}");
                assert!(f.sentinels_intact(), "{ctx}");
                // Boot after the cut: exactly old (until the last half-word of
                // the commit word is in) or exactly new — never a mix (the
                // whole Settings is compared), never defaults.
                match boot(&f) {
                    Loaded::Saved { settings, sequence } if k < total => {
                        assert!(r.is_err(), "{ctx}");
                        assert_eq!(settings, *old, "{ctx}");
                        assert_eq!(sequence, old_seq, "{ctx}");
                    }
                    Loaded::Saved { settings, sequence } => {
                        assert_eq!(r, Ok(new_seq), "{ctx}");
                        assert_eq!(settings, *new, "{ctx}");
                        assert_eq!(sequence, new_seq, "{ctx}");
                    }
                    Loaded::Defaults { reason, .. } => panic!("{ctx}: defaults ({reason:?})"),
                }
                // The next save after the power returns completes, whatever
                // the cut left behind.
                let mut f = f;
                f.power_on();
                let mut st = store(f);
                assert_eq!(st.save(new), Ok(new_seq), "{ctx}: retry");
                assert_eq!(
                    st.load(),
                    Loaded::Saved {
                        settings: new.clone(),
                        sequence: new_seq
                    },
                    "{ctx}: after retry"
                );
            }
        }
    }
    total
}

#[test]
fn power_cut_at_every_step_recovers_old_or_new() {
    let (a, b, x) = (settings_a(), settings_b(), settings_x());

    // 1. A alone in slot 0 (sequence 1); B goes to the blank slot 1.
    let mut st = store(SimFlash::<2>::new());
    st.save(&a).unwrap();
    let only_a = st.into_inner();
    let total = sweep(&only_a, &a, &b);
    // One erase + 340 bytes / 2 = 170 half-word programs (317-byte payload,
    // format 7: header 12, payload 317 + 3 padding, CRC 4, commit 4).
    assert_eq!(total, 171);

    // 2. X (seq 1) in slot 0, A (seq 2) in slot 1; B overwrites X's slot.
    //    X must never come back, whatever the torn erase leaves of it.
    let mut st = store(SimFlash::<2>::new());
    st.save(&x).unwrap();
    st.save(&a).unwrap();
    let x_then_a = st.into_inner();
    assert_eq!(sweep(&x_then_a, &a, &b), 171);

    // 3. Sequence wrap: X at u32::MAX − 1 in slot 0, A at u32::MAX in slot 1;
    //    B gets sequence 0 in slot 0.
    let mut f = SimFlash::new();
    put_raw(&mut f, 0, &raw_record(u32::MAX - 1, &x.encode()));
    put_raw(&mut f, 1, &raw_record(u32::MAX, &a.encode()));
    assert_eq!(sweep(&f, &a, &b), 171);
}

#[test]
fn power_cut_with_wider_program_units() {
    // A flash with 8-byte program units (and 8-byte reads): the commit word
    // takes its own unit at 336, the record ends at 344 = 43 units.
    let (a, b) = (settings_a(), settings_b());
    let mut st = store(SimFlash::<8>::new());
    st.save(&a).unwrap();
    let f = st.into_inner();
    assert_eq!(sweep(&f, &a, &b), 1 + 43);
    // And 1-byte units: 340 programs.
    let mut st = store(SimFlash::<1>::new());
    st.save(&a).unwrap();
    let f = st.into_inner();
    assert_eq!(sweep(&f, &a, &b), 1 + 340);
}

#[test]
fn interrupted_first_save_reports_corrupt_not_silent() {
    // Cut half-way through programming the very first record.
    let mut f = SimFlash::<2>::new();
    f.cut_after(50, EraseTear::FirstHalf, ProgramTear::SomeBits);
    let mut st = store(f);
    assert_eq!(
        st.save(&settings_b()),
        Err(StoreError::Flash(SimError::PowerCut))
    );
    assert_eq!(
        boot(&st.into_inner()),
        Loaded::Defaults {
            settings: Settings::default(),
            reason: DefaultsReason::Corrupt
        }
    );
}

// ---------------------------------------------------------------------------
// Ordinary behaviour
// ---------------------------------------------------------------------------

#[test]
fn first_boot_is_blank() {
    let mut st = store(SimFlash::<2>::new());
    let l = st.load();
    assert_eq!(
        l,
        Loaded::Defaults {
            settings: Settings::default(),
            reason: DefaultsReason::Blank
        }
    );
    assert_eq!(
        l.defaults_reason().unwrap().message(),
        "No saved settings: defaults"
    );
    assert_eq!(st.slots(), [SlotStatus::Blank, SlotStatus::Blank]);
    // Loading never writes.
    assert_eq!(st.into_inner().ops, 0);
}

#[test]
fn record_bytes_follow_the_documented_layout() {
    let mut st = store(SimFlash::<2>::new());
    assert_eq!(st.save(&settings_b()), Ok(1));
    let f = st.into_inner();
    let rec = raw_record(1, &settings_b().encode());
    assert_eq!(rec.len(), 340);
    let slot0 = slot_bytes(&f, 0);
    assert_eq!(&slot0[..340], &rec[..]);
    assert!(slot0[340..].iter().all(|&b| b == 0xFF));
    assert!(slot_bytes(&f, 1).iter().all(|&b| b == 0xFF));
    // Header bytes spelled out: "TPS1", seq 1, n = 317 = 0x013D, !n = 0xFEC2.
    assert_eq!(
        &slot0[..12],
        &[b'T', b'P', b'S', b'1', 1, 0, 0, 0, 0x3D, 0x01, 0xC2, 0xFE]
    );
    assert_eq!(SETTINGS_BYTES, 317);
}

#[test]
fn one_save_costs_one_erase_and_170_programs() {
    let mut st = store(SimFlash::<2>::new());
    st.save(&settings_a()).unwrap();
    let f = st.into_inner();
    // 1 erase + 340 / 2 half-words (record layout: end of commit word at 340).
    assert_eq!(f.ops, 171);
    assert_eq!(f.erases, [0, 1, 0, 0]);
}

#[test]
fn erase_first_then_body_in_order_then_commit_word_last() {
    let mut st = store(SimFlash::<2>::new());
    st.save(&settings_a()).unwrap();
    st.save(&settings_b()).unwrap(); // into slot 1 at offset 2048
    let log = st.into_inner().log;
    let second = &log[171..];
    assert_eq!(second[0], (true, 2 * PAGE));
    // Half-words 0, 2, …, 334 of the page: header, payload, padding, CRC.
    let body: Vec<_> = (0..168).map(|i| (false, 2 * PAGE + 2 * i)).collect();
    assert_eq!(&second[1..169], &body[..]);
    // Then, and only then, the commit word "DONE" at 336 and 338.
    assert_eq!(
        &second[169..],
        &[(false, 2 * PAGE + 336), (false, 2 * PAGE + 338)]
    );
}

#[test]
fn a_record_without_its_commit_word_is_ignored() {
    // Everything right (magic, sequence 9, length, CRC) except the commit
    // word, which reads erased, as after a cut just before it.
    let mut rec = raw_record(9, &settings_b().encode());
    let n = rec.len();
    rec[n - 4..].fill(0xFF);
    let mut f = SimFlash::new();
    put_raw(&mut f, 0, &raw_record(3, &settings_a().encode()));
    put_raw(&mut f, 1, &rec);
    assert_eq!(
        boot(&f),
        Loaded::Saved {
            settings: settings_a(),
            sequence: 3
        }
    );
    // Half a commit word is no commit either.
    rec[n - 2..].copy_from_slice(b"NE");
    rec[n - 4..n - 2].fill(0xFF);
    put_raw(&mut f, 1, &rec);
    rec[n - 4..n - 2].copy_from_slice(b"DO");
    rec[n - 2..].fill(0xFF);
    let mut g = f.clone();
    put_raw(&mut g, 1, &rec);
    for f in [f, g] {
        assert_eq!(store(f).slots()[1], SlotStatus::Corrupt);
    }
}

#[test]
fn unchanged_settings_are_not_written() {
    let mut st = store(SimFlash::<2>::new());
    assert_eq!(st.save(&settings_a()), Ok(1));
    assert_eq!(st.save(&settings_b()), Ok(2));
    let ops = st.into_inner();
    let before = ops.ops;
    let mut st = store(ops);
    assert_eq!(st.save(&settings_b()), Ok(2));
    assert_eq!(st.into_inner().ops, before);
}

#[test]
fn saves_alternate_slots_and_sequence_increases() {
    let mut st = store(SimFlash::<2>::new());
    let mut s = settings_a();
    for i in 1..=10u32 {
        s.spacing = Spacing::new(30 + i as i32).unwrap();
        assert_eq!(st.save(&s), Ok(i));
        let slots = st.slots();
        // Odd sequences in slot 0, even in slot 1; the other slot keeps i − 1.
        let (new, old) = if i % 2 == 1 { (0, 1) } else { (1, 0) };
        assert_eq!(slots[new], SlotStatus::Valid { sequence: i });
        if i > 1 {
            assert_eq!(slots[old], SlotStatus::Valid { sequence: i - 1 });
        } else {
            assert_eq!(slots[old], SlotStatus::Blank);
        }
        assert_eq!(
            st.load(),
            Loaded::Saved {
                settings: s.clone(),
                sequence: i
            }
        );
    }
    // Wear is shared: 5 erases per page.
    assert_eq!(st.into_inner().erases, [0, 5, 5, 0]);
}

#[test]
fn any_flipped_bit_in_the_newest_record_falls_back_to_the_older() {
    let mut st = store(SimFlash::<2>::new());
    st.save(&settings_a()).unwrap(); // slot 0, seq 1
    st.save(&settings_b()).unwrap(); // slot 1, seq 2
    let good = st.into_inner();
    // Every bit of every byte of the 272-byte record: magic, sequence,
    // length, !length, payload, padding, CRC, commit word.
    for byte in 0..272 {
        for bit in 0..8 {
            let mut f = good.clone();
            f.mem[2 * PAGE + byte] ^= 1 << bit;
            assert_eq!(
                boot(&f),
                Loaded::Saved {
                    settings: settings_a(),
                    sequence: 1
                },
                "byte {byte} bit {bit}"
            );
        }
    }
    // A flipped bit in the older record does not matter.
    let mut f = good.clone();
    f.mem[PAGE + 100] ^= 0x10;
    assert_eq!(
        boot(&f),
        Loaded::Saved {
            settings: settings_b(),
            sequence: 2
        }
    );
    // Both damaged: defaults, and the reason says so.
    let mut f = good;
    f.mem[PAGE + 100] ^= 0x10;
    f.mem[2 * PAGE + 100] ^= 0x10;
    let l = boot(&f);
    assert_eq!(l.defaults_reason(), Some(DefaultsReason::Corrupt));
    assert_eq!(l.settings(), &Settings::default());
    // A save from there writes sequence 1 into slot 0 and recovers.
    let mut st = store(f);
    assert_eq!(st.save(&settings_x()), Ok(1));
    assert_eq!(st.slots()[0], SlotStatus::Valid { sequence: 1 });
}

#[test]
fn a_record_with_valid_crc_but_invalid_field_is_corrupt() {
    // CRC over a payload whose gear byte is 9: framing fine, decode fails.
    let mut payload = settings_a().encode();
    payload[8] = 9;
    let mut f = SimFlash::new();
    put_raw(&mut f, 0, &raw_record(1, &payload));
    assert_eq!(boot(&f).defaults_reason(), Some(DefaultsReason::Corrupt));
}

/// A record whose drive link block parses but does not pass its checks
/// (the store checks it after the decode, `decode_into_unchecked_link`):
/// a ZLAC8015D behind 59:1 needs 2638 motor r/min, beyond its 1000. It
/// is corrupt: the older valid record (or the defaults) is used.
#[test]
fn a_record_whose_drive_link_fails_its_checks_is_corrupt() {
    let mut bad = settings_b();
    bad.drive_link.generic.micro_rpm_per_count = 1695;
    assert!(bad.drive_link.build().is_err());
    let mut f = SimFlash::new();
    put_raw(&mut f, 0, &raw_record(4, &settings_a().encode()));
    put_raw(&mut f, 1, &raw_record(5, &bad.encode()));
    assert_eq!(
        boot(&f),
        Loaded::Saved {
            settings: settings_a(),
            sequence: 4
        }
    );
    let mut st = store(f);
    assert_eq!(
        st.slots(),
        [SlotStatus::Valid { sequence: 4 }, SlotStatus::Corrupt]
    );
}

#[test]
fn a_record_written_before_profile_b_still_loads() {
    // Format 1: the first 209 bytes of today's payload, version byte 1
    // (docs of supervisor::settings). It loads as profile A with profile B's
    // defaults (and format 2's defaults: encoder forward, the default
    // drive), and the next save writes format 4 into the other slot.
    let b = settings_b();
    let mut v1 = b.encode()[..209].to_vec();
    v1[0] = 1;
    let mut f = SimFlash::new();
    put_raw(&mut f, 0, &raw_record(8, &v1));
    let expected = Settings {
        profile: Profile::DrumBelt,
        belt: ProfileBConfig::default(),
        drum_encoder_reversed: false,
        drive: supervisor::drive::DriveModel::DEFAULT,
        placement: supervisor::settings::Placement::DistanceLocked,
        work_switch_fitted: false,
        first_plant_distance: hmi_proto::screen::FirstPlantDistance::DEFAULT,
        drive_link: Default::default(),
        ground_wheel: Default::default(),
        ..b.clone()
    };
    assert_eq!(
        boot(&f),
        Loaded::Saved {
            settings: expected.clone(),
            sequence: 8
        }
    );
    let mut st = store(f);
    assert_eq!(st.save(&b), Ok(9));
    assert_eq!(
        boot(&st.into_inner()),
        Loaded::Saved {
            settings: b,
            sequence: 9
        }
    );
}

#[test]
fn a_record_written_before_the_work_switch_still_loads() {
    // Format 3: the first 250 bytes of today's payload, version byte 3,
    // flags bits 1 and 2 (unknown then) clear. It loads distance-locked,
    // without a work switch and with the default first-plant distance; the
    // next save writes format 4.
    let b = settings_b();
    let mut v3 = b.encode()[..250].to_vec();
    v3[0] = 3;
    v3[243] &= 1;
    let mut f = SimFlash::new();
    put_raw(&mut f, 0, &raw_record(5, &v3));
    let expected = Settings {
        placement: supervisor::settings::Placement::DistanceLocked,
        work_switch_fitted: false,
        first_plant_distance: hmi_proto::screen::FirstPlantDistance::DEFAULT,
        drive_link: Default::default(),
        ground_wheel: Default::default(),
        ..b.clone()
    };
    assert_eq!(
        boot(&f),
        Loaded::Saved {
            settings: expected,
            sequence: 5
        }
    );
    let mut st = store(f);
    assert_eq!(st.save(&b), Ok(6));
    assert_eq!(
        boot(&st.into_inner()),
        Loaded::Saved {
            settings: b,
            sequence: 6
        }
    );
}

#[test]
fn a_record_written_before_the_drive_link_still_loads() {
    // Format 4: the first 252 bytes of today's payload, version byte 4. It
    // loads with today's behaviour (encoder feedback, PWM, no driver); the
    // next save writes format 7.
    let b = settings_b();
    let mut v4 = b.encode()[..252].to_vec();
    v4[0] = 4;
    let mut f = SimFlash::new();
    put_raw(&mut f, 0, &raw_record(3, &v4));
    let expected = Settings {
        drive_link: Default::default(),
        ground_wheel: Default::default(),
        ..b.clone()
    };
    assert_ne!(expected, b);
    assert_eq!(
        boot(&f),
        Loaded::Saved {
            settings: expected,
            sequence: 3
        }
    );
    let mut st = store(f);
    assert_eq!(st.save(&b), Ok(4));
    assert_eq!(
        boot(&st.into_inner()),
        Loaded::Saved {
            settings: b,
            sequence: 4
        }
    );
}

#[test]
fn a_record_written_before_the_link_timing_still_loads() {
    // Format 5: the first 283 bytes of a payload whose link block holds
    // only what format 5 had (a generic driver: command in the feedback's
    // scale, none of the optional registers, the default timing), version
    // byte 5. It loads as saved; the next save writes format 7, and a
    // changed setting is saved with it.
    let mut b = settings_b();
    b.drive_link.kind = supervisor::drive_link::DriverKind::Generic;
    b.drive_link.timing = drive_link::link::LinkTiming::DEFAULT;
    b.drive_link.generic = drive_link::profile::GenericSettings {
        speed_command: Some(0x2088),
        command_scale: 5000,
        control: None,
        velocity_mode: None,
        offline_register: None,
        resolution_register: None,
        max_speed_register: None,
        ..b.drive_link.generic
    };
    b.ground_wheel = Default::default();
    let mut v5 = b.encode()[..283].to_vec();
    v5[0] = 5;
    let mut f = SimFlash::new();
    put_raw(&mut f, 0, &raw_record(7, &v5));
    assert_eq!(
        boot(&f),
        Loaded::Saved {
            settings: b.clone(),
            sequence: 7
        }
    );
    let mut st = store(f);
    b.drive_link.timing.reply_timeout_ms = 50;
    assert_eq!(st.save(&b), Ok(8));
    let f = st.into_inner();
    assert_eq!(slot_bytes(&f, 1)[12], 7, "format byte of the new record");
    assert_eq!(
        boot(&f),
        Loaded::Saved {
            settings: b,
            sequence: 8
        }
    );
}

#[test]
fn saving_what_an_older_record_decodes_to_upgrades_it() {
    // Records are compared as bytes in today's format: a format-4 record
    // that decodes to exactly the settings being saved is still rewritten
    // once as format 7 (sequence 4, version byte 7 in the new slot), and a
    // second save of the same settings then writes nothing.
    let b = settings_b();
    let mut v4 = b.encode()[..252].to_vec();
    v4[0] = 4;
    let mut f = SimFlash::new();
    put_raw(&mut f, 0, &raw_record(3, &v4));
    let Loaded::Saved { settings: old, .. } = boot(&f) else {
        panic!("the format-4 record must load");
    };
    let mut st = store(f);
    assert_eq!(st.save(&old), Ok(4));
    assert_eq!(st.save(&old), Ok(4));
    let f = st.into_inner();
    assert_eq!(slot_bytes(&f, 1)[12], 7, "format byte of the new record");
    // One erase, of slot 1 (pages: sentinel, slot 0, slot 1, sentinel).
    assert_eq!(f.erases, [0, 0, 1, 0]);
}

#[test]
fn a_record_written_before_the_drive_model_still_loads() {
    // Format 2: the first 243 bytes of today's payload, version byte 2
    // (docs of supervisor::settings). It loads with the encoder forward and
    // the default drive model, and the next save writes format 4.
    // settings_b: encoder reversed, a drive model other than the default.
    let b = settings_b();
    let mut v2 = b.encode()[..243].to_vec();
    v2[0] = 2;
    let mut f = SimFlash::new();
    put_raw(&mut f, 1, &raw_record(11, &v2));
    let expected = Settings {
        drum_encoder_reversed: false,
        drive: supervisor::drive::DriveModel::DEFAULT,
        placement: supervisor::settings::Placement::DistanceLocked,
        work_switch_fitted: false,
        first_plant_distance: hmi_proto::screen::FirstPlantDistance::DEFAULT,
        drive_link: Default::default(),
        ground_wheel: Default::default(),
        ..b.clone()
    };
    assert_eq!(
        boot(&f),
        Loaded::Saved {
            settings: expected,
            sequence: 11
        }
    );
    let mut st = store(f);
    assert_eq!(st.save(&b), Ok(12));
    assert_eq!(
        boot(&st.into_inner()),
        Loaded::Saved {
            settings: b,
            sequence: 12
        }
    );
}

#[test]
fn unsupported_version_falls_back_or_is_reported() {
    let a = settings_a();
    // A record of a future format 8 (payload version byte 8, longer payload).
    let mut v2 = vec![8u8; 340];
    v2[1] = 8;
    // Alone: defaults, reason UnsupportedVersion.
    let mut f = SimFlash::new();
    put_raw(&mut f, 1, &raw_record(40, &v2));
    let l = boot(&f);
    assert_eq!(
        l.defaults_reason(),
        Some(DefaultsReason::UnsupportedVersion)
    );
    assert_eq!(
        l.defaults_reason().unwrap().message(),
        "Settings from newer firmware: defaults"
    );
    // Saving then writes the other slot with a sequence above the v2 record,
    // and keeps the v2 record.
    let mut st = store(f);
    assert_eq!(st.save(&a), Ok(41));
    assert_eq!(
        st.slots(),
        [
            SlotStatus::Valid { sequence: 41 },
            SlotStatus::UnsupportedVersion { sequence: 40 }
        ]
    );

    // Newer than a valid current record: the valid one is used.
    let mut f = SimFlash::new();
    put_raw(&mut f, 0, &raw_record(5, &a.encode()));
    let mut same_len = settings_b().encode();
    same_len[0] = 8;
    put_raw(&mut f, 1, &raw_record(6, &same_len));
    assert_eq!(
        boot(&f),
        Loaded::Saved {
            settings: a.clone(),
            sequence: 5
        }
    );
    // The next save overwrites the v7 record (slot 1) with sequence 7.
    let mut st = store(f);
    assert_eq!(st.save(&settings_b()), Ok(7));
    assert_eq!(
        st.slots(),
        [
            SlotStatus::Valid { sequence: 5 },
            SlotStatus::Valid { sequence: 7 }
        ]
    );
}

#[test]
fn read_errors_give_defaults_and_block_saves() {
    let mut st = store(SimFlash::<2>::new());
    st.save(&settings_b()).unwrap();
    let mut f = st.into_inner();
    f.fail_reads = true;
    let ops = f.ops;
    let mut st = store(f);
    assert_eq!(
        st.load().defaults_reason(),
        Some(DefaultsReason::FlashError)
    );
    let e = st.save(&settings_a()).unwrap_err();
    assert_eq!(e, StoreError::Flash(SimError::ReadError));
    assert_eq!(
        e.to_string(),
        "flash error: An implementation specific error occurred"
    );
    assert_eq!(e.message(), "Save failed: flash error");
    assert_eq!(st.into_inner().ops, ops, "nothing written");
}

#[test]
fn new_checks_the_geometry() {
    let f = SimFlash::<2>::new();
    assert_eq!(
        SettingsStore::new(f.clone(), 100).err(),
        Some(StoreError::Misaligned)
    );
    // Pages 3 and 4 of a 4-page flash.
    assert_eq!(
        SettingsStore::new(f.clone(), 3 * PAGE as u32).err(),
        Some(StoreError::OutOfBounds)
    );
    assert_eq!(
        SettingsStore::new(f.clone(), u32::MAX - 1023).err(),
        Some(StoreError::OutOfBounds)
    );
    assert!(SettingsStore::new(f.clone(), 2 * PAGE as u32).is_ok());
    assert!(SettingsStore::new(f, 0).is_ok());
    assert_eq!(
        StoreError::<SimError>::Misaligned.to_string(),
        "store base is not page aligned"
    );
}

#[test]
fn sim_flash_enforces_f1_rules() {
    let mut f = SimFlash::<2>::new();
    // Program onto an already programmed half-word: PGERR.
    f.write(BASE, &[0x12, 0x34]).unwrap();
    assert_eq!(f.write(BASE, &[0x00, 0x00]), Err(SimError::ProgramError));
    // Alignment.
    assert_eq!(f.write(BASE + 1, &[0, 0]), Err(SimError::NotAligned));
    assert_eq!(f.write(BASE + 2, &[0]), Err(SimError::NotAligned));
    assert_eq!(f.erase(BASE + 2, BASE + 1026), Err(SimError::NotAligned));
    // Erase → 0xFF.
    f.erase(BASE, BASE + PAGE as u32).unwrap();
    assert!(f.mem[PAGE..2 * PAGE].iter().all(|&b| b == 0xFF));
    // A cut erase leaves half the page old.
    f.mem[PAGE..2 * PAGE].fill(0);
    f.cut_after(0, EraseTear::FirstHalf, ProgramTear::NoEffect);
    assert_eq!(f.erase(BASE, BASE + PAGE as u32), Err(SimError::PowerCut));
    assert!(f.mem[PAGE..PAGE + 512].iter().all(|&b| b == 0xFF));
    assert!(f.mem[PAGE + 512..2 * PAGE].iter().all(|&b| b == 0));
    // Dead until power-on.
    let mut buf = [0u8; 2];
    assert_eq!(f.read(BASE, &mut buf), Err(SimError::PowerCut));
    f.power_on();
    assert!(f.read(BASE, &mut buf).is_ok());
    assert_eq!(f.store_area().len(), 2 * PAGE);
}

// ---------------------------------------------------------------------------
// Properties
// ---------------------------------------------------------------------------

fn table() -> impl Strategy<Value = CoeffTable> {
    (
        proptest::collection::btree_set(any::<u32>(), 1..=MAX_POINTS),
        proptest::collection::vec(K_MIN.to_bits()..=K_MAX.to_bits(), MAX_POINTS),
    )
        .prop_map(|(xs, ks)| {
            let mut b = vec![1u8, xs.len() as u8];
            for (x, k) in xs.iter().zip(ks.iter()) {
                b.extend_from_slice(&x.to_le_bytes());
                b.extend_from_slice(&k.to_le_bytes());
            }
            CoeffTable::from_bytes(&b).unwrap().0
        })
}

fn settings() -> impl Strategy<Value = Settings> {
    (
        any::<bool>(),
        Spacing::MIN..=Spacing::MAX,
        DrumSpeed::MIN..=DrumSpeed::MAX,
        MotorCoefficient::MIN..=MotorCoefficient::MAX,
        0usize..6,
        Brightness::MIN..=Brightness::MAX,
        (table(), table(), table()),
        (any::<bool>(), 110u32..=990),
        (any::<bool>(), 1000u16..=9000, 10u16..=5000, 0u16..=2000),
        (any::<bool>(), 0u16..=1000),
    )
        .prop_map(
            |(
                fixed,
                sp,
                ds,
                mc,
                g,
                br,
                (k1, k2, k3),
                (b, x_mm),
                (rev, n, tau, dead),
                (work, first),
            )| Settings {
                mode: if fixed {
                    Mode::Fixed
                } else {
                    Mode::SpeedAdaptive
                },
                spacing: Spacing::new(i32::from(sp)).unwrap(),
                fixed_drum_speed: DrumSpeed::new(i32::from(ds)).unwrap(),
                motor_coefficient: MotorCoefficient::new(i32::from(mc)).unwrap(),
                gear: Gear::ALL[g],
                brightness: Brightness::new(i32::from(br)).unwrap(),
                calibration: Calibration { k1, k2, k3 },
                profile: if b {
                    Profile::SeedlingBelt
                } else {
                    Profile::DrumBelt
                },
                belt: ProfileBConfig::new(ProfileBSettings {
                    plant_spacing: kinematics::units::Metres::from_mm(x_mm),
                    ..ProfileBSettings::default()
                })
                .unwrap(),
                drum_encoder_reversed: rev,
                drive: supervisor::drive::DriveModel::new(n, tau, dead).unwrap(),
                placement: if rev {
                    supervisor::settings::Placement::SpeedFollowing
                } else {
                    supervisor::settings::Placement::DistanceLocked
                },
                work_switch_fitted: work,
                first_plant_distance: hmi_proto::screen::FirstPlantDistance::new(i32::from(first))
                    .unwrap(),
                drive_link: Default::default(),
                ground_wheel: supervisor::settings::wheel::GroundWheelSettings {
                    source: if work {
                        hmi_proto::screen::TravelSource::GroundWheel
                    } else {
                        hmi_proto::screen::TravelSource::HallGear
                    },
                    counts_per_m_x1000: 2_500_000 + u32::from(sp) * 1000,
                    reversed: rev,
                },
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn saves_load_back_the_last(list in proptest::collection::vec(settings(), 1..6)) {
        let mut st = store(SimFlash::<2>::new());
        let mut seq = 0u32;
        let mut last: Option<Settings> = None;
        for s in &list {
            if last.as_ref() != Some(s) {
                seq += 1;
            }
            prop_assert_eq!(st.save(s), Ok(seq));
            last = Some(s.clone());
        }
        let f = st.into_inner();
        prop_assert!(f.sentinels_intact());
        prop_assert_eq!(
            boot(&f),
            Loaded::Saved { settings: list.last().unwrap().clone(), sequence: seq }
        );
    }

    #[test]
    fn garbage_in_flash_never_panics_nor_invents_settings(
        a in settings(),
        b in settings(),
        hits in proptest::collection::vec((0usize..2 * PAGE, any::<u8>()), 0..40),
    ) {
        let mut st = store(SimFlash::<2>::new());
        st.save(&a).unwrap();
        st.save(&b).unwrap();
        let mut f = st.into_inner();
        for (at, v) in hits {
            f.mem[PAGE + at] = v;
        }
        // Either one of the saved settings or defaults with a reason.
        match boot(&f) {
            Loaded::Saved { settings, sequence } => {
                prop_assert!(
                    (settings == a && sequence == 1) || (settings == b && sequence == 2)
                );
            }
            Loaded::Defaults { settings, reason } => {
                prop_assert_eq!(settings, Settings::default());
                prop_assert!(reason == DefaultsReason::Corrupt || reason == DefaultsReason::Blank);
            }
        }
        // And a save always succeeds over whatever is there.
        f.power_on();
        let mut st = store(f);
        let seq = st.save(&a).unwrap();
        prop_assert_eq!(st.load(), Loaded::Saved { settings: a, sequence: seq });
    }

    #[test]
    fn random_pages_never_panic(
        page0 in proptest::collection::vec(any::<u8>(), PAGE),
        head in proptest::collection::vec(any::<u8>(), 12),
    ) {
        // A random page, and one with a valid magic and random header so the
        // length/CRC paths run.
        let mut f = SimFlash::<2>::new();
        f.mem[PAGE..2 * PAGE].copy_from_slice(&page0);
        f.mem[2 * PAGE..2 * PAGE + 12].copy_from_slice(&head);
        f.mem[2 * PAGE..2 * PAGE + 4].copy_from_slice(b"TPS1");
        let _ = boot(&f);
    }
}
