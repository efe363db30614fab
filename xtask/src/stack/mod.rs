//! Static stack analysis of a firmware image (`cargo xtask size`).
//!
//! From the ELF alone ([`analyse`]: its path, and the chip's RAM to check
//! the stack against): every entry in the vector table (Reset with the
//! boot, `init` and `idle`; each interrupt and exception handler, RTIC's
//! hardware tasks and software-task dispatchers among them) is analysed
//! down its call graph ([`graph`]). The handlers' priorities are the
//! constant bytes the image's code stores to the NVIC's and the SCB's
//! priority registers (RTIC writes them in `main` before `init`); an entry
//! nothing writes keeps the reset value 0, the highest configurable
//! priority. The worst case stacks, below the deepest path of the topmost
//! level, each lower level at its deepest point where interrupts are
//! enabled, with an exception frame per level ([`worst_case`]).
//!
//! Stable Rust has no `-Z emit-stack-sizes` (LLVM's `.stack_sizes`), and
//! `-C llvm-args=-stack-size-section` is accepted but emits nothing (the
//! linked image's bytes stay the same), so frames come from the code
//! itself: LLVM's disassembler (`llvm-objdump` of the pinned toolchain's
//! llvm-tools: the decoder of the compiler that wrote the code) and a
//! data-flow pass over each function ([`flow`]). Calls through pointers it
//! cannot resolve reach what [`mod@pointer`] allows. The analysis fails,
//! naming the function, where it cannot bound the stack: recursion that
//! grows it, a stack-pointer update it does not know, a frame sized at run
//! time.

mod flow;
mod graph;
mod image;
mod insn;
mod pointer;

use std::fmt::Write as _;
use std::ops::Range;
use std::path::Path;

use graph::{Depth, Graph, Node, PathKind};
use image::Image;
pub use image::StackRegion;

/// What the hardware stacks on exception entry: eight words, plus a word
/// of padding to align the frame to 8 bytes (no FPU on the Cortex-M3, so
/// no floating-point context).
pub const EXCEPTION_FRAME: u32 = 36;

/// The margin a stack must keep over its worst case: a tenth of the stack,
/// and at least 1 KB. It covers what the analysis does not see: a
/// debugger's or probe's use of the target's stack (none today), and the
/// next change to the code before it is measured again.
pub fn required_margin(stack: u32) -> u32 {
    (stack / 10).max(1024)
}

/// The chip an image runs on.
#[derive(Clone, Debug)]
pub struct Chip {
    /// Its RAM (the stack must lie in it).
    pub ram: Range<u32>,
    /// Priority bits the NVIC implements (4 on the STM32F1), for showing
    /// RTIC's logical priorities.
    pub nvic_prio_bits: u8,
    /// Functions that exhaust the stack on purpose (a test scenario's
    /// injected overflow): their own frame counts, the calls they make do
    /// not. Matched against the end of the demangled name.
    pub overflow_on_purpose: &'static [&'static str],
}

/// The NVIC's interrupt priority bytes (IPR0 onwards).
const NVIC_IPR: u32 = 0xE000_E400;
/// The SCB's system handler priority bytes (SHPR1 onwards, for
/// exception 4).
const SCB_SHPR: u32 = 0xE000_ED18;

/// A preemption level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// Thread mode: Reset, `init`, `idle`.
    Thread,
    /// A configurable priority: the byte the code writes (0 highest), or
    /// `None` (with the vector) when it writes one the analysis cannot
    /// read; such a level counts as above all configurable ones.
    Priority(Option<u8>, usize),
    /// HardFault (-1) and NMI (-2): above all, and PRIMASK does not mask
    /// them.
    Fixed(i8),
}

impl Level {
    /// Its place from the lowest priority up.
    fn rank(self) -> u32 {
        match self {
            Level::Thread => 0,
            Level::Priority(Some(b), _) => 1 + (255 - u32::from(b)),
            Level::Priority(None, v) => 1000 + v as u32,
            Level::Fixed(f) => 2000 + f.unsigned_abs() as u32,
        }
    }
}

/// One entry of the vector table (or several sharing a handler and level).
#[derive(Clone, Debug)]
pub struct Entry {
    /// The handler's name.
    pub name: String,
    /// How many vectors lead to it at this level.
    pub vectors: usize,
    /// Its preemption level.
    pub level: Level,
    /// How deep its stack goes.
    pub depth: Depth,
    /// Its deepest path's functions (on a restarted stack if that is the
    /// deeper), each with the bytes it adds.
    pub path: Vec<(String, u32)>,
}

/// The analysis of one image.
#[derive(Clone, Debug)]
pub struct Report {
    /// The stack region.
    pub stack: StackRegion,
    /// Every entry, thread mode first.
    pub entries: Vec<Entry>,
    /// The worst case, bytes.
    pub worst: u32,
    /// How [`Report::worst`] adds up.
    pub worst_terms: Vec<String>,
    /// The NVIC's priority bits, for display.
    nvic_prio_bits: u8,
}

/// Analyses the image at `elf` for `chip`, with the disassembler `objdump`.
pub fn analyse(elf: &Path, objdump: &Path, chip: &Chip) -> Result<Report, String> {
    let image = Image::load(elf, objdump, chip.ram.clone())?;
    analyse_image(&image, chip).map_err(|e| format!("{}: {e}", elf.display()))
}

fn analyse_image(image: &Image, chip: &Chip) -> Result<Report, String> {
    let mut graph = Graph::new(image, chip.overflow_on_purpose);
    let reset = *image.vectors.get(1).ok_or("no Reset vector")? & !1;
    // Each handler, with the vectors that lead to it.
    let mut handlers: Vec<(u32, Vec<usize>)> = Vec::new();
    for (i, &v) in image.vectors.iter().enumerate().skip(2) {
        if v == 0 {
            continue;
        }
        let h = v & !1;
        match handlers.iter_mut().find(|(a, _)| *a == h) {
            Some((_, vs)) => vs.push(i),
            None => handlers.push((h, vec![i])),
        }
    }
    // Every entry analysed first, so that all priority writes are known.
    graph.facts(reset)?;
    for (h, _) in &handlers {
        graph.facts(*h)?;
    }
    graph.close()?;
    let priorities = priority_bytes(&graph);
    let mut entries = Vec::new();
    let thread = graph.depth(Node::Fn(reset))?;
    entries.push(entry(
        &graph,
        "Reset (boot, init, idle)",
        1,
        Level::Thread,
        reset,
        thread,
    ));
    for (h, vectors) in &handlers {
        let depth = graph.depth(Node::Fn(*h))?;
        let mut levels: Vec<(Level, Vec<usize>)> = Vec::new();
        for &v in vectors {
            let level = match v {
                2 => Level::Fixed(-2),
                3 => Level::Fixed(-1),
                _ => {
                    let at = if v >= 16 {
                        NVIC_IPR + (v as u32 - 16)
                    } else {
                        SCB_SHPR + (v as u32 - 4)
                    };
                    match priorities.get(&at) {
                        None => Level::Priority(Some(0), 0),
                        Some(Some(b)) => Level::Priority(Some(*b), 0),
                        Some(None) => Level::Priority(None, v),
                    }
                }
            };
            match levels.iter_mut().find(|(l, _)| *l == level) {
                Some((_, vs)) => vs.push(v),
                None => levels.push((level, vec![v])),
            }
        }
        for (level, vs) in levels {
            let mut name = image.name(*h);
            // A handler shared by several vectors (the default one): name
            // the vector when it is alone at its level.
            if vectors.len() > 1 && vs.len() == 1 {
                name = format!("{name} ({})", vector_name(vs[0]));
            }
            entries.push(entry(&graph, &name, vs.len(), level, *h, depth));
        }
    }
    let (worst, worst_terms) = worst_case(&entries);
    Ok(Report {
        stack: image.stack,
        entries,
        worst,
        worst_terms,
        nvic_prio_bits: chip.nvic_prio_bits,
    })
}

/// A vector's name: the core exception's, or the interrupt's number.
fn vector_name(v: usize) -> String {
    match v {
        2 => "NonMaskableInt".into(),
        3 => "HardFault".into(),
        4 => "MemoryManagement".into(),
        5 => "BusFault".into(),
        6 => "UsageFault".into(),
        11 => "SVCall".into(),
        12 => "DebugMonitor".into(),
        14 => "PendSV".into(),
        15 => "SysTick".into(),
        v if v >= 16 => format!("IRQ {}", v - 16),
        v => format!("exception {v}"),
    }
}

fn entry(graph: &Graph, name: &str, vectors: usize, level: Level, h: u32, depth: Depth) -> Entry {
    let kind = if depth.fresh > depth.below {
        PathKind::Fresh
    } else {
        PathKind::Below
    };
    Entry {
        name: name.to_string(),
        vectors,
        level,
        depth,
        path: graph
            .path(Node::Fn(h), kind)
            .into_iter()
            .map(|(n, d)| (graph.node_name(n), d))
            .collect(),
    }
}

/// The priority byte each constant store in the analysed code leaves at
/// each address of the priority registers: `None` where stores disagree
/// or store a value that is not a constant.
fn priority_bytes(graph: &Graph) -> std::collections::BTreeMap<u32, Option<u8>> {
    let mut bytes = std::collections::BTreeMap::new();
    let ranges = [NVIC_IPR..NVIC_IPR + 240, SCB_SHPR..SCB_SHPR + 12];
    for s in graph.summaries() {
        for st in &s.stores {
            for k in 0..u32::from(st.bytes) {
                let at = st.addr.wrapping_add(k);
                if !ranges.iter().any(|r| r.contains(&at)) {
                    continue;
                }
                let b = st.value.map(|v| (v >> (8 * k)) as u8);
                let e = bytes.entry(at).or_insert(b);
                if *e != b {
                    *e = None;
                }
            }
        }
    }
    bytes
}

/// One preemption level's deepest handlers.
struct LevelDepth<'a> {
    level: Level,
    /// The exception frame it costs (none for thread mode).
    frame: u32,
    below: (u32, &'a str),
    open: Option<(u32, &'a str)>,
}

/// The worst case over all entries. The stack holds at most one handler
/// per preemption level, each preempted (if at all) where interrupts are
/// enabled: for each level taken as the top one, its deepest path plus,
/// for every level below it, an exception frame and that level's deepest
/// preemptible point; HardFault and NMI preempt anything, masked or not.
/// An entry that restarts the stack counts from the top, plus the levels
/// that may preempt it.
fn worst_case(entries: &[Entry]) -> (u32, Vec<String>) {
    let mut levels: Vec<LevelDepth> = Vec::new();
    for e in entries {
        let i = match levels.iter().position(|l| l.level == e.level) {
            Some(i) => i,
            None => {
                levels.push(LevelDepth {
                    level: e.level,
                    frame: if e.level == Level::Thread {
                        0
                    } else {
                        EXCEPTION_FRAME
                    },
                    below: (0, &e.name),
                    open: None,
                });
                levels.len() - 1
            }
        };
        let l = &mut levels[i];
        if e.depth.below >= l.below.0 {
            l.below = (e.depth.below, &e.name);
        }
        if let Some(o) = e.depth.open {
            if l.open.is_none_or(|(d, _)| o > d) {
                l.open = Some((o, &e.name));
            }
        }
    }
    levels.sort_by_key(|l| l.level.rank());
    let fixed: Vec<&LevelDepth> = levels
        .iter()
        .filter(|l| matches!(l.level, Level::Fixed(_)))
        .collect();
    let mut worst = 0;
    let mut terms = Vec::new();
    let mut consider = |total: u32, t: Vec<String>| {
        if total > worst {
            worst = total;
            terms = t;
        }
    };
    for (k, top) in levels.iter().enumerate() {
        if matches!(top.level, Level::Fixed(_)) {
            continue;
        }
        let mut total = 0;
        let mut t = Vec::new();
        for l in &levels[..k] {
            if let Some((o, name)) = l.open {
                total += l.frame + o;
                t.push(term(l.frame, o, name, " preemptible"));
            }
        }
        total += top.frame + top.below.0;
        t.push(term(top.frame, top.below.0, top.below.1, ""));
        for f in &fixed {
            total += f.frame + f.below.0;
            t.push(term(f.frame, f.below.0, f.below.1, ""));
        }
        consider(total, t);
    }
    for e in entries.iter().filter(|e| e.depth.fresh > 0) {
        let mut total = e.depth.fresh;
        let mut t = vec![format!(
            "{} {} (fresh stack)",
            short(&e.name),
            e.depth.fresh
        )];
        for f in fixed.iter().filter(|f| f.level.rank() > e.level.rank()) {
            total += f.frame + f.below.0;
            t.push(term(f.frame, f.below.0, f.below.1, ""));
        }
        consider(total, t);
    }
    (worst, terms)
}

fn term(frame: u32, depth: u32, name: &str, what: &str) -> String {
    if frame == 0 {
        format!("{} {depth}{what}", short(name))
    } else {
        format!("{} {frame}+{depth}{what}", short(name))
    }
}

/// A function name without its hash, generic arguments and leading
/// module path (its last two path segments).
pub fn short(name: &str) -> String {
    let mut out = String::new();
    let mut depth = 0;
    for c in name.chars() {
        match c {
            '<' => depth += 1,
            '>' if depth > 0 => depth -= 1,
            _ if depth == 0 => out.push(c),
            _ => {}
        }
    }
    let segments: Vec<&str> = out.split("::").filter(|s| !s.is_empty()).collect();
    let n = segments.len();
    segments[n.saturating_sub(2)..].join("::")
}

impl Report {
    /// The stack's size.
    pub fn stack_size(&self) -> u32 {
        self.stack.size()
    }

    /// What is left of the stack in the worst case (negative: overflow).
    pub fn margin(&self) -> i64 {
        i64::from(self.stack_size()) - i64::from(self.worst)
    }

    /// Fails when the margin is below [`required_margin`].
    pub fn check_margin(&self) -> Result<(), String> {
        let required = required_margin(self.stack_size());
        if self.margin() < i64::from(required) {
            return Err(format!(
                "stack worst case {} B of {} B leaves {} B, below the required margin of {required} B \
                 (deepest: {})",
                self.worst,
                self.stack_size(),
                self.margin(),
                self.worst_terms.join(" + ")
            ));
        }
        Ok(())
    }

    fn priority(&self, level: Level) -> String {
        match level {
            Level::Thread => "thread".into(),
            Level::Fixed(-2) => "NMI".into(),
            Level::Fixed(_) => "HardFault".into(),
            Level::Priority(None, _) => "unknown".into(),
            Level::Priority(Some(b), _) => {
                let bits = u32::from(self.nvic_prio_bits);
                let logical = (1u32 << bits).saturating_sub(u32::from(b) >> (8 - bits));
                format!("{logical} ({b:#04x})")
            }
        }
    }

    /// The report as a Markdown table with its totals.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "| entry | priority | deepest | preemptible | deepest path |\n|---|---|---|---|---|"
        );
        for e in &self.entries {
            let vectors = if e.vectors > 1 {
                format!(" ({} vectors)", e.vectors)
            } else {
                String::new()
            };
            let depth = if e.depth.fresh > e.depth.below {
                format!("{} B fresh stack", e.depth.fresh)
            } else {
                format!("{} B", e.depth.below)
            };
            let open = e.depth.open.map_or("never".into(), |o| format!("{o} B"));
            let _ = writeln!(
                s,
                "| {}{vectors} | {} | {depth} | {open} | {} |",
                short(&e.name),
                self.priority(e.level),
                shorten_path(&e.path)
            );
        }
        let required = required_margin(self.stack_size());
        let _ = writeln!(
            s,
            "\nworst case {} B = {} (exception frames {EXCEPTION_FRAME} B); stack {} B \
             ({:#x}..{:#x}); margin {} B, required {required} B",
            self.worst,
            self.worst_terms.join(" + "),
            self.stack_size(),
            self.stack.bottom,
            self.stack.top,
            self.margin()
        );
        s
    }
}

/// Compares the analysis of an image with what a run of it measured: the
/// QEMU board paints its stack at reset and logs `stack: N B used of M B`.
/// The static worst case must cover every measured depth, and the stack
/// the firmware sees must be the one analysed. Returns a line for the log.
pub fn check_measured(report: &Report, logs: &[String]) -> Result<String, String> {
    let mut deepest = None;
    for line in logs.iter().filter(|l| l.contains(" stack: ")) {
        let used = qemu_tests::number_after(line, "stack: ");
        let size = qemu_tests::number_after(line, "B used of ");
        let (Some(used), Some(size)) = (used, size) else {
            return Err(format!("cannot read the stack line `{line}`"));
        };
        if size != f64::from(report.stack_size()) {
            return Err(format!(
                "the firmware's stack is {size} B, the analysis read {} B from the image",
                report.stack_size()
            ));
        }
        if used > f64::from(report.worst) {
            return Err(format!(
                "the run used {used} B of stack, more than the static worst case {} B: \
                 the analysis misses a path",
                report.worst
            ));
        }
        deepest = Some(deepest.map_or(used, |d: f64| d.max(used)));
    }
    let deepest = deepest.ok_or("the run logged no `stack:` line")?;
    Ok(format!(
        "stack: {deepest} B measured in this run, static worst case {} B, stack {} B",
        report.worst,
        report.stack_size()
    ))
}

/// A path, shortened: its first and last functions, the panic handler,
/// and those adding at least a tenth of the path's bytes (with what they
/// add); "…" for the others.
fn shorten_path(path: &[(String, u32)]) -> String {
    let total: u32 = path.iter().map(|(_, d)| d).sum();
    let mut out: Vec<String> = Vec::new();
    let mut skipped = false;
    for (i, (name, d)) in path.iter().enumerate() {
        let big = *d > 0 && *d >= total / 10;
        let keep = i == 0 || i + 1 == path.len() || big || name.ends_with("rust_begin_unwind");
        if !keep {
            skipped = true;
            continue;
        }
        if skipped {
            out.push("…".into());
            skipped = false;
        }
        if big {
            out.push(format!("{} {d}", short(name)));
        } else {
            out.push(short(name));
        }
    }
    out.join(" > ")
}

#[cfg(test)]
mod tests;
