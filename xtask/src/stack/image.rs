//! One firmware image as the stack analysis sees it: its code as LLVM's
//! own disassembler reads it (`llvm-objdump` of rustup's llvm-tools, the
//! toolchain's version), and from the ELF (`object`): the symbols, the
//! read-only memory (literal pools, jump tables, constant tables), the
//! vector table, the stack region and the function addresses stored in data.

use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use std::path::Path;
use std::process::Command;

use object::{Object, ObjectSection, ObjectSymbol, SectionFlags, SymbolKind};

use super::insn::{self, Insn, Line, Op};

/// The ELF section flags that matter here.
const SHF_WRITE: u64 = 0x1;
const SHF_ALLOC: u64 = 0x2;

/// The stack region of an image: `bottom..top`, growing down from `top`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StackRegion {
    /// The lowest address the stack may use (`_stack_end`).
    pub bottom: u32,
    /// The initial stack pointer (`_stack_start`, 8-byte aligned; the
    /// vector table's first word).
    pub top: u32,
}

impl StackRegion {
    /// Its size in bytes.
    pub fn size(self) -> u32 {
        self.top - self.bottom
    }
}

/// A loaded image.
pub struct Image {
    /// Every instruction of the code, by address.
    pub insns: BTreeMap<u32, Insn>,
    /// Each function's start (Thumb bit cleared) and name, demangled.
    pub functions: BTreeMap<u32, String>,
    /// Every name of each function (identical code folded by the linker
    /// has several).
    pub aliases: BTreeMap<u32, Vec<String>>,
    /// For each call through a register: the functions it lies in,
    /// innermost first, inlined ones included (from the debug
    /// information; empty without it).
    pub call_frames: BTreeMap<u32, Vec<String>>,
    /// The read-only loaded sections: address and contents.
    rom: Vec<(u32, Vec<u8>)>,
    /// Functions whose address is stored in the image's data (read-only
    /// data, initialised statics: vtables, tables of functions). The
    /// vector table does not count.
    pub data_refs: BTreeSet<u32>,
    /// Function addresses in the literal pools of the code: the pool
    /// word's address and the function.
    pub pool_refs: Vec<(u32, u32)>,
    /// The vector table's words (the initial SP, then the handlers).
    pub vectors: Vec<u32>,
    /// The stack region.
    pub stack: StackRegion,
}

impl Image {
    /// Loads `elf`, checking that its stack lies in `ram` and that no
    /// static overlaps it.
    pub fn load(elf: &Path, objdump: &Path, ram: Range<u32>) -> Result<Image, String> {
        let bytes = std::fs::read(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
        let file = object::File::parse(&*bytes).map_err(|e| format!("{}: {e}", elf.display()))?;
        let out = Command::new(objdump)
            .args(["--disassemble", "--no-show-raw-insn"])
            .arg(elf)
            .output()
            .map_err(|e| {
                format!(
                    "{}: {e} (rust-toolchain.toml installs the llvm-tools component)",
                    objdump.display()
                )
            })?;
        if !out.status.success() {
            return Err(format!(
                "llvm-objdump failed on {}: {}",
                elf.display(),
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        let text = String::from_utf8_lossy(&out.stdout);
        Image::from_parts(&file, &text, ram).map_err(|e| format!("{}: {e}", elf.display()))
    }

    fn from_parts(
        file: &object::File,
        disassembly: &str,
        ram: Range<u32>,
    ) -> Result<Image, String> {
        let mut functions = BTreeMap::new();
        let mut aliases: BTreeMap<u32, Vec<String>> = BTreeMap::new();
        let mut symbol = BTreeMap::new();
        for sym in file.symbols() {
            let Ok(name) = sym.name() else { continue };
            let addr = u32::try_from(sym.address()).map_err(|_| "a 64-bit address")?;
            symbol.entry(name.to_string()).or_insert(addr);
            if sym.kind() == SymbolKind::Text && !name.starts_with('$') {
                let name = format!("{:#}", rustc_demangle::demangle(name));
                functions.entry(addr & !1).or_insert_with(|| name.clone());
                aliases.entry(addr & !1).or_default().push(name);
            }
        }
        let mut rom = Vec::new();
        let mut data = Vec::new();
        let mut vectors = Vec::new();
        let mut statics = Vec::new();
        for section in file.sections() {
            let SectionFlags::Elf { sh_flags } = section.flags() else {
                continue;
            };
            if sh_flags & SHF_ALLOC == 0 || section.size() == 0 {
                continue;
            }
            let addr = u32::try_from(section.address()).map_err(|_| "a 64-bit address")?;
            let name = section.name().unwrap_or("");
            let contents = section.data().unwrap_or(&[]).to_vec();
            let end = addr.saturating_add(u32::try_from(section.size()).unwrap_or(u32::MAX));
            if ram.contains(&addr) {
                statics.push((name.to_string(), addr..end));
            }
            if name == ".vector_table" {
                vectors = words(&contents).collect();
            } else if name != ".text" && !contents.is_empty() {
                data.push(contents.clone());
            }
            if sh_flags & SHF_WRITE == 0 && !contents.is_empty() {
                rom.push((addr, contents));
            }
        }
        let stack = stack_region(&symbol, &vectors, &statics, ram)?;
        let mut image = Image {
            insns: BTreeMap::new(),
            functions,
            aliases,
            call_frames: BTreeMap::new(),
            rom,
            data_refs: BTreeSet::new(),
            pool_refs: Vec::new(),
            vectors,
            stack,
        };
        let pool_words = image.parse_disassembly(disassembly)?;
        image.data_refs = data
            .iter()
            .flat_map(|d| words(d))
            .filter_map(|w| image.function_address(w))
            .collect();
        image.pool_refs = pool_words
            .into_iter()
            .filter_map(|(at, w)| Some((at, image.function_address(w)?)))
            .collect();
        image.call_frames = call_frames(file, &image.insns)?;
        Ok(image)
    }

    /// The function a word points to: a Thumb address (bit 0 set) of a
    /// function's first instruction.
    pub fn function_address(&self, w: u32) -> Option<u32> {
        (w & 1 == 1 && self.functions.contains_key(&(w & !1))).then_some(w & !1)
    }

    /// Reads the instructions; returns the words of the data inside the
    /// code (literal pools) with their addresses.
    fn parse_disassembly(&mut self, text: &str) -> Result<Vec<(u32, u32)>, String> {
        let mut pool_words = Vec::new();
        // The IT block being read: instructions left, and their else bits.
        let mut it_left = 0u8;
        let mut it_elses = 0u8;
        let mut it_slot = 0u8;
        let mut last: Option<u32> = None;
        for line in text.lines() {
            match insn::parse_line(line) {
                Line::Insn(addr, mnemonic, operands) => {
                    let in_it = it_left > 0;
                    let it = in_it.then(|| insn::ItSlot {
                        then: it_elses & (1 << it_slot) == 0,
                        last: it_left == 1,
                    });
                    it_left = it_left.saturating_sub(1);
                    it_slot = it_slot.saturating_add(1);
                    let (op, cond, writes, sets_flags, stored) =
                        match insn::decode(addr, &mnemonic, &operands, in_it) {
                            Ok(d) => d,
                            Err(e) => (
                                Op::Unknown(e),
                                in_it,
                                insn::Regs::ALL,
                                true,
                                insn::Regs::ALL,
                            ),
                        };
                    if let Op::It { count, elses } = op {
                        it_left = count;
                        it_elses = elses;
                        it_slot = 0;
                    }
                    if let Some(prev) = last.and_then(|p| self.insns.get_mut(&p)) {
                        prev.next = Some(addr);
                    }
                    self.insns.insert(
                        addr,
                        Insn {
                            addr,
                            op,
                            cond,
                            it,
                            sets_flags,
                            stored,
                            writes,
                            next: None,
                            text: format!("{mnemonic} {operands}").trim().to_string(),
                        },
                    );
                    last = Some(addr);
                }
                Line::Data(addr) => {
                    last = None;
                    if addr % 4 == 0 {
                        if let Some(w) = self.word(addr) {
                            pool_words.push((addr, w));
                        }
                    }
                }
                Line::Label(..) => {}
                Line::Other => last = None,
            }
        }
        if self.insns.is_empty() {
            return Err("no code in the disassembly".into());
        }
        Ok(pool_words)
    }

    /// The word at `addr` in read-only memory.
    pub fn word(&self, addr: u32) -> Option<u32> {
        let b = self.bytes(addr, 4)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// `n` bytes at `addr` in read-only memory.
    pub fn bytes(&self, addr: u32, n: u32) -> Option<&[u8]> {
        self.rom.iter().find_map(|(start, data)| {
            let off = usize::try_from(addr.checked_sub(*start)?).ok()?;
            data.get(off..off + usize::try_from(n).ok()?)
        })
    }

    /// The function whose code holds `addr`, and the offset into it.
    pub fn function_at(&self, addr: u32) -> Option<(u32, &str)> {
        self.functions
            .range(..=addr)
            .next_back()
            .map(|(start, name)| (*start, name.as_str()))
    }

    /// A readable name for an address: `function` or `function+0x12`.
    pub fn name(&self, addr: u32) -> String {
        match self.function_at(addr) {
            Some((start, name)) if start == addr => name.to_string(),
            Some((start, name)) => format!("{name}+{:#x}", addr - start),
            None => format!("{addr:#x}"),
        }
    }
}

/// The inlined and enclosing functions of each call through a register,
/// innermost first, from the debug information (none without it).
fn call_frames(
    file: &object::File,
    insns: &BTreeMap<u32, Insn>,
) -> Result<BTreeMap<u32, Vec<String>>, String> {
    use addr2line::gimli;
    let load = |id: gimli::SectionId| -> Result<gimli::EndianSlice<'_, gimli::LittleEndian>, gimli::Error> {
        let data = file
            .section_by_name(id.name())
            .and_then(|s| s.data().ok())
            .unwrap_or(&[]);
        Ok(gimli::EndianSlice::new(data, gimli::LittleEndian))
    };
    let dwarf = gimli::Dwarf::load(load).map_err(|e| format!("debug information: {e}"))?;
    let context =
        addr2line::Context::from_dwarf(dwarf).map_err(|e| format!("debug information: {e}"))?;
    let mut out = BTreeMap::new();
    for insn in insns.values() {
        if !matches!(insn.op, Op::CallReg(_) | Op::JumpReg(_)) {
            continue;
        }
        let mut names = Vec::new();
        if let Ok(mut frames) = context.find_frames(u64::from(insn.addr)).skip_all_loads() {
            while let Ok(Some(frame)) = frames.next() {
                if let Some(f) = frame.function.as_ref().and_then(|f| f.demangle().ok()) {
                    names.push(f.into_owned());
                }
            }
        }
        out.insert(insn.addr, names);
    }
    Ok(out)
}

/// Little-endian words of a byte slice.
fn words(data: &[u8]) -> impl Iterator<Item = u32> + '_ {
    data.chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
}

/// The stack region from cortex-m-rt's symbols (`_stack_end` up to
/// `_stack_start`), checked against the vector table's initial SP, the RAM
/// and the statics.
fn stack_region(
    symbol: &BTreeMap<String, u32>,
    vectors: &[u32],
    statics: &[(String, Range<u32>)],
    ram: Range<u32>,
) -> Result<StackRegion, String> {
    let get = |name: &str| {
        symbol
            .get(name)
            .copied()
            .ok_or_else(|| format!("no symbol `{name}` (cortex-m-rt's link.x defines it)"))
    };
    let top = get("_stack_start")? & !7;
    let bottom = get("_stack_end")?;
    if vectors.first() != Some(&top) {
        return Err(format!(
            "the vector table's initial SP ({:#x?}) is not `_stack_start` ({top:#x})",
            vectors.first()
        ));
    }
    if bottom >= top || bottom < ram.start || top > ram.end {
        return Err(format!(
            "the stack {bottom:#x}..{top:#x} does not lie in RAM {:#x}..{:#x}",
            ram.start, ram.end
        ));
    }
    if let Some((name, r)) = statics
        .iter()
        .find(|(_, r)| r.start < top && bottom < r.end)
    {
        return Err(format!(
            "section {name} ({:#x}..{:#x}) overlaps the stack {bottom:#x}..{top:#x}",
            r.start, r.end
        ));
    }
    Ok(StackRegion { bottom, top })
}
