//! The semihosting command line: the run limit, the host files and the
//! test scenario.

/// Words of the semihosting command line this board understands.
#[derive(Default)]
pub(super) struct CmdLine {
    pub(super) run_ms: Option<u32>,
    pub(super) scenario: Scenario,
    /// `gate=PATH`: the lock-step gate (see [`Sensors::sample`](super::Sensors::sample)).
    pub(super) gate: [u8; GATE_PATH_MAX],
    pub(super) gate_len: usize,
}

/// Longest lock-step gate path (the tests use a short one in `/tmp`;
/// 32 keeps `Default` derivable).
const GATE_PATH_MAX: usize = 32;

/// Scheduled changes to the simulated machine, in firmware milliseconds.
///
/// `gear=N` (1–6, Low 1 … High 3) sets the travel gear at boot;
/// `step=T:+P` / `step=T:-P` sets the travel speed P % off its gear speed at
/// T ms (`step=T:0` returns to it; up to four); `tau=MS` gives the chassis a
/// speed time constant;
/// `stop=T` stops the tractor at T ms; `stopgo=MS` drives it stop-and-go
/// (MS/2 of travel, MS/2 of rest, from boot); `stop_input=T` opens the stop
/// input's contact at T ms and `stop_input_close=T` closes it; `stall=T`, `hall_loss=T`,
/// `enc_loss=T` inject faults at T ms; `wheel_loss=T` stops machine A's
/// ground wheel's counts at T ms (lifted, blocked or clogged while the
/// track moves on) and `wheel_back=T` lets it turn again; `noise=0` makes the model noiseless;
/// `seed=N` seeds it; `slip=P` scales the track slip of paper A's Table 12
/// to P % (a machine whose calibration is not the paper's); `plant_log=1`
/// logs every plant the model drops (`sim: plant N at P um`, the main job's
/// report plots each spacing from them; off by default to keep the long
/// accelerated runs' logs short). The work switch (PB11): `work_down=T`
/// closes its contact (unit down) at T ms, `work_up=T` opens it; or, by
/// the simulated machine's true ground position, `work_down_mm=D` and
/// `work_up_mm=D` (up to four in all, each once; the contact starts open, as an
/// unwired input reads); `scatter=0` turns the landing scatter alone off
/// (the figures of the control, without the seedlings' fall) and
/// `slip_noise=0` the random variation of the track and belt slip around
/// their means (which no sensor of the machine sees). `drive_tau=MS`,
/// `drive_dead=MS` (0–63) and `drive_nmax=N` (r/min × 100) give the drum
/// another drive than the default 25 ms / 5 ms / 44.70 r/min (the drive
/// identification's test); `load=P` sets the seedlings' load droop to P ‰
/// (`load=0`: an empty belt). `stack_overflow=T` runs the control task's
/// stack off the bottom of RAM at T ms (the stack guard's test).
#[derive(Default, Clone, Copy)]
pub(super) struct Scenario {
    pub(super) gear: Option<u8>,
    pub(super) step: [Option<(u32, i32)>; 4],
    pub(super) tau_ms: Option<u32>,
    pub(super) stop: Option<u32>,
    pub(super) stop_input: Option<u32>,
    pub(super) stop_input_close: Option<u32>,
    /// Stop-and-go period, ms (`stopgo=MS`).
    pub(super) stop_go_ms: Option<u32>,
    /// The host runs a virtual drum driver on USART2 (`drive_link=1`,
    /// lock-step only): see [`Sensors::sample`](super::Sensors::sample).
    pub(super) drive_link: bool,
    pub(super) stall: Option<u32>,
    pub(super) hall_loss: Option<u32>,
    pub(super) enc_loss: Option<u32>,
    /// The ground wheel stops counting (`wheel_loss=T`).
    pub(super) wheel_loss: Option<u32>,
    /// It counts again (`wheel_back=T`).
    pub(super) wheel_back: Option<u32>,
    pub(super) noiseless: bool,
    pub(super) seed: Option<u32>,
    /// Profile B machine (`profile=b`).
    pub(super) profile_b: bool,
    /// Travel speed override, mm/s (`speed=N`).
    pub(super) speed_mm_s: Option<u32>,
    /// Restart the field metrics at this time (`metrics_from=T`).
    pub(super) metrics_from: Option<u32>,
    /// Track slip, % of Table 12's (`slip=P`).
    pub(super) slip_pct: Option<u32>,
    /// Log every plant's ground position (`plant_log=1`).
    pub(super) plant_log: bool,
    /// The drum drive's time constant, ms (`drive_tau=MS`).
    pub(super) drive_tau_ms: Option<u32>,
    /// Its dead time, ms (`drive_dead=MS`).
    pub(super) drive_dead_ms: Option<u32>,
    /// Its speed at 100 % duty, r/min × 100 (`drive_nmax=N`).
    pub(super) drive_nmax_centi: Option<u32>,
    /// The seedlings' load droop, ‰ (`load=P`).
    pub(super) load_permille: Option<u32>,
    /// Work switch changes, packed to keep `init`'s stack small: bit 31
    /// closed (down), bit 30 the value is ground mm (else firmware ms),
    /// bits 0–29 the value; 0 = none.
    pub(super) work: [u32; 4],
    /// No landing scatter (`scatter=0`).
    pub(super) no_scatter: bool,
    /// No slip variation (`slip_noise=0`).
    pub(super) no_slip_noise: bool,
    /// Run the stack off the bottom of RAM at this time
    /// (`stack_overflow=T`, the test of [`stack_guard`](super::stack_guard)).
    pub(super) stack_overflow: Option<u32>,
}

/// [`Scenario::work`]: the contact closes (unit down).
pub(super) const WORK_CLOSED: u32 = 1 << 31;

/// [`Scenario::work`]: the value is a ground position in mm.
pub(super) const WORK_GROUND: u32 = 1 << 30;

/// [`Scenario::work`]: the value's bits.
pub(super) const WORK_VALUE: u32 = WORK_GROUND - 1;

/// Reads the semihosting command line into `cmd`; copies a `flash=PATH`
/// value into `path` and returns its length.
pub(super) fn read_cmdline(cmd: &mut CmdLine, path: &mut [u8]) -> usize {
    let mut buf = [0u8; 192];
    // SYS_GET_CMDLINE takes a two-word block {buffer, length} and writes the
    // used length back into it.
    let block = [buf.as_mut_ptr() as usize, buf.len()];
    // SAFETY: the block points at a live buffer of the length it states; the
    // host writes at most that many bytes.
    let rc =
        unsafe { cortex_m_semihosting::syscall(cortex_m_semihosting::nr::GET_CMDLINE, &block) };
    if rc != 0 {
        return 0;
    }
    // SAFETY: the host updated the length word behind a shared reference.
    let len = unsafe { core::ptr::read_volatile(&block[1]) }.min(buf.len());
    let mut path_len = 0;
    let line = buf.get(..len).unwrap_or(&[]);
    for word in line.split(|&b| b == b' ') {
        let Some(eq) = word.iter().position(|&b| b == b'=') else {
            continue;
        };
        let (key, value) = (
            word.get(..eq).unwrap_or(&[]),
            word.get(eq + 1..).unwrap_or(&[]),
        );
        let s = &mut cmd.scenario;
        match key {
            b"run_ms" => cmd.run_ms = parse_u32(value),
            b"flash" => {
                if let Some(dst) = path.get_mut(..value.len()) {
                    dst.copy_from_slice(value);
                    path_len = value.len();
                }
            }
            b"gate" => {
                if let Some(dst) = cmd.gate.get_mut(..value.len()) {
                    dst.copy_from_slice(value);
                    cmd.gate_len = value.len();
                }
            }
            b"gear" => s.gear = parse_u32(value).and_then(|g| u8::try_from(g).ok()),
            b"step" => {
                let slot = s.step.iter_mut().find(|x| x.is_none());
                if let (Some(slot), Some(colon)) = (slot, value.iter().position(|&b| b == b':')) {
                    let at = parse_u32(value.get(..colon).unwrap_or(&[]));
                    let pct = value.get(colon + 1..).and_then(parse_i32);
                    if let (Some(at), Some(pct)) = (at, pct) {
                        *slot = Some((at, pct));
                    }
                }
            }
            b"stop" => s.stop = parse_u32(value),
            b"stop_input" => s.stop_input = parse_u32(value),
            b"stop_input_close" => s.stop_input_close = parse_u32(value),
            b"stopgo" => s.stop_go_ms = parse_u32(value),
            b"drive_link" => s.drive_link = value == b"1",
            b"tau" => s.tau_ms = parse_u32(value),
            b"profile" => s.profile_b = value == b"b" || value == b"B",
            b"speed" => s.speed_mm_s = parse_u32(value),
            b"metrics_from" => s.metrics_from = parse_u32(value),
            b"stall" => s.stall = parse_u32(value),
            b"hall_loss" => s.hall_loss = parse_u32(value),
            b"enc_loss" => s.enc_loss = parse_u32(value),
            b"wheel_loss" => s.wheel_loss = parse_u32(value),
            b"wheel_back" => s.wheel_back = parse_u32(value),
            b"noise" => s.noiseless = value == b"0",
            b"seed" => s.seed = parse_u32(value),
            b"slip" => s.slip_pct = parse_u32(value),
            b"plant_log" => s.plant_log = value == b"1",
            b"drive_tau" => s.drive_tau_ms = parse_u32(value),
            b"drive_dead" => s.drive_dead_ms = parse_u32(value),
            b"drive_nmax" => s.drive_nmax_centi = parse_u32(value),
            b"load" => s.load_permille = parse_u32(value),
            b"scatter" => s.no_scatter = value == b"0",
            b"slip_noise" => s.no_slip_noise = value == b"0",
            b"stack_overflow" => s.stack_overflow = parse_u32(value),
            b"work_down" | b"work_up" | b"work_down_mm" | b"work_up_mm" => {
                let flags = if key.starts_with(b"work_down") {
                    WORK_CLOSED
                } else {
                    0
                } | if key.ends_with(b"_mm") {
                    WORK_GROUND
                } else {
                    0
                };
                let at = parse_u32(value).filter(|&v| v <= WORK_VALUE);
                if let (Some(slot), Some(at)) = (s.work.iter_mut().find(|x| **x == 0), at) {
                    *slot = flags | at;
                }
            }
            _ => {}
        }
    }
    path_len
}

fn parse_u32(digits: &[u8]) -> Option<u32> {
    if digits.is_empty() {
        return None;
    }
    digits.iter().try_fold(0u32, |acc, &d| {
        if d.is_ascii_digit() {
            acc.checked_mul(10)?.checked_add(u32::from(d - b'0'))
        } else {
            None
        }
    })
}

fn parse_i32(text: &[u8]) -> Option<i32> {
    match text.split_first() {
        Some((b'-', rest)) => parse_u32(rest)
            .and_then(|v| i32::try_from(v).ok())
            .map(|v| -v),
        Some((b'+', rest)) => parse_u32(rest).and_then(|v| i32::try_from(v).ok()),
        _ => parse_u32(text).and_then(|v| i32::try_from(v).ok()),
    }
}
