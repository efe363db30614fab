//! Static stack analysis of a firmware image (`cargo xtask size`).
//!
//! From the ELF alone: every entry in the vector table (Reset with the
//! boot, `init` and `idle`; each interrupt and exception handler, RTIC's
//! hardware tasks and software-task dispatchers among them) is analysed
//! down its call graph. The worst case is Reset's deepest path (RTIC 2
//! enables the interrupts inside `init`, so tasks may preempt any point of
//! it), plus, for each preemption level in use, an exception frame and the
//! deepest handler of that level. The handlers' priorities are the constant
//! bytes the image's code stores to the NVIC's and the SCB's priority
//! registers (RTIC writes them in `main` before `init`); an entry nothing
//! writes keeps the reset value 0, the highest configurable priority.
//!
//! Stable Rust has no `-Z emit-stack-sizes` (LLVM's `.stack_sizes`), and
//! `-C llvm-args=-stack-size-section` is accepted but emits nothing, so
//! frames come from the code itself: LLVM's disassembler (`llvm-objdump`
//! of the pinned toolchain's llvm-tools) and a data-flow pass over each
//! function ([`flow`]). The analysis fails, naming the function, where it
//! cannot bound the stack: recursion, a call through a function pointer
//! that may reach recursion, a stack-pointer update it does not know.

mod flow;
mod graph;
mod image;
mod insn;
mod pointer;

use std::fmt::Write as _;
use std::ops::Range;
use std::path::Path;

use graph::{Depth, Graph, Node};
pub use image::StackRegion;
use image::Image;

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
}

/// The NVIC's interrupt priority bytes (IPR0 onwards).
const NVIC_IPR: u32 = 0xE000_E400;
/// The SCB's system handler priority bytes (SHPR1 onwards, for
/// exception 4).
const SCB_SHPR: u32 = 0xE000_ED18;

/// A preemption level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// Thread mode: Reset, `init`, `idle`.
    Thread,
    /// A configurable priority (the byte written, 0 highest), or `None`
    /// when the image writes one the analysis cannot read (then it counts
    /// as a level of its own, above all others).
    Priority(Option<u8>, usize),
    /// HardFault (-1) and NMI (-2).
    Fixed(i8),
}

impl Level {
    /// Whether this level may preempt `other`. Unknown priorities may
    /// preempt anything.
    fn preempts(self, other: Level) -> bool {
        match (self, other) {
            (_, Level::Thread) => self != Level::Thread,
            (Level::Fixed(a), Level::Fixed(b)) => a < b,
            (Level::Fixed(_), _) => true,
            (Level::Priority(None, _), Level::Priority(..)) => self != other,
            (Level::Priority(Some(a), _), Level::Priority(Some(b), _)) => a < b,
            (Level::Priority(Some(_), _), Level::Priority(None, _)) => false,
            (Level::Priority(..) | Level::Thread, Level::Fixed(_)) => false,
            (Level::Thread, Level::Priority(..)) => false,
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
    /// deeper).
    pub path: Vec<String>,
}

/// The analysis of one image.
#[derive(Clone, Debug)]
pub struct Report {
    /// The stack region.
    pub stack: StackRegion,
    /// Every entry, thread mode first.
    pub entries: Vec<Entry>,
    /// The worst case, bytes, and how it adds up.
    pub worst: u32,
    /// The terms of [`Report::worst`].
    pub worst_terms: Vec<String>,
    /// The NVIC's priority bits, for display.
    nvic_prio_bits: u8,
    /// Assumptions the figures rest on beyond the code itself.
    pub notes: Vec<String>,
}

/// Analyses the image at `elf` for `chip`, with the disassembler `objdump`.
pub fn analyse(elf: &Path, objdump: &Path, chip: &Chip) -> Result<Report, String> {
    let image = Image::load(elf, objdump, chip.ram.clone())?;
    analyse_image(&image, chip).map_err(|e| format!("{}: {e}", elf.display()))
}

fn analyse_image(image: &Image, chip: &Chip) -> Result<Report, String> {
    let mut graph = Graph::new(image);
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
    entries.push(entry(&graph, "Reset (boot, init, idle)", 1, Level::Thread, reset, thread));
    for (h, vectors) in &handlers {
        let depth = graph.depth(Node::Fn(*h))?;
        let mut levels: Vec<(Level, usize)> = Vec::new();
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
                Some((_, n)) => *n += 1,
                None => levels.push((level, 1)),
            }
        }
        for (level, n) in levels {
            let name = image.name(*h);
            entries.push(entry(&graph, &name, n, level, *h, depth));
        }
    }
    let (worst, worst_terms) = worst_case(&entries);
    Ok(Report {
        stack: image.stack,
        entries,
        worst,
        worst_terms,
        nvic_prio_bits: chip.nvic_prio_bits,
        notes: graph.notes.clone(),
    })
}

fn entry(graph: &Graph, name: &str, vectors: usize, level: Level, h: u32, depth: Depth) -> Entry {
    let fresh = depth.fresh > depth.below;
    Entry {
        name: name.to_string(),
        vectors,
        level,
        depth,
        path: graph
            .path(Node::Fn(h), fresh)
            .into_iter()
            .map(|n| graph.node_name(n))
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

/// The worst case over all entries: thread mode's deepest, plus an
/// exception frame and the deepest handler of each preemption level above
/// it; and, for an entry that restarts the stack, its depth on the fresh
/// stack plus the levels that may preempt it.
fn worst_case(entries: &[Entry]) -> (u32, Vec<String>) {
    let mut levels: Vec<(Level, u32, &str)> = Vec::new();
    for e in entries.iter().filter(|e| e.level != Level::Thread) {
        match levels.iter_mut().find(|(l, _, _)| *l == e.level) {
            Some((_, d, n)) => {
                if e.depth.below > *d {
                    *d = e.depth.below;
                    *n = &e.name;
                }
            }
            None => levels.push((e.level, e.depth.below, &e.name)),
        }
    }
    let above = |l: Level| -> (u32, Vec<String>) {
        let mut sum = 0u32;
        let mut terms = Vec::new();
        for (lv, d, name) in levels.iter().rev() {
            if lv.preempts(l) {
                sum += EXCEPTION_FRAME + d;
                terms.push(format!("{} ({EXCEPTION_FRAME} + {d})", short(name)));
            }
        }
        (sum, terms)
    };
    let mut worst = 0;
    let mut worst_terms = Vec::new();
    for e in entries {
        let (own, fresh) = if e.level == Level::Thread {
            (e.depth.below.max(e.depth.fresh), false)
        } else if e.depth.fresh > 0 {
            (e.depth.fresh, true)
        } else {
            continue;
        };
        let (sum, mut terms) = above(e.level);
        if own + sum > worst {
            worst = own + sum;
            let how = if fresh { " (fresh stack)" } else { "" };
            terms.insert(0, format!("{}{how} {own}", short(&e.name)));
            worst_terms = terms;
        }
    }
    (worst, worst_terms)
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
            "| entry | priority | worst depth | deepest path |\n|---|---|---|---|"
        );
        for e in &self.entries {
            let vectors = if e.vectors > 1 {
                format!(" ({} vectors)", e.vectors)
            } else {
                String::new()
            };
            let depth = if e.depth.fresh > e.depth.below {
                format!("{} B (fresh stack)", e.depth.fresh)
            } else {
                format!("{} B", e.depth.below)
            };
            let _ = writeln!(
                s,
                "| {}{vectors} | {} | {depth} | {} |",
                short(&e.name),
                self.priority(e.level),
                shorten_path(&e.path)
            );
        }
        let required = required_margin(self.stack_size());
        let _ = writeln!(
            s,
            "\nworst case {} B = {} (+{EXCEPTION_FRAME} B exception frame per level); \
             stack {} B ({:#x}..{:#x}); margin {} B, required {required} B",
            self.worst,
            self.worst_terms.join(" + "),
            self.stack_size(),
            self.stack.bottom,
            self.stack.top,
            self.margin()
        );
        for n in &self.notes {
            let _ = writeln!(s, "assumed: {n}");
        }
        s
    }
}

/// A path's names, shortened; long paths keep their first two and last
/// three functions.
fn shorten_path(path: &[String]) -> String {
    let names: Vec<String> = path.iter().map(|n| short(n)).collect();
    if names.len() <= 6 {
        return names.join(" > ");
    }
    let n = names.len();
    format!(
        "{} > … ({} more) > {}",
        names[..2].join(" > "),
        n - 5,
        names[n - 3..].join(" > ")
    )
}
