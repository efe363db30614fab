//! The twin: a register-level emulation of the real board (STM32F103RB at
//! 72 MHz) that runs the unmodified release ELF of a real-board image.
//!
//! - The Cortex-M3 instruction set comes from unicorn (QEMU's TCG).
//!   Exception entry and return, the NVIC, SysTick and faults are modelled
//!   here ([`core`]); the peripherals the images touch are modelled from
//!   RM0008 ([`periph`]).
//! - Time: one executed instruction is one cycle of the core clock (flash
//!   wait states and pipeline effects are ignored, see docs/twin.md); `wfi`
//!   skips to the next event.
//! - The machine (`machine-sim`) is wired to the pins and timers
//!   ([`plant`]); the virtual touchscreen talks to USART1; the defmt log is
//!   read from the image's RTT buffer in RAM and decoded by `defmt-print`.
//!
//! Licence: this crate links unicorn (GPL-2.0) and is therefore GPL-2.0; it
//! is a development tool that the firmware never links.

pub mod core;
pub mod image;
pub mod periph;
pub mod plant;

use std::cell::RefCell;
use std::io::{self, BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::rc::Rc;
use std::sync::mpsc::{self, Receiver};
use std::thread;
use std::time::{Duration, Instant};

use object::{Object, ObjectSection, ObjectSymbol};
use unicorn_engine::{
    unicorn_const::{Arch, HookType, MemType, Mode, Prot},
    ArmCpuModel, Unicorn,
};

use crate::core::{exc, Nvic};
use crate::periph::{Bus, FlashOp, FLASH_BASE, FLASH_SIZE, NEVER};
pub use crate::periph::{External, Level, Ticks, TICKS_PER_S};
pub use unicorn_engine::RegisterARM;

/// Start of SRAM.
pub const RAM_BASE: u32 = 0x2000_0000;
/// 20 KB (STM32F103RB).
pub const RAM_SIZE: u32 = 20 * 1024;

/// Errors of the twin.
#[derive(Debug)]
pub enum Error {
    /// The ELF could not be read or lacks what the twin needs.
    Elf(String),
    /// Unicorn refused an operation.
    Engine(String),
    /// A host tool (defmt-print) failed.
    Io(io::Error),
}

impl std::fmt::Display for Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Error::Elf(s) => write!(f, "ELF: {s}"),
            Error::Engine(s) => write!(f, "unicorn: {s}"),
            Error::Io(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for Error {}

impl From<io::Error> for Error {
    fn from(e: io::Error) -> Self {
        Error::Io(e)
    }
}

fn uc_err(e: unicorn_engine::unicorn_const::uc_error) -> Error {
    Error::Engine(format!("{e:?}"))
}

/// Why the MCU was reset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResetCause {
    /// Power applied (the twin was built or [`Twin::power_cycle`]).
    PowerOn,
    /// The independent watchdog counted down to 0.
    Watchdog,
    /// SYSRESETREQ in AIRCR.
    Software,
}

/// What the core is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CoreState {
    /// Executing instructions.
    Running,
    /// Asleep in `wfi`.
    Sleeping,
    /// Locked up (a fault in HardFault or NMI): executes nothing until reset.
    Lockup,
    /// Halted by the (virtual) debugger.
    DebugHalt,
    /// Its clock is gone (crystal failure without the clock security
    /// system): executes nothing until a reset.
    NoClock,
}

/// Options of a twin.
#[derive(Clone, Debug)]
pub struct Options {
    /// The crystal never starts.
    pub hse_dead: bool,
    /// LSI frequency (IWDG clock), Hz: 40 kHz nominal, 30..60 kHz.
    pub lsi_hz: u64,
    /// Print decoded log lines to stderr as they come.
    pub echo_logs: bool,
    /// Flash contents to start from (a previous twin's [`Twin::flash`]);
    /// `None` = the ELF programmed onto an erased chip.
    pub flash: Option<Vec<u8>>,
    /// Decode the defmt log with `defmt-print` (off: no host process).
    pub decode_logs: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            hse_dead: false,
            lsi_hz: 40_000,
            echo_logs: false,
            flash: None,
            decode_logs: true,
        }
    }
}

/// A stop reason recorded by a hook for the run loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stop {
    /// Re-plan (a register write changed the next event).
    Replan,
    /// The core executed an instruction that faults (intr hook number).
    Fault(u32),
}

/// Everything the hooks share with the run loop.
pub struct State {
    /// Firmware time.
    pub now: Ticks,
    /// Ticks per instruction (72 MHz / core clock).
    cost: Ticks,
    /// The peripherals.
    pub bus: Bus,
    /// The NVIC and SCB.
    pub nvic: Nvic,
    stop: Option<Stop>,
    /// Something is pending but masked: the code hook watches the masks.
    watch_masks: bool,
    /// Instructions executed since power-on.
    pub instructions: u64,
    /// Flash stall to serve (ticks) before the next instruction.
    stall: Ticks,
    /// A flash write to put right (address, value the array must hold).
    fixups: Vec<(u32, u16)>,
    /// Memory errors the CPU made (address) in this chunk.
    pub bus_error: Option<u32>,
    /// A peripheral register write happened (for the waker).
    touched: bool,
    /// Stop before the first block that starts at or after this time.
    deadline: Ticks,
    /// Instructions per translated block (start address, bytes).
    block_insns: std::collections::HashMap<(u32, u32), u64, BlockHash>,
    /// Exceptions entered since the twin was built.
    pub exception_entries: u64,
    /// Of those, entries whose frame (the handler's SP) is not 8-byte
    /// aligned: CCR.STKALIGN = 0 and SP ≡ 4 (mod 8) when the exception came
    /// (AAPCS wants SP ≡ 0 mod 8 at every function entry, a handler's too).
    pub frames_not_8_aligned: u64,
    /// The last exception entry: (exception number, frame address).
    pub last_entry: Option<(u32, u32)>,
}

impl State {
    /// A CPU read on the private peripheral bus (a read of SYST_CSR clears
    /// COUNTFLAG, PM0056 §4.5.1).
    fn ppb_read(&mut self, a: u32) -> u32 {
        match a {
            0xE000_E010 => {
                self.bus.advance_systick(self.now);
                let st = &mut self.bus.systick;
                st.ctrl | if st.countflag_take() { 1 << 16 } else { 0 }
            }
            0xE000_E018 => {
                self.bus.advance_systick(self.now);
                self.bus.systick.val()
            }
            _ => self.ppb_peek(a),
        }
    }

    /// A register of the private peripheral bus as it reads now, without
    /// side effects (SYST_CSR's COUNTFLAG is shown, not cleared).
    pub fn ppb_peek(&self, a: u32) -> u32 {
        match a {
            0xE000_E010 | 0xE000_E018 => {
                let (csr, cvr) = self.bus.systick.peek(self.now, &self.bus.clocks());
                if a == 0xE000_E010 {
                    csr
                } else {
                    cvr
                }
            }
            0xE000_E014 => self.bus.systick.load,
            // SYST_CALIB (PM0056 §4.5.4): NOREF = 0 (the HCLK/8 reference
            // is there), SKEW = 1, TENMS = 9000 (1 ms at 72 MHz / 8).
            0xE000_E01C => 0x4000_2328,
            // DBGMCU_IDCODE (RM0008 §31.6.1): DEV_ID 0x410 (medium
            // density), REV_ID 0x2003 (revision Y, 1, 2 or X); bits 14:13
            // read as 1 on the chip.
            0xE004_2000 => 0x2003_6410,
            0xE004_2004 => self.bus.dbgmcu_cr,
            0xE000_1004 => self.instructions as u32, // DWT_CYCCNT
            _ => self.nvic.read(a),
        }
    }

    fn ppb_write(&mut self, a: u32, v: u32, size: usize) {
        match a {
            0xE000_E010 => {
                self.bus.advance_systick(self.now);
                self.bus.systick.ctrl = v & 7;
                self.bus.systick.restart(self.now);
            }
            0xE000_E014 => self.bus.systick.load = v & 0x00FF_FFFF,
            0xE000_E018 => {
                self.bus.advance_systick(self.now);
                self.bus.systick.clear(self.now);
            }
            0xE004_2004 => self.bus.dbgmcu_cr = v,
            _ => self.nvic.write(a, v, size),
        }
        self.stop.get_or_insert(Stop::Replan);
    }
}

/// The hasher of the block table: looked up once per executed block, where
/// the standard SipHash took a fifth of the host time. Keys are block
/// addresses and sizes chosen by the image, not by an adversary.
#[derive(Clone, Copy, Default)]
pub struct BlockHasher(u64);

impl std::hash::Hasher for BlockHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u32(&mut self, v: u32) {
        self.write_u64(u64::from(v));
    }

    fn write_u64(&mut self, v: u64) {
        // Fibonacci hashing: spread the bits over the whole word.
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

/// [`BlockHasher`] for `HashMap`.
pub type BlockHash = std::hash::BuildHasherDefault<BlockHasher>;

/// A probe on the twin's state ([`Twin::watch`]).
pub type Watcher = Box<dyn FnMut(&State) -> bool>;

/// A saved instant of a twin ([`Twin::snapshot`]).
pub struct Snapshot {
    ctx: unicorn_engine::Context,
    ram: Vec<u8>,
    flash: Vec<u8>,
    now: Ticks,
    bus: Bus,
    nvic: Nvic,
    instructions: u64,
    core: CoreState,
    resets: Vec<(Ticks, ResetCause)>,
    screen: Option<hmi_proto::virtual_screen::VirtualScreen>,
    screen_next: Ticks,
    rtt_last: Option<u8>,
}

/// Where the defmt frames go.
struct LogSink {
    /// Complete defmt frames (rzcobs: each ends with a 0x00) sent to the
    /// decoder: one log line each.
    frames: usize,
    /// Bytes before the first frame boundary are dropped (a decoder started
    /// after a restore joins the stream mid-frame).
    synced: bool,
    /// The last byte sent.
    prev: u8,
    stdin: Option<ChildStdin>,
    child: Option<Child>,
    rx: Option<Receiver<String>>,
    lines: Vec<String>,
    last_write: Instant,
}

/// The twin of the real board running one image.
pub struct Twin {
    uc: Unicorn<'static, State>,
    elf_path: PathBuf,
    /// The ELF's loadable flash contents (programmed at "production").
    vector_sp: u32,
    rtt: Option<u32>,
    symbols: Vec<(String, u32, u64)>,
    log: LogSink,
    /// The raw defmt bytes read from RTT.
    pub rtt_bytes: Vec<u8>,
    /// Resets so far: (time, cause).
    pub resets: Vec<(Ticks, ResetCause)>,
    /// The core's state.
    pub core: CoreState,
    /// When the core locked up.
    pub lockup_at: Option<Ticks>,
    /// The machine wired to the pins, if any.
    pub plant: Option<plant::Plant>,
    /// The touchscreen on USART1, if any.
    pub screen: Option<hmi_proto::virtual_screen::VirtualScreen>,
    /// Called after every scheduling step (a probe on the pins).
    watchers: Vec<Watcher>,
    /// Host time spent in [`Twin::run_for`].
    pub host_time: Duration,
    screen_next: Ticks,
    echo: bool,
    /// The last defmt byte sent to the decoder (frame boundary if 0).
    rtt_last: Option<u8>,
}

/// Reads a little-endian u32 from unicorn memory.
fn rd32(uc: &Unicorn<'static, State>, a: u32) -> Option<u32> {
    let mut b = [0u8; 4];
    uc.mem_read(u64::from(a), &mut b).ok()?;
    Some(u32::from_le_bytes(b))
}

impl Twin {
    /// Loads `elf` onto a fresh twin (flash programmed, RAM random-free
    /// zeros, power-on reset) without running it.
    pub fn new(elf: &Path, options: Options) -> Result<Self, Error> {
        let data = std::fs::read(elf).map_err(|e| Error::Elf(format!("{}: {e}", elf.display())))?;
        let file = object::File::parse(&*data).map_err(|e| Error::Elf(e.to_string()))?;
        let mut flash = options
            .flash
            .clone()
            .unwrap_or_else(|| vec![0xFF; FLASH_SIZE as usize]);
        if options.flash.is_none() {
            // Program the image's loadable segments (by load address).
            load_flash(&data, &mut flash)?;
        }
        let mut symbols = Vec::new();
        let mut rtt = None;
        for s in file.symbols() {
            if let Ok(name) = s.name() {
                if name == "_SEGGER_RTT" {
                    rtt = Some(s.address() as u32);
                }
                symbols.push((name.to_string(), s.address() as u32, s.size()));
            }
        }
        Self::build(Some(elf), flash, symbols, rtt, options)
    }

    /// A fresh twin running a bare program: `image` is programmed at the
    /// start of the flash (its vector table first), the rest erased; no
    /// symbols, no RTT log. For the models' own tests.
    pub fn from_program(image: &[u8], options: Options) -> Result<Self, Error> {
        if image.len() > FLASH_SIZE as usize {
            return Err(Error::Elf("program larger than the flash".into()));
        }
        let mut flash = vec![0xFF; FLASH_SIZE as usize];
        flash[..image.len()].copy_from_slice(image);
        let options = Options {
            decode_logs: false,
            ..options
        };
        Self::build(None, flash, Vec::new(), None, options)
    }

    fn build(
        elf: Option<&Path>,
        flash: Vec<u8>,
        symbols: Vec<(String, u32, u64)>,
        rtt: Option<u32>,
        options: Options,
    ) -> Result<Self, Error> {
        let state = State {
            now: 0,
            cost: 9,
            bus: Bus::new(options.hse_dead, options.lsi_hz),
            nvic: Nvic::default(),
            stop: None,
            watch_masks: false,
            instructions: 0,
            stall: 0,
            fixups: Vec::new(),
            bus_error: None,
            touched: false,
            deadline: 0,
            block_insns: std::collections::HashMap::default(),
            exception_entries: 0,
            frames_not_8_aligned: 0,
            last_entry: None,
        };
        let mut uc = Unicorn::new_with_data(Arch::ARM, Mode::MCLASS | Mode::LITTLE_ENDIAN, state)
            .map_err(uc_err)?;
        uc.ctl_set_cpu_model(ArmCpuModel::CORTEX_M3 as i32)
            .map_err(uc_err)?;
        uc.mem_map(
            u64::from(FLASH_BASE),
            u64::from(FLASH_SIZE),
            Prot::READ | Prot::EXEC | Prot::WRITE,
        )
        .map_err(uc_err)?;
        uc.mem_write(u64::from(FLASH_BASE), &flash)
            .map_err(uc_err)?;
        uc.mem_map(u64::from(RAM_BASE), u64::from(RAM_SIZE), Prot::ALL)
            .map_err(uc_err)?;
        map_peripherals(&mut uc)?;
        add_hooks(&mut uc)?;
        let vector_sp = u32::from_le_bytes(flash[0..4].try_into().unwrap_or([0; 4]));
        let log = match elf {
            Some(elf) => LogSink::start(elf, options.decode_logs, options.echo_logs)?,
            None => LogSink::start(Path::new(""), false, false)?,
        };
        let mut twin = Self {
            uc,
            elf_path: elf.map(Path::to_path_buf).unwrap_or_default(),
            vector_sp,
            rtt,
            symbols,
            log,
            rtt_bytes: Vec::new(),
            resets: Vec::new(),
            core: CoreState::Running,
            lockup_at: None,
            plant: None,
            screen: None,
            watchers: Vec::new(),
            host_time: Duration::ZERO,
            screen_next: 0,
            echo: options.echo_logs,
            rtt_last: None,
        };
        twin.reset(ResetCause::PowerOn)?;
        Ok(twin)
    }

    /// The ELF this twin runs.
    pub fn elf(&self) -> &Path {
        &self.elf_path
    }

    /// The shared state (peripherals, NVIC, time).
    pub fn state(&self) -> &State {
        self.uc.get_data()
    }

    /// The shared state, mutable (inject inputs, set external pins).
    pub fn state_mut(&mut self) -> &mut State {
        self.uc.get_data_mut()
    }

    /// Firmware time, seconds.
    pub fn now_s(&self) -> f64 {
        self.state().now as f64 / TICKS_PER_S as f64
    }

    /// Firmware time, ticks.
    pub fn now(&self) -> Ticks {
        self.state().now
    }

    /// The level of a pin now (`port` 'A'..'E').
    pub fn pin(&mut self, port: char, pin: u32) -> Level {
        let now = self.now();
        let st = self.uc.get_data_mut();
        st.bus.advance(now);
        st.bus.pin_level(port_index(port), pin)
    }

    /// Records the level changes of a pin (`port` 'A'..'E') from now on,
    /// with their times, into `state().bus.pin_log` (see
    /// [`periph::Bus::trace_pin`]).
    pub fn trace_pin(&mut self, port: char, pin: u32) {
        let now = self.now();
        let st = self.uc.get_data_mut();
        st.bus.advance(now);
        st.bus.trace_pin(port_index(port), pin, now);
    }

    /// Drives an input pin from outside.
    pub fn set_external(&mut self, port: char, pin: u32, e: External) {
        let now = self.now();
        let st = self.uc.get_data_mut();
        st.bus.external[port_index(port)][pin as usize] = e;
        st.bus.advance(now);
    }

    /// Address and size of an ELF symbol.
    pub fn symbol(&self, name: &str) -> Option<(u32, u64)> {
        self.symbols
            .iter()
            .find(|(n, _, _)| n == name)
            .map(|(_, a, s)| (*a, *s))
    }

    /// Address of the first symbol whose (mangled) name contains all of
    /// `parts`.
    pub fn symbol_like(&self, parts: &[&str]) -> Option<(u32, u64)> {
        self.symbols
            .iter()
            .find(|(n, _, _)| parts.iter().all(|p| n.contains(p)))
            .map(|(_, a, s)| (*a, *s))
    }

    /// Reads a word of memory (RAM or flash).
    pub fn read_u32(&self, a: u32) -> Option<u32> {
        rd32(&self.uc, a)
    }

    /// Writes memory (as a debugger would).
    pub fn write_mem(&mut self, a: u32, bytes: &[u8]) -> Result<(), Error> {
        self.uc.mem_write(u64::from(a), bytes).map_err(uc_err)
    }

    /// A core register.
    pub fn reg(&self, r: RegisterARM) -> u32 {
        self.uc.reg_read(r).unwrap_or(0) as u32
    }

    /// Writes a core register (as a debugger would).
    pub fn set_reg(&mut self, r: RegisterARM, v: u32) -> Result<(), Error> {
        self.uc.reg_write(r, u64::from(v)).map_err(uc_err)
    }

    /// The whole flash array (persists across resets; hand it to a new
    /// twin in [`Options::flash`]).
    pub fn flash(&self) -> Vec<u8> {
        self.uc
            .mem_read_as_vec(u64::from(FLASH_BASE), FLASH_SIZE as usize)
            .unwrap_or_default()
    }

    /// The flash operations the FPEC carried out so far.
    pub fn flash_ops(&self) -> &[FlashOp] {
        &self.state().bus.flash.log
    }

    /// Arms a power cut at flash operation `n` (counted from 0 since the
    /// twin was built): before it takes effect, or right after.
    pub fn cut_power_at_flash_op(&mut self, n: u64, after: bool) {
        self.state_mut().bus.flash.cut_at = Some((n, after));
    }

    /// Reads a peripheral or system register without side effects on the
    /// twin (a debugger's view).
    pub fn peek(&self, a: u32) -> u32 {
        let st = self.state();
        if (0xE000_0000..0xE010_0000).contains(&a) {
            st.ppb_peek(a)
        } else {
            let mut bus = st.bus.clone();
            bus.read(a, st.now)
        }
    }

    /// Bytes the firmware sent on USART1 (or 2) not yet taken.
    pub fn take_serial(&mut self, n: usize) -> Vec<u8> {
        std::mem::take(&mut self.state_mut().bus.usart[n].tx_out)
    }

    /// Bytes put on USART `n`'s RX line (they arrive at the line rate).
    pub fn send_serial(&mut self, n: usize, bytes: &[u8]) {
        self.state_mut().bus.usart[n]
            .rx_line
            .extend(bytes.iter().copied());
        self.state_mut().stop = Some(Stop::Replan);
    }

    /// Connects the virtual touchscreen to USART1 (it boots and sends its
    /// start-up frames, as a real Nextion does).
    pub fn connect_screen(&mut self) {
        let mut s = hmi_proto::virtual_screen::VirtualScreen::with_contract();
        s.boot();
        self.screen = Some(s);
    }

    /// Adds a watcher called after each scheduling step with the state;
    /// returning `true` stops [`Twin::run_until`].
    pub fn watch(&mut self, f: impl FnMut(&State) -> bool + 'static) {
        self.watchers.push(Box::new(f));
    }

    /// Resets the MCU (the flash keeps its contents; RAM is kept as it is,
    /// like a real system reset; a power-on also keeps it here, zeroed by
    /// the firmware's start-up code anyway).
    pub fn reset(&mut self, cause: ResetCause) -> Result<(), Error> {
        let now = self.now();
        self.resets.push((now, cause));
        let flag = match cause {
            ResetCause::PowerOn => 0x0C00_0000,
            ResetCause::Watchdog => 0x2400_0000,
            ResetCause::Software => 0x1400_0000,
        };
        {
            let st = self.uc.get_data_mut();
            if cause == ResetCause::PowerOn && now > 0 {
                let hse = st.bus.rcc.hse_dead;
                let lsi = st.bus.iwdg.lsi_hz;
                let flash = st.bus.flash.clone();
                st.bus = Bus::new(hse, lsi);
                st.bus.flash = flash;
                st.bus.flash.cut_fired = false;
                st.bus.system_reset(now, flag);
            } else {
                st.bus.system_reset(now, flag);
            }
            st.nvic = Nvic::default();
            st.stop = None;
            st.stall = 0;
            st.fixups.clear();
            st.watch_masks = false;
            st.bus_error = None;
        }
        // A frame cut by the reset: end it for the decoder (not counted as a
        // line); the new run's frames start on a boundary.
        if self.rtt_last.is_some_and(|b| b != 0) {
            self.log.terminate();
            self.rtt_last = Some(0);
        }
        // Clear the RTT control block so that a stale one is never read.
        if let Some(a) = self.rtt {
            let _ = self.uc.mem_write(u64::from(a), &[0u8; 16]);
        }
        let sp = rd32(&self.uc, FLASH_BASE).unwrap_or(self.vector_sp);
        let pc = rd32(&self.uc, FLASH_BASE + 4).unwrap_or(0);
        let uc = &mut self.uc;
        for (r, v) in [
            (RegisterARM::PRIMASK, 0),
            (RegisterARM::BASEPRI, 0),
            (RegisterARM::FAULTMASK, 0),
            (RegisterARM::CONTROL, 0),
            (RegisterARM::IPSR, 0),
            (RegisterARM::MSP, u64::from(sp)),
            (RegisterARM::SP, u64::from(sp)),
            (RegisterARM::LR, 0xFFFF_FFFF),
            (RegisterARM::PC, u64::from(pc | 1)),
        ] {
            uc.reg_write(r, v).map_err(uc_err)?;
        }
        self.core = CoreState::Running;
        self.lockup_at = None;
        if let Some(p) = &mut self.plant {
            p.mcu_reset();
        }
        Ok(())
    }

    /// Cuts the power and applies it again (flash kept).
    pub fn power_cycle(&mut self) -> Result<(), Error> {
        // RAM loses its contents.
        let _ = self
            .uc
            .mem_write(u64::from(RAM_BASE), &vec![0u8; RAM_SIZE as usize]);
        self.reset(ResetCause::PowerOn)
    }

    /// Runs for `ms` milliseconds of firmware time.
    pub fn run_ms(&mut self, ms: u64) -> Result<(), Error> {
        let until = self.now() + ms * TICKS_PER_S / 1000;
        self.run_until_time(until, &mut |_| false)
    }

    /// Runs until `pred` holds (checked after every scheduling step) or
    /// `ms` of firmware time passed; `Ok(true)` when `pred` held.
    pub fn run_until(
        &mut self,
        ms: u64,
        mut pred: impl FnMut(&mut Twin) -> bool,
    ) -> Result<bool, Error> {
        let until = self.now() + ms * TICKS_PER_S / 1000;
        let step = TICKS_PER_S / 1000;
        while self.now() < until {
            if pred(self) {
                return Ok(true);
            }
            let t = (self.now() + step).min(until);
            self.run_until_time(t, &mut |_| false)?;
        }
        Ok(pred(self))
    }

    fn run_until_time(
        &mut self,
        until: Ticks,
        stop: &mut dyn FnMut(&State) -> bool,
    ) -> Result<(), Error> {
        let started = Instant::now();
        let r = self.run_inner(until, stop);
        self.host_time += started.elapsed();
        r
    }

    fn run_inner(
        &mut self,
        until: Ticks,
        stop: &mut dyn FnMut(&State) -> bool,
    ) -> Result<(), Error> {
        while self.now() < until {
            // Peripheral time, interrupts, machine, screen.
            self.service()?;
            if stop(self.state()) {
                return Ok(());
            }
            let now = self.now();
            if now >= until {
                break;
            }
            let next = self.next_event().min(until).max(now + 1);
            match self.core {
                CoreState::Running => {
                    self.execute(next)?;
                }
                CoreState::Sleeping => {
                    if self.wake_pending() {
                        self.core = CoreState::Running;
                    } else {
                        self.state_mut().now = next;
                    }
                }
                CoreState::Lockup | CoreState::DebugHalt | CoreState::NoClock => {
                    self.state_mut().now = next;
                }
            }
        }
        self.service()?;
        Ok(())
    }

    /// The next time something outside the core happens.
    fn next_event(&self) -> Ticks {
        let st = self.state();
        let mut t = st.bus.next_event();
        if let Some(p) = &self.plant {
            t = t.min(p.next_event());
        }
        if self.screen.is_some() {
            t = t.min(self.screen_next);
        }
        // Drain RTT at least every 10 ms of firmware time.
        t.min((st.now / 720_000 + 1) * 720_000)
    }

    /// Brings everything up to the current time and takes exceptions.
    fn service(&mut self) -> Result<(), Error> {
        let now = self.now();
        // The machine first: its events (Hall edges) are in the past or now.
        if let Some(mut p) = self.plant.take() {
            p.service(now, &mut self.uc.get_data_mut().bus);
            self.plant = Some(p);
        }
        if let Some(mut s) = self.screen.take() {
            if now >= self.screen_next {
                let st = self.uc.get_data_mut();
                let out = std::mem::take(&mut st.bus.usart[0].tx_out);
                if !out.is_empty() {
                    s.feed(&out);
                }
                let inp = s.take_output();
                st.bus.usart[0].rx_line.extend(inp);
                self.screen_next = now + TICKS_PER_S / 1000;
            }
            self.screen = Some(s);
        }
        {
            let st = self.uc.get_data_mut();
            st.bus.advance(now);
            if std::mem::take(&mut st.bus.systick.fired) {
                st.nvic.set_pending(exc::SYSTICK);
            }
            for l in st.bus.irq_lines() {
                st.nvic.line(l);
            }
        }
        let (wd, sw, cut) = {
            let st = self.state();
            (
                st.bus.iwdg.expires_at() <= now,
                st.nvic.reset_requested,
                st.bus.flash.cut_fired,
            )
        };
        if wd {
            self.drain_rtt();
            return self.reset(ResetCause::Watchdog);
        }
        if sw {
            self.drain_rtt();
            return self.reset(ResetCause::Software);
        }
        if cut {
            self.drain_rtt();
            return self.power_cycle();
        }
        self.drain_rtt();
        if self.core == CoreState::Running || self.core == CoreState::Sleeping {
            self.take_exceptions()?;
        }
        Ok(())
    }

    fn masks(&self) -> (bool, bool, u8) {
        (
            self.reg(RegisterARM::PRIMASK) & 1 != 0,
            self.reg(RegisterARM::FAULTMASK) & 1 != 0,
            self.reg(RegisterARM::BASEPRI) as u8,
        )
    }

    fn wake_pending(&self) -> bool {
        // WFI wakes on a pending exception that would preempt with PRIMASK
        // ignored (ARMv7-M B1.5.19).
        let (_, fm, bp) = self.masks();
        let st = self.state();
        let exec = st.nvic.execution_priority(false, fm, bp);
        st.nvic.top_pending().is_some_and(|(_, p)| p < exec)
    }

    fn take_exceptions(&mut self) -> Result<(), Error> {
        loop {
            let (pm, fm, bp) = self.masks();
            let st = self.uc.get_data_mut();
            let exec = st.nvic.execution_priority(pm, fm, bp);
            match st.nvic.top_pending() {
                Some((n, p)) if p < exec => {
                    if self.core == CoreState::Sleeping {
                        self.core = CoreState::Running;
                    }
                    self.enter_exception(n)?;
                }
                Some(_) => {
                    st.watch_masks = true;
                    return Ok(());
                }
                None => {
                    st.watch_masks = false;
                    return Ok(());
                }
            }
        }
    }

    /// Exception entry (ARMv7-M B1.5.6): the frame pushed on the main
    /// stack, LR = EXC_RETURN, PC from the vector table. Stacking errors
    /// are ignored (the handler runs; a fault in HardFault locks up later).
    fn enter_exception(&mut self, n: u32) -> Result<(), Error> {
        let pc = self.reg(RegisterARM::PC);
        self.enter_exception_at(n, pc)
    }

    fn enter_exception_at(&mut self, n: u32, return_pc: u32) -> Result<(), Error> {
        let regs = [
            RegisterARM::R0,
            RegisterARM::R1,
            RegisterARM::R2,
            RegisterARM::R3,
            RegisterARM::R12,
            RegisterARM::LR,
        ];
        let mut frame = [0u32; 8];
        for (i, r) in regs.iter().enumerate() {
            frame[i] = self.reg(*r);
        }
        frame[6] = return_pc & !1;
        let xpsr = self.reg(RegisterARM::XPSR);
        let current = self.state().nvic.active.last().copied().unwrap_or(0);
        let mut sp = self.reg(RegisterARM::SP);
        // With CCR.STKALIGN the frame starts on an 8-byte boundary (a
        // padding word, flagged by xPSR bit 9); without it, wherever SP
        // points (ARMv7-M B1.5.6 PushStack; PM0056 §4.4.7).
        let stkalign = self.state().nvic.ccr & core::CCR_STKALIGN != 0;
        let align = stkalign && sp & 4 != 0;
        if align {
            sp -= 4;
        }
        sp = sp.wrapping_sub(32);
        frame[7] =
            (xpsr & !0x1FF & !(1 << 9)) | current | (1 << 24) | if align { 1 << 9 } else { 0 };
        let mut stack_fault = false;
        for (i, w) in frame.iter().enumerate() {
            if self
                .uc
                .mem_write(u64::from(sp + 4 * i as u32), &w.to_le_bytes())
                .is_err()
            {
                stack_fault = true;
            }
        }
        let nested = !self.state().nvic.active.is_empty();
        let vtor = self.state().nvic.vtor;
        let vec_addr = if vtor == 0 { FLASH_BASE } else { vtor } + 4 * n;
        let handler = rd32(&self.uc, vec_addr).unwrap_or(0);
        {
            let st = self.uc.get_data_mut();
            st.nvic.pending &= !(1u128 << n);
            st.nvic.active.push(n);
            st.exception_entries += 1;
            if sp & 7 != 0 {
                st.frames_not_8_aligned += 1;
            }
            st.last_entry = Some((n, sp));
            // Entry latency: 12 cycles on the Cortex-M3.
            st.now += 12 * st.cost;
            if stack_fault {
                // A derived BusFault on stacking (BSTKERR) escalates to
                // HardFault; for HardFault/NMI entries it is ignored here
                // and the handler runs on the broken stack.
                st.nvic.cfsr |= 1 << 12;
                if n != exc::HARD_FAULT && n != exc::NMI {
                    st.nvic.hfsr |= 1 << 30;
                    st.nvic.set_pending(exc::HARD_FAULT);
                }
            }
        }
        let lr = if nested { 0xFFFF_FFF1u32 } else { 0xFFFF_FFF9 };
        let uc = &mut self.uc;
        uc.reg_write(RegisterARM::SP, u64::from(sp))
            .map_err(uc_err)?;
        uc.reg_write(RegisterARM::LR, u64::from(lr))
            .map_err(uc_err)?;
        uc.reg_write(RegisterARM::XPSR, u64::from(1u32 << 24))
            .map_err(uc_err)?;
        uc.reg_write(RegisterARM::PC, u64::from(handler | 1))
            .map_err(uc_err)?;
        Ok(())
    }

    /// Exception return (ARMv7-M B1.5.8) to `exc_return`.
    fn exception_return(&mut self, exc_return: u32) -> Result<(), Error> {
        let active = self.uc.get_data_mut().nvic.active.pop();
        if active.is_none() || exc_return & 0xF == 0xD {
            // A return with nothing active, or to the process stack (the
            // images never use it): a UsageFault (INVPC) → HardFault.
            self.uc.get_data_mut().nvic.cfsr |= 1 << 18;
            return self.fault(0xFFFF_FFFF, false);
        }
        let sp = self.reg(RegisterARM::SP);
        let mut frame = [0u32; 8];
        for (i, w) in frame.iter_mut().enumerate() {
            match rd32(&self.uc, sp + 4 * i as u32) {
                Some(v) => *w = v,
                None => return self.fault(sp, false),
            }
        }
        let mut new_sp = sp + 32;
        if frame[7] & (1 << 9) != 0 {
            new_sp += 4;
        }
        let regs = [
            RegisterARM::R0,
            RegisterARM::R1,
            RegisterARM::R2,
            RegisterARM::R3,
            RegisterARM::R12,
            RegisterARM::LR,
        ];
        let uc = &mut self.uc;
        for (i, r) in regs.iter().enumerate() {
            uc.reg_write(*r, u64::from(frame[i])).map_err(uc_err)?;
        }
        uc.reg_write(RegisterARM::SP, u64::from(new_sp))
            .map_err(uc_err)?;
        uc.reg_write(RegisterARM::XPSR, u64::from(frame[7] & !0x1FF & !(1 << 9)))
            .map_err(uc_err)?;
        uc.reg_write(RegisterARM::PC, u64::from(frame[6] | 1))
            .map_err(uc_err)?;
        let st = uc.get_data_mut();
        st.now += 10 * st.cost;
        // A level line still asserted pends its interrupt again.
        for l in st.bus.irq_lines() {
            st.nvic.line(l);
        }
        Ok(())
    }

    /// A synchronous fault at `pc` (escalated to HardFault; lockup when
    /// HardFault or NMI is already active, ARMv7-M B1.5.15).
    fn fault(&mut self, addr: u32, _write: bool) -> Result<(), Error> {
        let pc = self.reg(RegisterARM::PC);
        let st = self.uc.get_data_mut();
        st.nvic.bfar = addr;
        st.nvic.hfsr |= 1 << 30;
        if st.nvic.active_priority() < 0 {
            self.core = CoreState::Lockup;
            self.lockup_at = Some(st.now);
            return Ok(());
        }
        self.enter_exception_at(exc::HARD_FAULT, pc)
    }

    /// Executes instructions until `until` (or an earlier stop).
    fn execute(&mut self, until: Ticks) -> Result<(), Error> {
        let pc = self.reg(RegisterARM::PC);
        let (cost, now) = {
            let st = self.uc.get_data_mut();
            let c = st.bus.clocks();
            st.cost = (TICKS_PER_S / c.hclk.max(1)).max(1);
            st.stop = None;
            (st.cost, st.now)
        };
        self.uc.get_data_mut().deadline = until;
        let r = self.uc.emu_start(u64::from(pc | 1), 0, 0, 0);
        // Flash fix-ups and stalls.
        self.apply_fixups();
        let stop = self.uc.get_data_mut().stop.take();
        let pc_now = self.reg(RegisterARM::PC);
        if std::env::var_os("TWIN_TRACE").is_some() {
            eprintln!(
                "exec pc {pc:#x} -> {pc_now:#x} until {until} ran {} r {r:?} stop {stop:?} core {:?}",
                (self.now() - now) / cost,
                self.core
            );
        }
        match r {
            Ok(()) => {}
            Err(e) => {
                use unicorn_engine::unicorn_const::uc_error as E;
                let addr = self.state().bus_error.unwrap_or(pc_now);
                match e {
                    E::FETCH_UNMAPPED | E::FETCH_PROT if pc_now >= 0xFFFF_FF00 => {
                        return self.exception_return(pc_now | 1);
                    }
                    E::READ_UNMAPPED
                    | E::WRITE_UNMAPPED
                    | E::FETCH_UNMAPPED
                    | E::READ_PROT
                    | E::WRITE_PROT
                    | E::FETCH_PROT
                    | E::READ_UNALIGNED
                    | E::WRITE_UNALIGNED
                    | E::FETCH_UNALIGNED
                    | E::EXCEPTION
                    | E::INSN_INVALID => {
                        self.uc.get_data_mut().bus_error = None;
                        self.uc.get_data_mut().nvic.cfsr |= 1 << 9; // PRECISERR
                        return self.fault(addr, false);
                    }
                    other => return Err(uc_err(other)),
                }
            }
        }
        if let Some(Stop::Fault(intno)) = stop {
            if pc_now >= 0xFFFF_FF00 {
                return self.exception_return(pc_now | 1);
            }
            if intno == 8 {
                // EXCP_EXCEPTION_EXIT (unicorn saw handler mode).
                return self.exception_return(pc_now | 1);
            }
            self.uc.get_data_mut().nvic.cfsr |= 1 << 16; // UNDEFINSTR
            return self.fault(pc_now, false);
        }
        if pc_now >= 0xFFFF_FF00 {
            return self.exception_return(pc_now | 1);
        }
        // Stopped early without a reason: `wfi` (unicorn halts the CPU with
        // the PC on the WFI or just after it).
        let st = self.state();
        if st.now < until && stop.is_none() {
            for at in [pc_now, pc_now.wrapping_sub(2)] {
                let mut b = [0u8; 2];
                if self.uc.mem_read(u64::from(at), &mut b).is_ok()
                    && u16::from_le_bytes(b) == 0xBF30
                {
                    self.core = CoreState::Sleeping;
                    self.set_reg(RegisterARM::PC, (at + 2) | 1)?;
                    break;
                }
            }
        }
        Ok(())
    }

    fn apply_fixups(&mut self) {
        let (fixups, stall) = {
            let st = self.uc.get_data_mut();
            (
                std::mem::take(&mut st.fixups),
                std::mem::take(&mut st.stall),
            )
        };
        for (a, v) in fixups {
            let _ = self.uc.mem_write(u64::from(a), &v.to_le_bytes());
        }
        if stall > 0 {
            // The CPU waits for the flash (it fetches from it): time goes on
            // for the peripherals, in order, while nothing executes.
            let end = self.now() + stall;
            while self.now() < end {
                let _ = self.service();
                let next = self.next_event().min(end).max(self.now() + 1);
                self.state_mut().now = next;
            }
        }
    }

    /// Moves the RTT up-channel 0 bytes to the decoder.
    fn drain_rtt(&mut self) {
        let Some(cb) = self.rtt else { return };
        let mut id = [0u8; 10];
        if self.uc.mem_read(u64::from(cb), &mut id).is_err() || &id != b"SEGGER RTT" {
            return;
        }
        let desc = cb + 24;
        let (Some(buf), Some(size), Some(wr), Some(rd)) = (
            rd32(&self.uc, desc + 4),
            rd32(&self.uc, desc + 8),
            rd32(&self.uc, desc + 12),
            rd32(&self.uc, desc + 16),
        ) else {
            return;
        };
        if size == 0 || wr == rd || wr >= size || rd >= size {
            return;
        }
        let mut out = Vec::new();
        let mut r = rd;
        while r != wr {
            let end = if wr > r { wr } else { size };
            if let Ok(v) = self
                .uc
                .mem_read_as_vec(u64::from(buf + r), (end - r) as usize)
            {
                out.extend(v);
            }
            r = if end == size { 0 } else { end };
        }
        let _ = self.uc.mem_write(u64::from(desc + 16), &r.to_le_bytes());
        self.log.write(&out);
        if let Some(&b) = out.last() {
            self.rtt_last = Some(b);
        }
        self.rtt_bytes.extend(out);
    }

    /// Every decoded log line so far (waits briefly for the decoder to
    /// catch up with the bytes already read).
    pub fn logs(&mut self) -> Vec<String> {
        self.drain_rtt();
        self.log.settle();
        self.log.lines.clone()
    }

    /// Log lines that contain `text`.
    pub fn log_lines(&mut self, text: &str) -> Vec<String> {
        self.logs()
            .into_iter()
            .filter(|l| l.contains(text))
            .collect()
    }

    /// Halts the core as a debug probe would (DBGMCU stop bits apply).
    pub fn debug_halt(&mut self, halt: bool) {
        let now = self.now();
        self.core = if halt {
            CoreState::DebugHalt
        } else {
            CoreState::Running
        };
        let st = self.uc.get_data_mut();
        st.bus.advance(now);
        st.bus.debug_halt = halt;
        let cr = st.bus.dbgmcu_cr;
        // DBG_TIM1_STOP (10), TIM2 (11), TIM3 (12), TIM4 (13).
        for (i, bit) in [(0usize, 10u32), (1, 11), (2, 12), (3, 13)] {
            st.bus.tim[i].halted = halt && cr & (1 << bit) != 0;
        }
    }

    /// The board's crystal fails now (see [`periph::Bus::crystal_fails`]):
    /// the clock security system's NMI, or a core without a clock.
    pub fn fail_crystal(&mut self) {
        let now = self.now();
        let st = self.uc.get_data_mut();
        let (nmi, lost) = st.bus.crystal_fails(now);
        if nmi {
            st.nvic.set_pending(exc::NMI);
        }
        if lost {
            self.core = CoreState::NoClock;
        }
    }

    /// Whether the core is locked up.
    pub fn lockup(&self) -> bool {
        self.core == CoreState::Lockup
    }

    /// Runs for `n` ticks of firmware time.
    pub fn run_ticks(&mut self, n: Ticks) -> Result<(), Error> {
        let until = self.now() + n;
        self.run_until_time(until, &mut |_| false)
    }

    /// Wires a machine model to the pins (see [`plant`]).
    pub fn attach_plant(&mut self, machine: machine_sim::Machine, wiring: plant::Wiring) {
        let now = self.now();
        self.plant = Some(plant::Plant::new(machine, wiring, now));
    }

    /// The operator taps a button on the touchscreen; 60 ms pass.
    pub fn tap(&mut self, name: &str) -> Result<(), Error> {
        if let Some(s) = &mut self.screen {
            s.tap(name)
                .map_err(|e| Error::Engine(format!("tap {name}: {e:?}")))?;
        }
        self.run_ms(60)
    }

    /// The operator types `value` into `field` and taps `apply`; 150 ms pass.
    pub fn enter(&mut self, field: &str, value: i32, apply: &str) -> Result<(), Error> {
        if let Some(s) = &mut self.screen {
            s.set_value(field, value)
                .map_err(|e| Error::Engine(format!("set {field}: {e:?}")))?;
        }
        self.tap(apply)?;
        self.run_ms(150)
    }

    /// Runs until the screen satisfies `pred` or `ms` pass.
    pub fn run_until_screen(
        &mut self,
        ms: u64,
        mut pred: impl FnMut(&hmi_proto::virtual_screen::VirtualScreen) -> bool,
    ) -> Result<bool, Error> {
        self.run_until(ms, |t| t.screen.as_ref().is_some_and(&mut pred))
    }

    /// A debugger sets the PC to `addr` (a call from the current context:
    /// LR is made invalid so that a return faults) and resumes.
    pub fn jump(&mut self, addr: u32) -> Result<(), Error> {
        self.set_reg(RegisterARM::LR, 0xFFFF_FFFF)?;
        self.set_reg(RegisterARM::PC, addr | 1)?;
        self.core = CoreState::Running;
        Ok(())
    }

    /// A u32 static of the firmware by (part of) its mangled name.
    pub fn static_u32(&self, name_part: &str) -> Option<u32> {
        let (a, _) = self.symbol_like(&[name_part])?;
        self.read_u32(a)
    }

    /// Everything needed to come back to this instant (core registers,
    /// RAM, flash, peripherals, screen, machine excluded).
    pub fn snapshot(&self) -> Result<Snapshot, Error> {
        let st = self.state();
        Ok(Snapshot {
            ctx: self.uc.context_init().map_err(uc_err)?,
            ram: self
                .uc
                .mem_read_as_vec(u64::from(RAM_BASE), RAM_SIZE as usize)
                .map_err(uc_err)?,
            flash: self.flash(),
            now: st.now,
            bus: st.bus.clone(),
            nvic: st.nvic.clone(),
            instructions: st.instructions,
            core: self.core,
            resets: self.resets.clone(),
            screen: self.screen.clone(),
            screen_next: self.screen_next,
            rtt_last: self.rtt_last,
        })
    }

    /// Goes back to a [`Twin::snapshot`]; the log decoder starts afresh.
    pub fn restore(&mut self, snap: &Snapshot) -> Result<(), Error> {
        self.uc.context_restore(&snap.ctx).map_err(uc_err)?;
        self.uc
            .mem_write(u64::from(RAM_BASE), &snap.ram)
            .map_err(uc_err)?;
        let now_flash = self.flash();
        for (i, (a, b)) in now_flash
            .chunks(periph::FLASH_PAGE as usize)
            .zip(snap.flash.chunks(periph::FLASH_PAGE as usize))
            .enumerate()
        {
            if a != b {
                let at = FLASH_BASE + i as u32 * periph::FLASH_PAGE;
                self.uc.mem_write(u64::from(at), b).map_err(uc_err)?;
            }
        }
        {
            let st = self.uc.get_data_mut();
            st.now = snap.now;
            st.bus = snap.bus.clone();
            st.nvic = snap.nvic.clone();
            st.instructions = snap.instructions;
            st.stop = None;
            st.stall = 0;
            st.fixups.clear();
            st.bus_error = None;
        }
        self.core = snap.core;
        self.lockup_at = None;
        self.resets = snap.resets.clone();
        self.screen = snap.screen.clone();
        self.screen_next = snap.screen_next;
        let decode = self.log.child.is_some();
        self.log = LogSink::start(&self.elf_path, decode, self.echo)?;
        // Mid-frame at the snapshot: the new decoder joins at the next
        // boundary.
        self.log.synced = snap.rtt_last.is_none_or(|b| b == 0);
        self.rtt_last = snap.rtt_last;
        self.rtt_bytes.clear();
        Ok(())
    }

    /// Pends an external interrupt as a debugger writing NVIC_ISPR would.
    pub fn pend_irq(&mut self, irq: u32) {
        self.state_mut().nvic.pend_irq(irq);
    }
}

fn port_index(port: char) -> usize {
    (port as u8).wrapping_sub(b'A').min(4) as usize
}

/// Writes the ELF's loadable contents (by load address) into the flash image.
fn load_flash(data: &[u8], flash: &mut [u8]) -> Result<(), Error> {
    use object::read::elf::{ElfFile32, ProgramHeader};
    let elf =
        ElfFile32::<object::Endianness>::parse(data).map_err(|e| Error::Elf(e.to_string()))?;
    let endian = elf.endian();
    for ph in elf.elf_program_headers() {
        if ph.p_type(endian) != object::elf::PT_LOAD {
            continue;
        }
        let paddr = ph.p_paddr(endian);
        let filesz = ph.p_filesz(endian) as usize;
        if filesz == 0 {
            continue;
        }
        let bytes = ph
            .data(endian, data)
            .map_err(|_| Error::Elf("segment data".into()))?;
        if paddr < FLASH_BASE || paddr + filesz as u32 > FLASH_BASE + FLASH_SIZE {
            continue;
        }
        let off = (paddr - FLASH_BASE) as usize;
        flash[off..off + filesz].copy_from_slice(&bytes[..filesz]);
    }
    let _ = elf.sections().count();
    let _ = elf.section_by_name(".vector_table").map(|s| s.address());
    Ok(())
}

fn map_peripherals(uc: &mut Unicorn<'static, State>) -> Result<(), Error> {
    // APB1, APB2, AHB peripherals.
    uc.mmio_map(
        0x4000_0000,
        0x24000,
        Some(|uc: &mut Unicorn<'_, State>, off: u64, size: usize| {
            let st = uc.get_data_mut();
            let a = 0x4000_0000 + off as u32;
            let word = st.bus.read(a & !3, st.now);
            u64::from(narrow(word, a, size))
        }),
        Some(
            |uc: &mut Unicorn<'_, State>, off: u64, size: usize, v: u64| {
                let st = uc.get_data_mut();
                let a = 0x4000_0000 + off as u32;
                let v = widen(v as u32, a, size);
                st.bus.write(a & !3, v, st.now);
                st.touched = true;
                if let Some(cmd) = st.bus.flash_cmd.take() {
                    do_flash_cmd(uc, cmd);
                }
                let st = uc.get_data_mut();
                st.stop.get_or_insert(Stop::Replan);
            },
        ),
    )
    .map_err(uc_err)?;
    // Peripheral bit-band alias (ARMv7-M A3.7; the HAL sets RCC enable bits
    // this way).
    uc.mmio_map(
        0x4200_0000,
        0x48_0000,
        Some(|uc: &mut Unicorn<'_, State>, off: u64, _size: usize| {
            let st = uc.get_data_mut();
            let byte = (off / 32) as u32;
            let bit = ((off % 32) / 4) as u32 + 8 * (byte & 3);
            let word = st.bus.read(0x4000_0000 + (byte & !3), st.now);
            u64::from((word >> bit) & 1)
        }),
        Some(
            |uc: &mut Unicorn<'_, State>, off: u64, _size: usize, v: u64| {
                let st = uc.get_data_mut();
                let byte = (off / 32) as u32;
                let bit = ((off % 32) / 4) as u32 + 8 * (byte & 3);
                let a = 0x4000_0000 + (byte & !3);
                let word = st.bus.read(a, st.now);
                let word = if v & 1 != 0 {
                    word | (1 << bit)
                } else {
                    word & !(1 << bit)
                };
                st.bus.write(a, word, st.now);
                st.stop.get_or_insert(Stop::Replan);
            },
        ),
    )
    .map_err(uc_err)?;
    // Private peripheral bus: SysTick, NVIC, SCB, DWT, DBGMCU.
    uc.mmio_map(
        0xE000_0000,
        0x10_0000,
        Some(|uc: &mut Unicorn<'_, State>, off: u64, size: usize| {
            let st = uc.get_data_mut();
            let a = 0xE000_0000 + off as u32;
            let word = st.ppb_read(a & !3);
            u64::from(narrow(word, a, size))
        }),
        Some(
            |uc: &mut Unicorn<'_, State>, off: u64, size: usize, v: u64| {
                let st = uc.get_data_mut();
                let a = 0xE000_0000 + off as u32;
                if size == 4 {
                    st.ppb_write(a, v as u32, 4);
                } else if (0xE000_E400..0xE000_E500).contains(&a)
                    || (0xE000_ED18..0xE000_ED24).contains(&a)
                {
                    // Byte-accessible priority registers.
                    st.ppb_write(a, v as u32, size);
                } else {
                    let w = widen(v as u32, a, size);
                    st.ppb_write(a & !3, w, 4);
                }
            },
        ),
    )
    .map_err(uc_err)?;
    Ok(())
}

fn narrow(word: u32, a: u32, size: usize) -> u32 {
    let shift = 8 * (a & 3);
    let v = word >> shift;
    match size {
        1 => v & 0xFF,
        2 => v & 0xFFFF,
        _ => v,
    }
}

fn widen(v: u32, a: u32, size: usize) -> u32 {
    match size {
        1 | 2 => v << (8 * (a & 3)),
        _ => v,
    }
}

/// A page erase by the FPEC: the page reads 0xFF, the CPU stalls tERASE.
fn do_flash_cmd(uc: &mut Unicorn<'_, State>, cmd: periph::FlashCmd) {
    let periph::FlashCmd::ErasePage(page) = cmd;
    let st = uc.get_data_mut();
    if !(FLASH_BASE..FLASH_BASE + FLASH_SIZE).contains(&page) {
        st.bus.flash.sr |= 0x10; // WRPRTERR-like: address outside flash
        return;
    }
    let n = st.bus.flash.ops;
    st.bus.flash.ops += 1;
    let cut = st.bus.flash.cut_at;
    if cut == Some((n, false)) {
        // Power lost while erasing: half the page erased (an interrupted
        // erase leaves it neither old nor blank).
        st.bus.flash.cut_fired = true;
        let _ = uc.mem_write(u64::from(page), &[0xFF; (periph::FLASH_PAGE / 2) as usize]);
        return;
    }
    let _ = uc.mem_write(u64::from(page), &[0xFF; periph::FLASH_PAGE as usize]);
    let st = uc.get_data_mut();
    st.bus.flash.log.push(FlashOp::Erase(page));
    st.bus.flash.sr |= 0x20; // EOP
    st.stall += periph::T_ERASE;
    if cut == Some((n, true)) {
        st.bus.flash.cut_fired = true;
    }
}

fn add_hooks(uc: &mut Unicorn<'static, State>) -> Result<(), Error> {
    // Every instruction: time, and the masks while an exception waits.
    // Every translated block, before it runs: time advances by its
    // instructions (Thumb-2: a half-word whose top five bits are 0b11101,
    // 0b11110 or 0b11111 starts a 32-bit instruction), and the run stops
    // here — before the block — for a re-plan, at the deadline, or when an
    // exception waiting behind a mask can now be taken. Unicorn checks for
    // a stop right after this hook, so a stopped block has not run.
    uc.add_block_hook(1, 0, |uc: &mut Unicorn<'_, State>, addr: u64, size: u32| {
        let st = uc.get_data_mut();
        if st.stop.is_some() || st.now >= st.deadline {
            let _ = uc.emu_stop();
            return;
        }
        if st.watch_masks {
            let pm = uc.reg_read(RegisterARM::PRIMASK).unwrap_or(0) & 1 != 0;
            let fm = uc.reg_read(RegisterARM::FAULTMASK).unwrap_or(0) & 1 != 0;
            let bp = uc.reg_read(RegisterARM::BASEPRI).unwrap_or(0) as u8;
            let st = uc.get_data_mut();
            let exec = st.nvic.execution_priority(pm, fm, bp);
            if st.nvic.top_pending().is_some_and(|(_, p)| p < exec) {
                st.watch_masks = false;
                st.stop.get_or_insert(Stop::Replan);
                let _ = uc.emu_stop();
                return;
            }
        }
        let key = (addr as u32, size);
        let n = match uc.get_data().block_insns.get(&key) {
            Some(&n) => n,
            None => {
                let mut bytes = vec![0u8; size as usize];
                let _ = uc.mem_read(addr, &mut bytes);
                let mut n = 0u64;
                let mut i = 0usize;
                while i + 1 < bytes.len() {
                    let hw = u16::from_le_bytes([bytes[i], bytes[i + 1]]);
                    i += if hw >> 11 >= 0b11101 { 4 } else { 2 };
                    n += 1;
                }
                let n = n.max(1);
                uc.get_data_mut().block_insns.insert(key, n);
                n
            }
        };
        let st = uc.get_data_mut();
        st.now += n * st.cost;
        st.instructions += n;
    })
    .map_err(uc_err)?;
    // Exceptions raised by the instruction set (UDF, BKPT, SVC, aborts).
    uc.add_intr_hook(|uc: &mut Unicorn<'_, State>, intno: u32| {
        let st = uc.get_data_mut();
        st.stop = Some(Stop::Fault(intno));
        let _ = uc.emu_stop();
    })
    .map_err(uc_err)?;
    // Writes into the flash array: the FPEC programs half-words only when
    // PG is set and the half-word is erased (RM0008 §3.3.3, PM0075 §2.3.3).
    uc.add_mem_hook(
        HookType::MEM_WRITE,
        u64::from(FLASH_BASE),
        u64::from(FLASH_BASE + FLASH_SIZE - 1),
        |uc: &mut Unicorn<'_, State>, _t: MemType, addr: u64, size: usize, value: i64| {
            let a = addr as u32 & !1;
            let mut old = [0u8; 2];
            let _ = uc.mem_read(u64::from(a), &mut old);
            let old = u16::from_le_bytes(old);
            let st = uc.get_data_mut();
            let fc = &mut st.bus.flash;
            let pg = fc.cr & 1 != 0 && fc.cr & 0x80 == 0;
            let new = value as u16;
            if !pg || size != 2 {
                // Not programming: the array does not change.
                st.fixups.push((a, old));
                return true;
            }
            let n = fc.ops;
            fc.ops += 1;
            if fc.cut_at == Some((n, false)) {
                fc.cut_fired = true;
                st.fixups.push((a, old));
                st.stop.get_or_insert(Stop::Replan);
                return true;
            }
            if old != 0xFFFF && new != 0 {
                // PGERR: not erased; nothing written.
                fc.sr |= 0x04;
                st.fixups.push((a, old));
            } else {
                fc.sr |= 0x20; // EOP
                fc.log.push(FlashOp::Program(a, new));
                st.stall += periph::T_PROG;
            }
            if fc.cut_at == Some((n, true)) {
                fc.cut_fired = true;
            }
            st.stop.get_or_insert(Stop::Replan);
            true
        },
    )
    .map_err(uc_err)?;
    // Accesses to unmapped memory: note the address for BFAR.
    uc.add_mem_hook(
        HookType::MEM_UNMAPPED,
        1,
        0,
        |uc: &mut Unicorn<'_, State>, _t: MemType, addr: u64, _size: usize, _v: i64| {
            uc.get_data_mut().bus_error = Some(addr as u32);
            false
        },
    )
    .map_err(uc_err)?;
    Ok(())
}

impl LogSink {
    fn start(elf: &Path, decode: bool, echo: bool) -> Result<Self, Error> {
        if !decode {
            return Ok(Self {
                frames: 0,
                synced: true,
                prev: 0,
                stdin: None,
                child: None,
                rx: None,
                lines: Vec::new(),
                last_write: Instant::now(),
            });
        }
        let mut child = Command::new("defmt-print")
            .arg("-e")
            .arg(elf)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| {
                io::Error::new(
                    e.kind(),
                    format!("defmt-print: {e} (install it with `cargo install defmt-print --locked`; bash .ci/run does)"),
                )
            })?;
        let stdin = child.stdin.take();
        let out = child
            .stdout
            .take()
            .ok_or_else(|| io::Error::other("no defmt-print stdout"))?;
        let (tx, rx) = mpsc::channel();
        thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if echo {
                    eprintln!("twin| {line}");
                }
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Ok(Self {
            frames: 0,
            synced: true,
            prev: 0,
            stdin,
            child: Some(child),
            rx: Some(rx),
            lines: Vec::new(),
            last_write: Instant::now(),
        })
    }

    fn write(&mut self, bytes: &[u8]) {
        let mut bytes = bytes;
        if !self.synced {
            match bytes.iter().position(|&b| b == 0) {
                Some(i) => {
                    bytes = &bytes[i + 1..];
                    self.synced = true;
                }
                None => return,
            }
        }
        // A frame ends with a 0x00 after its bytes; a 0x00 after a 0x00 (or
        // at the start of the stream, as defmt-rtt begins) is no frame.
        for &b in bytes {
            if b == 0 && self.prev != 0 {
                self.frames += 1;
            }
            self.prev = b;
        }
        if let Some(s) = &mut self.stdin {
            let _ = s.write_all(bytes);
            let _ = s.flush();
            self.last_write = Instant::now();
        }
        self.poll();
    }

    /// Ends a frame cut short (the decoder drops it; no line expected).
    fn terminate(&mut self) {
        if let Some(s) = &mut self.stdin {
            let _ = s.write_all(&[0]);
            let _ = s.flush();
        }
        self.prev = 0;
    }

    fn poll(&mut self) {
        if let Some(rx) = &self.rx {
            while let Ok(l) = rx.try_recv() {
                self.lines.push(l);
            }
        }
    }

    /// Waits until the decoder has printed a line for every complete frame
    /// sent (deterministic whatever the host's load; 20 s at most, reached
    /// only if the decoder fails).
    fn settle(&mut self) {
        let Some(rx) = &self.rx else { return };
        let deadline = Instant::now() + Duration::from_secs(20);
        while self.lines.len() < self.frames && Instant::now() < deadline {
            if let Ok(l) = rx.recv_timeout(Duration::from_millis(50)) {
                self.lines.push(l);
            }
        }
        while let Ok(l) = rx.try_recv() {
            self.lines.push(l);
        }
    }
}

impl Drop for LogSink {
    fn drop(&mut self) {
        self.stdin = None;
        if let Some(c) = &mut self.child {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

// Shared handle used by watchers that need the twin across closures.
/// A shared, interior-mutable cell for values a watcher records.
pub type Shared<T> = Rc<RefCell<T>>;

/// `NEVER` re-exported for the plant.
pub const NEVER_TICKS: Ticks = NEVER;
