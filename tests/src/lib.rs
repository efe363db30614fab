//! Runs the firmware's QEMU board and talks to it like the machine does.
//!
//! [`Firmware::boot`] starts `qemu-system-arm -machine netduino2` with
//! the firmware ELF, connects the emulated USART1 to a TCP socket on the
//! loopback interface (the touchscreen side), and decodes the firmware's
//! defmt log (semihosting on QEMU's stdout) with `defmt-print`.
//!
//! Used by the integration tests in `tests/tests/` and by `cargo xtask qemu`.

pub mod browser;
pub mod drive;
pub mod images;
pub mod screen_shots;
pub mod screen_web;
pub mod thumb;

use std::io::{self, BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Mutex, OnceLock};
use std::thread;
use std::time::{Duration, Instant};

/// The Nextion/TJC frame terminator.
pub const TERMINATOR: [u8; 3] = [0xFF; 3];

/// Splits what the firmware sent into complete instructions (terminator
/// removed); an unterminated tail is left out.
pub fn instructions(bytes: &[u8]) -> Vec<&[u8]> {
    let mut out = Vec::new();
    let mut rest = bytes;
    while let Some(end) = rest.windows(3).position(|w| w == TERMINATOR) {
        let (head, tail) = rest.split_at(end);
        out.push(head);
        rest = tail.get(3..).unwrap_or(&[]);
    }
    out
}

/// The workspace root (this crate lives in `<root>/tests`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// The QEMU machine the QEMU board runs on: QEMU's STM32F205 model (128 KB
/// of SRAM, of which the board uses the real board's 20 KB;
/// `firmware/src/board/qemu/mod.rs`).
pub const QEMU_MACHINE: &str = "netduino2";

/// The QEMU board's cargo features (both machines and the drum driver's
/// link, as on the real board: the settings choose).
pub const QEMU_FEATURES: &str = "board-qemu";

/// The name the QEMU board's ELF is kept under
/// (`target/images/<name>/firmware`, [`images`]).
pub const QEMU_IMAGE: &str = "qemu";

/// Builds the QEMU board (release, in the one firmware target directory,
/// [`images`]) once per process and returns the ELF path.
/// `FIRMWARE_QEMU_ELF` names a prebuilt ELF instead (used by `cargo xtask
/// test`, which has just built it).
pub fn qemu_firmware_elf() -> io::Result<PathBuf> {
    static BUILT: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    if let Some(elf) = std::env::var_os("FIRMWARE_QEMU_ELF") {
        return Ok(PathBuf::from(elf));
    }
    BUILT
        .get_or_init(|| {
            images::build(
                QEMU_IMAGE,
                &["--no-default-features", "--features", QEMU_FEATURES],
            )
            .map_err(|e| e.to_string())
        })
        .clone()
        .map_err(io::Error::other)
}

/// How to start the emulation.
#[derive(Clone, Debug)]
pub struct BootOptions {
    /// Firmware-side time limit (`run_ms=` on the semihosting command line):
    /// the firmware exits by itself when its uptime reaches it.
    pub run_ms: Option<u32>,
    /// Print each decoded log line to stderr as it arrives.
    pub echo_logs: bool,
    /// The host file behind the board's settings flash (`flash=`); it
    /// survives a reboot of the emulated board.
    pub flash: Option<PathBuf>,
    /// Scenario words for the simulated machine (`gear=2`, `stall=3000`, …;
    /// see `firmware/src/board/qemu/scenario.rs`).
    pub scenario: Vec<String>,
    /// Run in QEMU's instruction-counting mode with idle time skipped
    /// (`-icount shift=0,sleep=off`): deterministic and faster than real
    /// time. Without [`lockstep`](Self::lockstep) the firmware runs as fast
    /// as it can, ahead of any touchscreen.
    pub accelerated: bool,
    /// Lock-step with the test (implies `accelerated`): the QEMU board
    /// blocks at the start of every control period until the test allows it
    /// (a byte in a host FIFO, `gate=PATH`), so firmware time is exactly the
    /// time the test has pumped: the screen answers in firmware time, and
    /// no host load can make a control period late. The default.
    pub lockstep: bool,
    /// A virtual drum driver on USART2 at this baud rate ([`drive`];
    /// lock-step only; the firmware's settings must name the driver).
    pub drive_baud: Option<u32>,
}

impl Default for BootOptions {
    fn default() -> Self {
        Self {
            run_ms: Some(10_000),
            echo_logs: false,
            flash: None,
            scenario: Vec::new(),
            accelerated: false,
            lockstep: true,
            drive_baud: None,
        }
    }
}

/// The control period of the QEMU board, and so the firmware time one
/// lock-step token allows.
pub const LOCKSTEP_PERIOD: Duration = Duration::from_millis(10);

/// Control periods [`Bench::pump`] allows at once while the screen has
/// nothing to send.
const LOCKSTEP_BATCH: usize = 5;

/// Most screen bytes one lock-step period carries (the QEMU board's
/// `GATE_BYTES`).
pub const GATE_BYTES: usize = 32;

/// The host end of the lock-step gate: a FIFO the QEMU board reads one byte
/// from per control period.
struct Gate {
    fifo: std::fs::File,
    path: PathBuf,
}

impl Gate {
    fn create() -> io::Result<Self> {
        static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        // Short: the QEMU board keeps at most 32 bytes of the path.
        let path = PathBuf::from(format!("/tmp/tpg-{}-{n}", std::process::id()));
        let fifo = make_fifo(&path)?;
        Ok(Self { fifo, path })
    }

    /// Allows one control period carrying the screen's bytes and the
    /// virtual driver's part of the record.
    fn allow_one(
        &self,
        to_firmware: &mut std::collections::VecDeque<u8>,
        drive: &[u8],
    ) -> io::Result<()> {
        let n = to_firmware.len().min(GATE_BYTES);
        let mut msg = vec![u8::try_from(n).unwrap_or(0)];
        msg.extend(to_firmware.drain(..n));
        msg.extend_from_slice(drive);
        (&self.fifo).write_all(&msg)
    }
}

/// Creates a FIFO at `path` and opens it for reading and writing (Linux:
/// never blocks, and QEMU's own open finds a peer).
fn make_fifo(path: &Path) -> io::Result<std::fs::File> {
    {
        let _ = std::fs::remove_file(path);
        let status = Command::new("mkfifo").arg(path).status()?;
        if !status.success() {
            return Err(io::Error::other(format!(
                "mkfifo {}: {status}",
                path.display()
            )));
        }
        // Read and write: opening a FIFO so never blocks (Linux), and QEMU's
        // own open for reading finds a writer.
        std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
    }
}

impl Gate {
    /// Tokens written and not yet taken by the firmware.
    fn pending(&self) -> usize {
        rustix::io::ioctl_fionread(&self.fifo)
            .ok()
            .and_then(|n| usize::try_from(n).ok())
            .unwrap_or(0)
    }

    /// Allows `periods` control periods; the first ones carry the screen's
    /// bytes waiting in `to_firmware` (at most [`GATE_BYTES`] each, the
    /// QEMU board's message format: a count, then the bytes).
    fn allow(
        &self,
        periods: usize,
        to_firmware: &mut std::collections::VecDeque<u8>,
    ) -> io::Result<()> {
        let mut msg = Vec::with_capacity(periods);
        for _ in 0..periods {
            let n = to_firmware.len().min(GATE_BYTES);
            msg.push(u8::try_from(n).unwrap_or(0));
            msg.extend(to_firmware.drain(..n));
        }
        (&self.fifo).write_all(&msg)
    }
}

impl Drop for Gate {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// A running emulation of the QEMU board.
pub struct Firmware {
    qemu: Child,
    printer: Child,
    serial: TcpStream,
    serial_in: Vec<u8>,
    serial_taken: usize,
    logs_rx: Receiver<String>,
    logs: Mutex<Vec<String>>,
    gate: Option<Gate>,
    /// Lock-step: the screen's bytes for the next periods.
    to_firmware: Mutex<std::collections::VecDeque<u8>>,
    /// QEMU has exited (seen while waiting for a period to be taken).
    ended: std::sync::atomic::AtomicBool,
    /// Lock-step: control periods allowed since boot.
    allowed: std::sync::atomic::AtomicUsize,
    /// The virtual drum driver on USART2, and its truth records.
    drive: Option<(Mutex<drive::DriveBench>, Receiver<drive::Truth>, PathBuf)>,
    /// QEMU's stdout has closed (it exited).
    exited: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

fn tool_missing(tool: &str, hint: &str) -> io::Error {
    io::Error::new(
        io::ErrorKind::NotFound,
        format!("`{tool}` was not found on PATH: {hint}"),
    )
}

impl Firmware {
    /// Starts QEMU with `elf`, connects USART1 and the log decoder.
    pub fn boot(elf: &Path, options: &BootOptions) -> io::Result<Self> {
        // We listen; QEMU connects as the client, so there is no port race.
        let listener = TcpListener::bind("127.0.0.1:0")?;
        let port = listener.local_addr()?.port();
        let mut semihosting = String::from("enable=on,target=native,arg=firmware");
        if let Some(ms) = options.run_ms {
            semihosting.push_str(&format!(",arg=run_ms={ms}"));
        }
        if let Some(flash) = &options.flash {
            semihosting.push_str(&format!(",arg=flash={}", flash.display()));
        }
        let gate = if options.lockstep {
            let gate = Gate::create()?;
            semihosting.push_str(&format!(",arg=gate={}", gate.path.display()));
            Some(gate)
        } else {
            None
        };
        // The virtual driver: USART2 to a second socket, the truth FIFO.
        let drive_listener = match (options.drive_baud, &gate) {
            (Some(_), Some(g)) => {
                semihosting.push_str(",arg=drive_link=1");
                let truth_path = PathBuf::from(format!("{}t", g.path.display()));
                let truth = make_fifo(&truth_path)?;
                let l = TcpListener::bind("127.0.0.1:0")?;
                Some((l, truth, truth_path))
            }
            _ => None,
        };
        for word in &options.scenario {
            semihosting.push_str(&format!(",arg={word}"));
        }
        let mut qemu = Command::new("qemu-system-arm");
        if options.accelerated || options.lockstep {
            qemu.args(["-icount", "shift=0,sleep=off"]);
        }
        let qemu = qemu
            .args(["-machine", QEMU_MACHINE, "-cpu", "cortex-m3"])
            .args(["-display", "none", "-monitor", "none"])
            .args(["-semihosting-config", &semihosting])
            .arg("-chardev")
            .arg(format!(
                "socket,id=hmi,host=127.0.0.1,port={port},server=off,nodelay=on"
            ))
            .args(["-serial", "chardev:hmi"]);
        if let Some((l, _, _)) = &drive_listener {
            qemu.arg("-chardev")
                .arg(format!(
                    "socket,id=drive,host=127.0.0.1,port={},server=off,nodelay=on",
                    l.local_addr()?.port()
                ))
                .args(["-serial", "chardev:drive"]);
        }
        let mut qemu = qemu
            .arg("-kernel")
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| match e.kind() {
                io::ErrorKind::NotFound => tool_missing(
                    "qemu-system-arm",
                    "install it with `apt-get install qemu-system-arm` (bash .ci/run does)",
                ),
                _ => e,
            })?;
        let qemu_out = qemu
            .stdout
            .take()
            .ok_or_else(|| io::Error::other("no QEMU stdout"))?;
        let mut printer = Command::new("defmt-print")
            .arg("-e")
            .arg(elf)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| match e.kind() {
                io::ErrorKind::NotFound => tool_missing(
                    "defmt-print",
                    "install it with `cargo install defmt-print --locked` (bash .ci/run does)",
                ),
                _ => e,
            })?;
        let mut printer_in = printer
            .stdin
            .take()
            .ok_or_else(|| io::Error::other("no defmt-print stdin"))?;
        let exited = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let exited_flag = exited.clone();
        thread::spawn(move || {
            let mut qemu_out = qemu_out;
            let _ = io::copy(&mut qemu_out, &mut printer_in);
            exited_flag.store(true, std::sync::atomic::Ordering::Relaxed);
        });
        let printer_out = printer
            .stdout
            .take()
            .ok_or_else(|| io::Error::other("no defmt-print stdout"))?;
        let (tx, logs_rx) = mpsc::channel();
        let echo = options.echo_logs;
        thread::spawn(move || {
            for line in BufReader::new(printer_out).lines().map_while(Result::ok) {
                if echo {
                    eprintln!("{line}");
                }
                if tx.send(line).is_err() {
                    break;
                }
            }
        });

        listener.set_nonblocking(true)?;
        let deadline = Instant::now() + Duration::from_secs(10);
        let serial = loop {
            match listener.accept() {
                Ok((stream, _)) => break stream,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    if let Some(status) = qemu.try_wait()? {
                        return Err(io::Error::other(format!(
                            "QEMU exited before connecting its USART1: {status}"
                        )));
                    }
                    if Instant::now() > deadline {
                        let _ = qemu.kill();
                        return Err(io::Error::other("QEMU did not connect its USART1"));
                    }
                    thread::sleep(Duration::from_millis(10));
                }
                Err(e) => return Err(e),
            }
        };
        serial.set_nonblocking(false)?;
        serial.set_nodelay(true)?;
        let drive = match (drive_listener, options.drive_baud) {
            (Some((listener, truth, truth_path)), Some(baud)) => {
                listener.set_nonblocking(true)?;
                let deadline = Instant::now() + Duration::from_secs(10);
                let usart2 = loop {
                    match listener.accept() {
                        Ok((stream, _)) => break stream,
                        Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                            if Instant::now() > deadline {
                                let _ = qemu.kill();
                                return Err(io::Error::other("QEMU did not connect its USART2"));
                            }
                            thread::sleep(Duration::from_millis(10));
                        }
                        Err(e) => return Err(e),
                    }
                };
                let (tx, rx) = mpsc::channel();
                thread::spawn(move || {
                    let mut truth = truth;
                    while let Ok(t) = drive::read_truth(&mut truth) {
                        if tx.send(t).is_err() {
                            break;
                        }
                    }
                });
                Some((
                    Mutex::new(drive::DriveBench::new(usart2, baud)?),
                    rx,
                    truth_path,
                ))
            }
            _ => None,
        };
        Ok(Self {
            qemu,
            printer,
            serial,
            serial_in: Vec::new(),
            serial_taken: 0,
            logs_rx,
            logs: Mutex::new(Vec::new()),
            gate,
            to_firmware: Mutex::new(std::collections::VecDeque::new()),
            ended: std::sync::atomic::AtomicBool::new(false),
            allowed: std::sync::atomic::AtomicUsize::new(0),
            drive,
            exited,
        })
    }

    /// The virtual drum driver (none without [`BootOptions::drive_baud`]).
    pub fn drive(&self) -> Option<std::sync::MutexGuard<'_, drive::DriveBench>> {
        self.drive.as_ref().and_then(|(d, _, _)| d.lock().ok())
    }

    /// Lock-step with the virtual driver: one period at a time — wait for
    /// the truth record of the period that ended (the firmware now waits
    /// at the gate), answer its requests, allow the next period.
    fn allow_driven(&self, gate: &Gate, periods: usize) -> io::Result<()> {
        let Some((drive, truth_rx, _)) = &self.drive else {
            return Ok(());
        };
        for _ in 0..periods {
            let deadline = Instant::now() + Duration::from_secs(60);
            let truth = loop {
                match truth_rx.recv_timeout(Duration::from_millis(20)) {
                    Ok(t) => break t,
                    Err(RecvTimeoutError::Timeout) => {
                        if self.exited.load(std::sync::atomic::Ordering::Relaxed) {
                            self.ended.store(true, std::sync::atomic::Ordering::Relaxed);
                            return Ok(());
                        }
                        if Instant::now() > deadline {
                            return Err(io::Error::other(
                                "the firmware sent no truth record for 60 s",
                            ));
                        }
                    }
                    Err(RecvTimeoutError::Disconnected) => {
                        return Err(io::Error::other("the truth FIFO closed"))
                    }
                }
            };
            let part = drive
                .lock()
                .map_err(|_| io::Error::other("poisoned"))?
                .period(&truth)?;
            let mut queue = self
                .to_firmware
                .lock()
                .map_err(|_| io::Error::other("poisoned"))?;
            self.allowed
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            gate.allow_one(&mut queue, &part)?;
        }
        Ok(())
    }

    /// Lock-step: allows the firmware `periods` more control periods.
    /// Without lock-step, or once QEMU has ended (its run limit: nobody
    /// reads the FIFO any more, a full one would block), nothing.
    pub fn allow(&self, periods: usize) -> io::Result<()> {
        if self.ended.load(std::sync::atomic::Ordering::Relaxed) {
            return Ok(());
        }
        match &self.gate {
            Some(g) if self.drive.is_some() => self.allow_driven(g, periods),
            Some(g) => {
                let mut queue = self
                    .to_firmware
                    .lock()
                    .map_err(|_| io::Error::other("poisoned"))?;
                self.allowed
                    .fetch_add(periods, std::sync::atomic::Ordering::Relaxed);
                g.allow(periods, &mut queue)
            }
            None => Ok(()),
        }
    }

    /// Lock-step: the decoded log lines up to the firmware time the test
    /// has allowed, waiting (without allowing more) for the decoder to
    /// deliver them. The log reaches the test through QEMU's semihosting,
    /// `defmt-print` and a reader thread: on a busy host it trails the
    /// firmware, and [`Firmware::logs`] right after a pump may miss the
    /// last lines (a test of the Stop saw no line after it under load).
    /// The QEMU board logs at least every 100 ms (its `sim:` lines), so
    /// this waits for a line within 150 ms of the allowed time; up to 30 s
    /// of host time, then returns what it has. Without lock-step (or once
    /// QEMU has ended), [`Firmware::logs`].
    pub fn logs_caught_up(&self) -> Vec<String> {
        let allowed = self.allowed.load(std::sync::atomic::Ordering::Relaxed);
        if self.gate.is_none() || self.ended.load(std::sync::atomic::Ordering::Relaxed) {
            return self.logs();
        }
        let target_ms = u32::try_from(allowed.saturating_mul(10))
            .unwrap_or(u32::MAX)
            .saturating_sub(150);
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            let newest = self
                .logs()
                .iter()
                .rev()
                .find_map(|l| log_time_ms(l))
                .unwrap_or(0);
            if newest >= target_ms || Instant::now() > deadline {
                return self.logs();
            }
            let _ = self.drain_logs(Duration::from_millis(5));
        }
    }

    /// Lock-step: waits until the firmware has taken every period allowed
    /// (it then runs the last one and stops at the next).
    /// Returns at once if QEMU has ended (its run limit).
    pub fn wait_taken(&mut self) -> io::Result<()> {
        let deadline = Instant::now() + Duration::from_secs(60);
        while self.pending_periods() > 0 {
            if self.qemu.try_wait()?.is_some() {
                self.ended.store(true, std::sync::atomic::Ordering::Relaxed);
                return Ok(());
            }
            if Instant::now() > deadline {
                return Err(io::Error::other(
                    "the firmware stopped taking control periods",
                ));
            }
            thread::sleep(Duration::from_micros(20));
        }
        Ok(())
    }

    /// Lock-step: the firmware's time, ms: the control periods the test
    /// has allowed since boot × 10 ms (exact: the firmware takes each period
    /// only when allowed, whatever the host's load). `None` without
    /// lock-step.
    pub fn now_ms(&self) -> Option<u32> {
        self.gate.as_ref()?;
        let allowed = self.allowed.load(std::sync::atomic::Ordering::Relaxed);
        Some(u32::try_from(allowed.saturating_mul(10)).unwrap_or(u32::MAX))
    }

    /// Lock-step: control periods allowed and not yet taken (0 without
    /// lock-step).
    pub fn pending_periods(&self) -> usize {
        self.gate.as_ref().map_or(0, Gate::pending)
    }

    /// `true` in lock-step.
    pub fn is_lockstep(&self) -> bool {
        self.gate.is_some()
    }

    /// Lets the firmware run free (QEMU's `-icount`, as fast as it can):
    /// the gate's end of file.
    pub fn release(&mut self) {
        self.gate = None;
    }

    /// Lock-step: keeps the firmware going while a caller waits for it
    /// (one period at a time, only when the last was taken).
    fn keep_going(&self) -> io::Result<()> {
        if self.gate.is_some() && self.pending_periods() == 0 {
            self.allow(1)?;
        }
        Ok(())
    }

    /// Real time, paced by the wall clock: the lock-step gate is handed
    /// to a thread that allows one control period every 10 ms of host
    /// time, and the screen's bytes go straight to the emulated USART1
    /// (as on a real line, whenever they come; do not use [`Bench`]'s
    /// pumping after this). When the host keeps up, firmware time is real
    /// time; when it does not (a busy machine), the firmware runs slower,
    /// every control period whole, never a period late or a burst of
    /// periods to catch up. (QEMU without instruction counting follows the
    /// host's clock instead, and a descheduled QEMU delivers SysTick late:
    /// under load the firmware's control periods overran and its planting
    /// figures drifted from the simulator's — precision CV 7.1 % against
    /// 0.57 % in a browser test.) Needs a board booted in lock-step (the
    /// default); the pacing ends when QEMU exits.
    pub fn pace_in_real_time(&mut self) -> io::Result<()> {
        let Some(gate) = self.gate.take() else {
            return Err(io::Error::other("pacing needs a board booted in lock-step"));
        };
        let exited = self.exited.clone();
        thread::spawn(move || {
            let start = Instant::now();
            let mut allowed: u128 = 0;
            while !exited.load(std::sync::atomic::Ordering::Relaxed) {
                let due = start.elapsed().as_millis() / LOCKSTEP_PERIOD.as_millis();
                // At most two periods waiting: a board behind the clock
                // runs on at its own pace, it is not sent a backlog.
                while allowed < due && gate.pending() < 2 {
                    if (&gate.fifo).write_all(&[0]).is_err() {
                        return;
                    }
                    allowed += 1;
                }
                allowed = allowed.max(due);
                thread::sleep(Duration::from_millis(2));
            }
        });
        Ok(())
    }

    /// A second handle on the socket of the firmware's USART1, for a
    /// screen served elsewhere (the browser screen's server,
    /// [`screen_web::ScreenServer`]). Whoever holds it reads the firmware's
    /// bytes: do not also call the `read_serial_*` methods.
    pub fn serial_stream(&self) -> io::Result<TcpStream> {
        self.serial.try_clone()
    }

    /// Sends bytes into the firmware's USART1 (the touchscreen's TX line);
    /// in lock-step they go with the next allowed periods.
    pub fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        if self.gate.is_some() {
            self.to_firmware
                .lock()
                .map_err(|_| io::Error::other("poisoned"))?
                .extend(bytes.iter().copied());
            return Ok(());
        }
        self.serial.write_all(bytes)?;
        self.serial.flush()
    }

    /// Reads what the firmware sent on USART1 until `done` accepts the bytes
    /// received so far (all of them, from the start of the run), or `timeout`.
    pub fn read_serial_until(
        &mut self,
        timeout: Duration,
        mut done: impl FnMut(&[u8]) -> bool,
    ) -> io::Result<Vec<u8>> {
        let deadline = Instant::now() + timeout;
        let mut chunk = [0u8; 256];
        while !done(&self.serial_in) {
            self.keep_going()?;
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!(
                        "no matching reply within {timeout:?}; received {:02x?}",
                        self.serial_in
                    ),
                ));
            }
            let step = if self.gate.is_some() { 2 } else { 100 };
            self.serial
                .set_read_timeout(Some(left.min(Duration::from_millis(step))))?;
            match self.serial.read(&mut chunk) {
                Ok(0) => {
                    return Err(io::Error::new(
                        io::ErrorKind::UnexpectedEof,
                        "QEMU closed USART1",
                    ))
                }
                Ok(n) => self
                    .serial_in
                    .extend_from_slice(chunk.get(..n).unwrap_or(&[])),
                Err(e)
                    if e.kind() == io::ErrorKind::WouldBlock
                        || e.kind() == io::ErrorKind::TimedOut => {}
                Err(e) => return Err(e),
            }
        }
        Ok(self.serial_in.clone())
    }

    /// Reads what the firmware sent on USART1 for up to `wait`, and returns
    /// the bytes not returned by an earlier call.
    pub fn read_serial_new(&mut self, wait: Duration) -> io::Result<Vec<u8>> {
        let mut chunk = [0u8; 512];
        if wait.is_zero() {
            // Whatever has arrived, without waiting.
            self.serial.set_nonblocking(true)?;
            loop {
                match self.serial.read(&mut chunk) {
                    Ok(0) => break,
                    Ok(n) => self
                        .serial_in
                        .extend_from_slice(chunk.get(..n).unwrap_or(&[])),
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                    Err(e) => {
                        self.serial.set_nonblocking(false)?;
                        return Err(e);
                    }
                }
            }
            self.serial.set_nonblocking(false)?;
        } else {
            self.serial.set_read_timeout(Some(wait))?;
            match self.serial.read(&mut chunk) {
                Ok(0) => {}
                Ok(n) => self
                    .serial_in
                    .extend_from_slice(chunk.get(..n).unwrap_or(&[])),
                Err(e)
                    if e.kind() == io::ErrorKind::WouldBlock
                        || e.kind() == io::ErrorKind::TimedOut => {}
                Err(e) => return Err(e),
            }
        }
        let new = self
            .serial_in
            .get(self.serial_taken..)
            .unwrap_or(&[])
            .to_vec();
        self.serial_taken = self.serial_in.len();
        Ok(new)
    }

    /// Every decoded log line received so far.
    pub fn logs(&self) -> Vec<String> {
        while self.drain_logs(Duration::from_millis(0)).is_some() {}
        self.logs.lock().map(|l| l.clone()).unwrap_or_default()
    }

    /// Every byte the firmware has sent on USART1 so far (as read by
    /// [`Self::read_serial_until`]).
    pub fn serial_received(&self) -> &[u8] {
        &self.serial_in
    }

    fn drain_logs(&self, wait: Duration) -> Option<String> {
        match self.logs_rx.recv_timeout(wait) {
            Ok(line) => {
                if let Ok(mut logs) = self.logs.lock() {
                    logs.push(line.clone());
                }
                Some(line)
            }
            Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => None,
        }
    }

    /// Waits for a decoded log line that satisfies `pred`.
    pub fn wait_log(&self, timeout: Duration, pred: impl Fn(&str) -> bool) -> Option<String> {
        let deadline = Instant::now() + timeout;
        if let Ok(logs) = self.logs.lock() {
            if let Some(line) = logs.iter().find(|l| pred(l)) {
                return Some(line.clone());
            }
        }
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            let wait = if self.gate.is_some() {
                if self.keep_going().is_err() {
                    return None;
                }
                left.min(Duration::from_millis(2))
            } else {
                left
            };
            if let Some(line) = self.drain_logs(wait) {
                if pred(&line) {
                    return Some(line);
                }
            }
        }
    }

    /// Waits for QEMU to exit by itself (the firmware's run limit), then
    /// returns its exit status and every decoded log line.
    pub fn wait_exit(mut self, timeout: Duration) -> io::Result<(ExitStatus, Vec<String>)> {
        // Lock-step ends here: the rest of the run goes at QEMU's pace.
        self.release();
        let deadline = Instant::now() + timeout;
        let status = loop {
            if let Some(status) = self.qemu.try_wait()? {
                break status;
            }
            if Instant::now() > deadline {
                let _ = self.qemu.kill();
                let _ = self.qemu.wait();
                return Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    "the firmware did not end its run in time",
                ));
            }
            let _ = self.drain_logs(Duration::from_millis(20));
        };
        // QEMU is gone: the decoder sees end of input and finishes.
        let _ = self.printer.wait();
        while self.drain_logs(Duration::from_millis(200)).is_some() {}
        let logs = self.logs.lock().map(|l| l.clone()).unwrap_or_default();
        check_stack(&logs)?;
        Ok((status, logs))
    }
}

/// The QEMU board reports how deep its stack went (it paints the stack at
/// reset) after `init` and when a run ends by itself; a run whose stack
/// reached the statics fails here, whatever else it showed (every
/// [`Firmware::wait_exit`]; tests that stop QEMU themselves call it). The
/// QEMU board has the real board's RAM and statics layout, so its figures
/// are the real board's (`tests/tests/qemu_board.rs`).
pub fn check_stack(logs: &[String]) -> io::Result<()> {
    for line in logs.iter().filter(|l| l.contains(" stack: ")) {
        let used = number_after(line, "stack: ");
        let size = number_after(line, "B used of ");
        match (used, size) {
            (Some(used), Some(size)) if used < size => eprintln!("firmware {line}"),
            _ => {
                return Err(io::Error::other(format!(
                    "the firmware's stack overflowed into its statics: {line}"
                )))
            }
        }
    }
    Ok(())
}

impl Drop for Firmware {
    fn drop(&mut self) {
        if let Some((_, _, path)) = &self.drive {
            let _ = std::fs::remove_file(path);
        }
        let _ = self.qemu.kill();
        let _ = self.qemu.wait();
        let _ = self.printer.kill();
        let _ = self.printer.wait();
    }
}

/// The firmware in QEMU with a virtual touchscreen on its USART1.
pub struct Bench {
    /// The emulation.
    pub fw: Firmware,
    /// The touchscreen, following the machine's screen contract.
    pub screen: hmi_proto::virtual_screen::VirtualScreen,
}

impl Bench {
    /// Boots the firmware and powers up the screen (it sends its start-up
    /// and ready frames, as a real Nextion does).
    pub fn boot(options: &BootOptions) -> io::Result<Self> {
        let elf = qemu_firmware_elf()?;
        let fw = Firmware::boot(&elf, options)?;
        let mut screen = hmi_proto::virtual_screen::VirtualScreen::with_contract();
        screen.boot();
        let mut bench = Self { fw, screen };
        bench.pump(Duration::from_millis(50))?;
        Ok(bench)
    }

    /// Moves bytes both ways for `dur`.
    pub fn pump(&mut self, dur: Duration) -> io::Result<()> {
        if self.fw.is_lockstep() {
            return self.pump_lockstep(dur, true);
        }
        let deadline = Instant::now() + dur;
        loop {
            let out = self.screen.take_output();
            if !out.is_empty() {
                self.fw.send(&out)?;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            let got = self
                .fw
                .read_serial_new(left.min(Duration::from_millis(5)))?;
            if !got.is_empty() {
                self.screen.feed(&got);
            }
            if left.is_zero() {
                return Ok(());
            }
        }
    }

    /// The screen's cable is cut for `dur`: what the firmware sends is lost
    /// and the screen sends nothing (its own state is kept, as a screen
    /// that stays powered keeps it).
    pub fn unplug(&mut self, dur: Duration) -> io::Result<()> {
        if self.fw.is_lockstep() {
            return self.pump_lockstep(dur, false);
        }
        let deadline = Instant::now() + dur;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(());
            }
            self.fw
                .read_serial_new(left.min(Duration::from_millis(5)))?;
        }
    }

    /// Lock-step: `dur` of firmware time (whole control periods, at least
    /// one), with the screen connected (`connected`) or its cable cut. One
    /// period at a time while the screen talks: what it sends in answer to
    /// a period's output reaches the firmware at the start of the period
    /// after the next (20 ms; a real screen answers in 1–10 ms).
    fn pump_lockstep(&mut self, dur: Duration, connected: bool) -> io::Result<()> {
        let periods = dur.as_micros().div_ceil(LOCKSTEP_PERIOD.as_micros()).max(1);
        let mut left = usize::try_from(periods).unwrap_or(usize::MAX);
        while left > 0 {
            let out = self.screen.take_output();
            // While the screen has nothing to say, a few periods at a time
            // (its answers to what the firmware sends then come up to 50 ms
            // later; the firmware's shortest reply timeout is 200 ms).
            let n = if out.is_empty() && self.fw.drive.is_none() {
                left.min(LOCKSTEP_BATCH)
            } else {
                1
            };
            if connected && !out.is_empty() {
                self.fw.send(&out)?;
            }
            left -= n;
            self.fw.allow(n)?;
            // Taken: the period before has ended, its output is on the line.
            self.fw.wait_taken()?;
            let got = self.fw.read_serial_new(Duration::ZERO)?;
            if connected && !got.is_empty() {
                self.screen.feed(&got);
            }
        }
        Ok(())
    }

    /// Pumps until `pred` holds for the screen, or `timeout`. In lock-step
    /// the firmware gets at least `timeout` of its own time, however long
    /// a busy host takes for it (the host's clock never cuts it short).
    pub fn pump_until(
        &mut self,
        timeout: Duration,
        mut pred: impl FnMut(&hmi_proto::virtual_screen::VirtualScreen) -> bool,
    ) -> io::Result<bool> {
        let deadline = Instant::now() + timeout;
        let timeout_ms = u32::try_from(timeout.as_millis()).unwrap_or(u32::MAX);
        let until_ms = self.fw.now_ms().map(|now| now.saturating_add(timeout_ms));
        loop {
            if pred(&self.screen) {
                return Ok(true);
            }
            let firmware_left = match (until_ms, self.fw.now_ms()) {
                (Some(until), Some(now)) => now < until,
                _ => false,
            };
            if Instant::now() >= deadline && !firmware_left {
                return Ok(pred(&self.screen));
            }
            self.pump(Duration::from_millis(10))?;
        }
    }

    /// The operator taps a button. Like an operator, it waits for the
    /// button's page first: a page change the firmware sent at the end of
    /// the last period may still be on its way through QEMU's serial
    /// socket (up to 100 periods of 10 ms, counted in firmware periods).
    pub fn tap(&mut self, name: &str) -> io::Result<()> {
        for _ in 0..100 {
            if self.screen.component(name).is_some() {
                break;
            }
            self.pump(Duration::from_millis(10))?;
        }
        self.screen
            .tap(name)
            .map_err(|e| io::Error::other(format!("tap {name}: {e:?}")))?;
        self.pump(Duration::from_millis(60))
    }

    /// The operator taps Save on the settings page; `Ok(true)` once the
    /// screen confirms "Settings saved" (within 3 s), else `Ok(false)`.
    pub fn save_settings(&mut self) -> io::Result<bool> {
        self.tap("bsave")?;
        self.pump_until(Duration::from_secs(3), |s| {
            s.text("tmsg") == Some("Settings saved")
        })
    }

    /// The operator types `value` into the number field `field` and taps
    /// `apply`.
    pub fn enter(&mut self, field: &str, value: i32, apply: &str) -> io::Result<()> {
        self.screen
            .set_value(field, value)
            .map_err(|e| io::Error::other(format!("set {field}: {e:?}")))?;
        self.tap(apply)?;
        self.pump(Duration::from_millis(150))
    }
}

/// One `sim:` line of the QEMU board's log (ten a second): the simulated
/// machine's truth next to the firmware's outputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimSample {
    /// Firmware time, ms.
    pub t_ms: u32,
    /// True ground speed, m/s.
    pub ground_m_s: f64,
    /// True drum speed, r/min.
    pub drum_rpm: f64,
    /// The firmware's target drum speed, r/min.
    pub target_rpm: f64,
    /// The PWM compare value the firmware applied.
    pub ccr: u32,
    /// Plants the belt dropped since boot.
    pub plants: u32,
    /// Ground position, m.
    pub ground_m: f64,
    /// Hall edges the simulated gear sensor delivered since boot.
    pub hall_edges: u32,
}

/// The firmware time (ms) at the start of a decoded defmt line
/// (`"12.340 INFO  …"`).
pub fn log_time_ms(line: &str) -> Option<u32> {
    let t: f64 = line.split_whitespace().next()?.parse().ok()?;
    Some((t * 1000.0).round() as u32)
}

/// The number after `key` in a log line (`"… plants 12, …"` → 12).
pub fn number_after(line: &str, key: &str) -> Option<f64> {
    line.split(key)
        .nth(1)?
        .split_whitespace()
        .next()?
        .trim_end_matches(',')
        .parse()
        .ok()
}

/// Parses the `sim:` lines of a log.
pub fn sim_samples(logs: &[String]) -> Vec<SimSample> {
    logs.iter()
        .filter(|l| l.contains(" sim: ground "))
        .filter_map(|l| {
            Some(SimSample {
                t_ms: log_time_ms(l)?,
                ground_m_s: number_after(l, "sim: ground ")? / 1e6,
                drum_rpm: number_after(l, "drum ")? / 1000.0,
                target_rpm: number_after(l, "target ")? / 1000.0,
                ccr: number_after(l, "ccr ")? as u32,
                plants: number_after(l, "plants ")? as u32,
                ground_m: number_after(l, "ground position ")? / 1000.0,
                hall_edges: number_after(l, "hall edges ")? as u32,
            })
        })
        .collect()
}
