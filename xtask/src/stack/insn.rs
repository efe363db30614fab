//! The instructions of `llvm-objdump -d` output, decoded into what the
//! stack analysis needs: how each one moves the stack pointer, where control
//! goes next, and which registers it writes (for the constants that resolve
//! calls through registers and the stores that set interrupt priorities).
//!
//! Anything that writes SP or PC in a form not listed here is an error
//! naming the instruction: the analysis never guesses at the stack.

/// A core register number (r0–r12, then SP, LR, PC).
pub type Reg = u8;
/// The stack pointer.
pub const SP: Reg = 13;
/// The link register.
pub const LR: Reg = 14;
/// The program counter.
pub const PC: Reg = 15;

/// A set of core registers, bit `n` for register `n`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Regs(pub u16);

impl Regs {
    /// No register.
    pub const NONE: Regs = Regs(0);
    /// Every register.
    pub const ALL: Regs = Regs(0xffff);
    /// The registers a procedure call may change (AAPCS: r0–r3, r12, LR).
    pub const CALLER_SAVED: Regs = Regs(0b0101_0000_0000_1111);

    /// Whether `r` is in the set.
    pub fn has(self, r: Reg) -> bool {
        self.0 & (1 << r) != 0
    }
    /// The set with `r` added.
    pub fn with(self, r: Reg) -> Regs {
        Regs(self.0 | (1 << r))
    }
    /// The union of two sets.
    pub fn or(self, other: Regs) -> Regs {
        Regs(self.0 | other.0)
    }
    /// The set without the registers of `other`.
    pub fn minus(self, other: Regs) -> Regs {
        Regs(self.0 & !other.0)
    }
    /// How many registers the set holds.
    pub fn count(self) -> u32 {
        self.0.count_ones()
    }
    /// The registers of the set.
    pub fn iter(self) -> impl Iterator<Item = Reg> {
        (0..16).filter(move |&r| self.has(r))
    }
}

/// Where a table branch's table lies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TableBase {
    /// Right after the instruction (`tbb [pc, rN]`).
    Pc,
    /// At the address a register holds (`adr rB, table; tbh [rB, rN]`).
    Reg(Reg),
}

/// What an instruction does, as far as the analysis is concerned.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Op {
    /// The stack grows by `bytes` (push, stmdb sp!, `str rX, [sp, #-n]!`,
    /// sub sp, vpush), storing `saves`.
    Grow { bytes: u32, saves: Regs },
    /// `sub sp, rN`: the stack grows by the value of a register.
    GrowBy(Reg),
    /// The stack shrinks by `bytes` (pop, `ldr rX, [sp], #n`, add sp).
    Shrink { bytes: u32 },
    /// `add sp, rN`.
    ShrinkBy(Reg),
    /// SP from another register plus a constant (`mov sp, r7`,
    /// `sub.w sp, r7, #16`: a frame pointer restoring the stack).
    SetSp { src: Reg, add: i32 },
    /// A pop or load of PC from the stack: shrink by `bytes`, then return.
    PopReturn { bytes: u32 },
    /// `msr msp, rN`: the stack starts afresh (the fatal-exception entries).
    ResetStack(Reg),
    /// `bl`: a call.
    Call(u32),
    /// `blx rN`: a call through a register.
    CallReg(Reg),
    /// `b`, `b<cond>`, `cbz`, `cbnz`: a branch, inside the function or a
    /// tail call to another.
    Jump(u32),
    /// `bx rN` (not LR), `mov pc, rN`: a tail call through a register.
    JumpReg(Reg),
    /// `bx lr`, `mov pc, lr`.
    Return,
    /// `tbb`/`tbh`: a jump table of bytes or halfwords.
    Table { base: TableBase, halfwords: bool },
    /// `udf`, `trap`: a fault (HardFault runs instead; no successor).
    Trap,
    /// `ldr rD, [pc, #n]`: a word from the literal pool at `addr`.
    LoadLiteral { dst: Reg, addr: u32 },
    /// `ldr rD, [rB, #n]`: a word from memory (a constant when rB holds
    /// an address in read-only memory).
    Load { dst: Reg, base: Reg, offset: i32 },
    /// `mov rD, #n`, `movw`, `adr`: a constant.
    MovImm { dst: Reg, value: u32 },
    /// `movt rD, #n`: the top half of a constant.
    MovTop { dst: Reg, value: u32 },
    /// `mov rD, rS`.
    Copy { dst: Reg, src: Reg },
    /// `add rD, rS, #n` / `sub rD, rS, #n` (also with SP as rS).
    AddImm { dst: Reg, src: Reg, imm: i32 },
    /// `str`/`strh`/`strb` of a register (`bytes` wide) to
    /// `[base, #offset]` or `[base, index]`.
    Store {
        src: Reg,
        base: Reg,
        offset: i32,
        index: Option<Reg>,
        bytes: u8,
    },
    /// `cpsid i`/`cpsid f` (true), `cpsie` (false): interrupts masked or
    /// not.
    Mask(bool),
    /// `msr primask, rN`: interrupts masked as bit 0 of a register says.
    SetMask(Reg),
    /// `mrs rD, primask`: whether interrupts are masked, into a register.
    ReadMask(Reg),
    /// `it`: the next `count` instructions are conditional; bit `i` of
    /// `elses` set when the instruction `i` after it runs when the
    /// condition fails (an `e` in `itte`).
    It { count: u8, elses: u8 },
    /// Anything else: writes [`Insn::writes`], nothing more.
    Other,
    /// An instruction writing SP or PC in a form the analysis does not
    /// know: an error if the analysis reaches it.
    Unknown(String),
}

/// One decoded instruction.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Insn {
    /// Its address.
    pub addr: u32,
    /// What it does.
    pub op: Op,
    /// Executed only when a condition holds (inside an IT block, or a
    /// conditional branch).
    pub cond: bool,
    /// Its place in an IT block, if it is in one.
    pub it: Option<ItSlot>,
    /// Whether it may change the condition flags.
    pub sets_flags: bool,
    /// The registers whose values it stores to memory.
    pub stored: Regs,
    /// The registers it writes (as well as what `op` describes; written
    /// registers lose any constant value they held).
    pub writes: Regs,
    /// The address of the instruction after it, if an instruction follows.
    pub next: Option<u32>,
    /// The disassembly, for messages.
    pub text: String,
}

/// An instruction's place in an IT block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ItSlot {
    /// It runs when the block's condition holds (a `t` slot); otherwise
    /// when it fails (an `e` slot).
    pub then: bool,
    /// It is the block's last instruction.
    pub last: bool,
}

/// One line of `llvm-objdump -d` output.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Line {
    /// `08000130 <name>:`: a symbol starts.
    Label(u32, String),
    /// An instruction: address, mnemonic, operands.
    Insn(u32, String, String),
    /// Data inside the code (literal pools, jump tables).
    Data(u32),
    /// Anything else (headers, blank lines).
    Other,
}

/// Splits one line of `llvm-objdump -d --no-show-raw-insn` output.
pub fn parse_line(line: &str) -> Line {
    let trimmed = line.trim_end();
    if let Some(rest) = trimmed.strip_suffix(">:") {
        if let Some((addr, name)) = rest.split_once(" <") {
            if let Ok(addr) = u32::from_str_radix(addr.trim(), 16) {
                return Line::Label(addr, name.to_string());
            }
        }
        return Line::Other;
    }
    let Some((addr, rest)) = trimmed.split_once(':') else {
        return Line::Other;
    };
    let Ok(addr) = u32::from_str_radix(addr.trim(), 16) else {
        return Line::Other;
    };
    // Drop the comment (`@ imm = #0x4`, `@ 0x8000158 <sym+0x28>`).
    let body = rest.split(" @ ").next().unwrap_or("").trim();
    let mut words = body.splitn(2, char::is_whitespace);
    let first = words.next().unwrap_or("");
    let is_hex_byte = |w: &str| w.len() == 2 && w.bytes().all(|b| b.is_ascii_hexdigit());
    if first.is_empty() {
        return Line::Other;
    }
    if is_hex_byte(first) || first.starts_with('.') || first == "<unknown>" {
        return Line::Data(addr);
    }
    let operands = words.next().unwrap_or("").trim().to_string();
    Line::Insn(addr, first.to_string(), operands)
}

/// The condition codes, as suffixes of conditional mnemonics.
const CONDITIONS: [&str; 16] = [
    "eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le",
];

/// Mnemonics that write no register (beyond what a writeback adds).
const NO_DEST: &[&str] = &[
    "cmp", "cmn", "tst", "teq", "str", "strb", "strh", "strd", "stm", "stmia", "stmea", "stmdb",
    "stmfd", "nop", "dmb", "dsb", "isb", "cpsid", "cpsie", "msr", "wfi", "wfe", "sev", "bkpt",
    "udf", "trap", "vstr", "vstm", "vstmia", "vstmdb", "pld", "pli", "svc", "yield", "clrex",
    "cbz", "cbnz", "push", "vpush", "tbb", "tbh", "b", "bl", "blx", "bx", "sevl", "dbg", "it",
];

/// Mnemonics that write their first two operands.
const TWO_DESTS: &[&str] = &[
    "ldrd", "ldrexd", "umull", "smull", "umlal", "smlal", "umaal", "vmov",
];

/// An error decoding one instruction.
pub type DecodeError = String;

/// A decoded instruction: what it does, whether it is conditional, the
/// registers it writes, whether it may change the flags, the registers
/// whose values it stores to memory.
pub type Decoded = (Op, bool, Regs, bool, Regs);

/// Decodes one instruction. `in_it` says whether it lies in an IT block
/// (its mnemonic then carries a condition suffix, stripped here).
pub fn decode(
    addr: u32,
    mnemonic: &str,
    operands: &str,
    in_it: bool,
) -> Result<Decoded, DecodeError> {
    let text = format!("{mnemonic} {operands}");
    let err = |why: &str| Err(format!("{addr:#x}: `{}`: {why}", text.trim()));
    let base = mnemonic
        .strip_suffix(".w")
        .or_else(|| mnemonic.strip_suffix(".n"))
        .unwrap_or(mnemonic);
    let mut cond = in_it;
    let m: &str = if in_it {
        strip_condition(base).unwrap_or(base)
    } else {
        base
    };
    let ops = split_operands(operands);
    // Branches carry their condition outside IT blocks (`beq`, `bhi.w`).
    let branch_cond = !in_it && m.len() == 3 && m.starts_with('b') && is_condition(&m[1..]);
    let m = if branch_cond {
        cond = true;
        "b"
    } else {
        m
    };
    let writes = generic_writes(m, &ops);
    let op = match m {
        "push" | "stmdb" | "stmfd"
            if m == "push" || ops.first().map(String::as_str) == Some("sp!") =>
        {
            let list = reg_list(ops.last().map(String::as_str).unwrap_or(""))
                .ok_or_else(|| format!("{addr:#x}: `{text}`: register list"))?;
            Op::Grow {
                bytes: 4 * list.count(),
                saves: list,
            }
        }
        "pop" | "ldm" | "ldmia" | "ldmfd"
            if m == "pop" || ops.first().map(String::as_str) == Some("sp!") =>
        {
            let list = reg_list(ops.last().map(String::as_str).unwrap_or(""))
                .ok_or_else(|| format!("{addr:#x}: `{text}`: register list"))?;
            let bytes = 4 * list.count();
            if list.has(PC) {
                Op::PopReturn { bytes }
            } else {
                Op::Shrink { bytes }
            }
        }
        "vpush" | "vpop" => {
            let bytes = vfp_list_bytes(ops.first().map(String::as_str).unwrap_or(""))
                .ok_or_else(|| format!("{addr:#x}: `{text}`: register list"))?;
            if m == "vpush" {
                Op::Grow {
                    bytes,
                    saves: Regs::NONE,
                }
            } else {
                Op::Shrink { bytes }
            }
        }
        "str" | "strd"
            if ops
                .last()
                .is_some_and(|o| o.starts_with("[sp, #-") && o.ends_with("]!")) =>
        {
            let bytes = parse_imm(&ops[ops.len() - 1][5..ops[ops.len() - 1].len() - 2])
                .and_then(|v| u32::try_from(v.unsigned_abs()).ok())
                .ok_or_else(|| format!("{addr:#x}: `{text}`: offset"))?;
            let mut saves = Regs::NONE;
            for o in &ops[..ops.len() - 1] {
                saves = saves.with(reg(o).ok_or_else(|| format!("{addr:#x}: `{text}`"))?);
            }
            Op::Grow { bytes, saves }
        }
        "ldr" if ops.len() == 3 && ops[1] == "[sp]" => {
            let bytes = parse_imm(&ops[2])
                .and_then(|v| u32::try_from(v).ok())
                .ok_or_else(|| format!("{addr:#x}: `{text}`: offset"))?;
            if reg(&ops[0]) == Some(PC) {
                Op::PopReturn { bytes }
            } else {
                Op::Shrink { bytes }
            }
        }
        "sub" | "subw" | "add" | "addw" if ops.first().map(String::as_str) == Some("sp") => {
            let grow = m.starts_with("sub");
            let (src, last) = match ops.len() {
                2 => (SP, ops[1].as_str()),
                3 => (
                    reg(&ops[1]).ok_or_else(|| format!("{addr:#x}: `{text}`: source"))?,
                    ops[2].as_str(),
                ),
                _ => return err("an SP update of an unknown form"),
            };
            match (src, parse_imm(last), reg(last)) {
                (SP, Some(n), _) => {
                    let bytes =
                        u32::try_from(n).map_err(|_| format!("{addr:#x}: `{text}`: negative"))?;
                    if grow {
                        Op::Grow {
                            bytes,
                            saves: Regs::NONE,
                        }
                    } else {
                        Op::Shrink { bytes }
                    }
                }
                (SP, None, Some(r)) => {
                    if grow {
                        Op::GrowBy(r)
                    } else {
                        Op::ShrinkBy(r)
                    }
                }
                (src, Some(n), _) => {
                    let n = i32::try_from(n).map_err(|_| format!("{addr:#x}: `{text}`"))?;
                    Op::SetSp {
                        src,
                        add: if grow { -n } else { n },
                    }
                }
                _ => return err("an SP update of an unknown form"),
            }
        }
        "mov" if ops.len() == 2 && ops[0] == "sp" => match reg(&ops[1]) {
            Some(src) => Op::SetSp { src, add: 0 },
            None => return err("an SP update of an unknown form"),
        },
        "mov" if ops.len() == 2 && ops[0] == "pc" => match reg(&ops[1]) {
            Some(LR) => Op::Return,
            Some(r) => Op::JumpReg(r),
            None => return err("a PC update of an unknown form"),
        },
        "cpsid" | "cpsie" => Op::Mask(m == "cpsid"),
        "msr"
            if matches!(
                ops.first().map(String::as_str),
                Some("primask" | "faultmask")
            ) =>
        {
            match ops.get(1).and_then(|o| reg(o)) {
                Some(r) => Op::SetMask(r),
                None => return err("a PRIMASK update of an unknown form"),
            }
        }
        "mrs" if ops.get(1).map(String::as_str) == Some("primask") => {
            match ops.first().and_then(|o| reg(o)) {
                Some(r) => Op::ReadMask(r),
                None => return err("a PRIMASK read of an unknown form"),
            }
        }
        "msr" if ops.first().map(String::as_str) == Some("msp") => {
            match ops.get(1).and_then(|o| reg(o)) {
                Some(r) => Op::ResetStack(r),
                None => return err("an MSP update of an unknown form"),
            }
        }
        "bl" => Op::Call(target(&ops).ok_or_else(|| format!("{addr:#x}: `{text}`: target"))?),
        "blx" => match ops.first().and_then(|o| reg(o)) {
            Some(r) => Op::CallReg(r),
            None => return err("a call of an unknown form"),
        },
        "b" => Op::Jump(target(&ops).ok_or_else(|| format!("{addr:#x}: `{text}`: target"))?),
        "cbz" | "cbnz" => {
            cond = true;
            Op::Jump(
                ops.get(1)
                    .and_then(|o| parse_address(o))
                    .ok_or_else(|| format!("{addr:#x}: `{text}`: target"))?,
            )
        }
        "bx" => match ops.first().and_then(|o| reg(o)) {
            Some(LR) => Op::Return,
            Some(r) => Op::JumpReg(r),
            None => return err("a branch of an unknown form"),
        },
        "tbb" | "tbh" => {
            let inner = ops
                .first()
                .and_then(|o| o.strip_prefix('['))
                .ok_or_else(|| format!("{addr:#x}: `{text}`: table"))?;
            let base = match inner.split(',').next().map(str::trim).and_then(reg) {
                Some(PC) => TableBase::Pc,
                Some(r) => TableBase::Reg(r),
                None => return err("a table branch of an unknown form"),
            };
            Op::Table {
                base,
                halfwords: m == "tbh",
            }
        }
        "udf" | "trap" => Op::Trap,
        "ldr" if ops.len() == 2 && ops[1].starts_with("[pc") => {
            let dst = reg(&ops[0]).ok_or_else(|| format!("{addr:#x}: `{text}`"))?;
            let (_, offset) = mem_operand(&ops[1]).ok_or_else(|| format!("{addr:#x}: `{text}`"))?;
            let pool = (addr.wrapping_add(4) & !3).wrapping_add_signed(offset);
            Op::LoadLiteral { dst, addr: pool }
        }
        "ldr" if ops.len() == 2 && !ops[1].ends_with('!') => {
            let dst = reg(&ops[0]).ok_or_else(|| format!("{addr:#x}: `{text}`"))?;
            match mem_operand(&ops[1]) {
                Some((base, offset)) => Op::Load { dst, base, offset },
                None => Op::Other,
            }
        }
        "mov" | "movs" | "movw" if ops.len() == 2 => {
            let dst = reg(&ops[0]).ok_or_else(|| format!("{addr:#x}: `{text}`"))?;
            if let Some(v) = parse_imm(&ops[1]) {
                Op::MovImm {
                    dst,
                    value: v as u32,
                }
            } else if let Some(src) = reg(&ops[1]) {
                Op::Copy { dst, src }
            } else {
                Op::Other
            }
        }
        "movt" if ops.len() == 2 => {
            let dst = reg(&ops[0]).ok_or_else(|| format!("{addr:#x}: `{text}`"))?;
            match parse_imm(&ops[1]).and_then(|v| u32::try_from(v).ok()) {
                Some(value) => Op::MovTop { dst, value },
                None => Op::Other,
            }
        }
        "adr" if ops.len() == 2 => {
            let dst = reg(&ops[0]).ok_or_else(|| format!("{addr:#x}: `{text}`"))?;
            let off = parse_imm(&ops[1]).ok_or_else(|| format!("{addr:#x}: `{text}`"))?;
            let off = i32::try_from(off).map_err(|_| format!("{addr:#x}: `{text}`"))?;
            Op::MovImm {
                dst,
                value: (addr.wrapping_add(4) & !3).wrapping_add_signed(off),
            }
        }
        "add" | "adds" | "addw" | "sub" | "subs" | "subw" if ops.len() == 3 || ops.len() == 2 => {
            let dst = reg(&ops[0]);
            let (src, imm) = if ops.len() == 3 {
                (reg(&ops[1]), parse_imm(&ops[2]))
            } else {
                (dst, parse_imm(&ops[1]))
            };
            match (dst, src, imm.and_then(|v| i32::try_from(v).ok())) {
                (Some(dst), Some(src), Some(imm)) if src != PC => Op::AddImm {
                    dst,
                    src,
                    imm: if m.starts_with("sub") { -imm } else { imm },
                },
                _ => Op::Other,
            }
        }
        "str" | "strh" | "strb" if ops.len() == 2 && !ops[1].ends_with('!') => {
            let src = reg(&ops[0]).ok_or_else(|| format!("{addr:#x}: `{text}`"))?;
            let bytes = match m {
                "str" => 4,
                "strh" => 2,
                _ => 1,
            };
            match mem_operand(&ops[1]) {
                Some((base, offset)) => Op::Store {
                    src,
                    base,
                    offset,
                    index: None,
                    bytes,
                },
                None => match mem_index_operand(&ops[1]) {
                    Some((base, index)) => Op::Store {
                        src,
                        base,
                        offset: 0,
                        index: Some(index),
                        bytes,
                    },
                    None => Op::Other,
                },
            }
        }
        _ if m.starts_with("it")
            && m[2..].bytes().all(|b| b == b't' || b == b'e')
            && m.len() <= 5 =>
        {
            Op::It {
                count: (m.len() - 1) as u8,
                elses: m
                    .bytes()
                    .skip(2)
                    .enumerate()
                    .filter(|(_, b)| *b == b'e')
                    .fold(0, |acc, (i, _)| acc | (1 << (i + 1))),
            }
        }
        _ => Op::Other,
    };
    // Every write of SP or PC must have been understood above.
    let handled_sp = matches!(
        op,
        Op::Grow { .. }
            | Op::GrowBy(_)
            | Op::Shrink { .. }
            | Op::ShrinkBy(_)
            | Op::SetSp { .. }
            | Op::PopReturn { .. }
    );
    if writes.has(SP) && !handled_sp {
        return err("writes SP in a form the stack analysis does not know");
    }
    let handled_pc = matches!(op, Op::PopReturn { .. } | Op::Return | Op::JumpReg(_));
    if writes.has(PC) && !handled_pc {
        return err("writes PC in a form the stack analysis does not know");
    }
    let sets_flags = matches!(m, "cmp" | "cmn" | "tst" | "teq") || m.ends_with('s');
    Ok((
        op,
        cond,
        writes.minus(Regs::NONE.with(SP).with(PC)),
        sets_flags,
        stored_regs(m, &ops),
    ))
}

/// `base` without its condition suffix, if it has one.
fn strip_condition(base: &str) -> Option<&str> {
    let n = base.len();
    (n > 2 && is_condition(&base[n - 2..])).then(|| &base[..n - 2])
}

fn is_condition(s: &str) -> bool {
    CONDITIONS.contains(&s)
}

/// The registers an instruction writes, from its operands: the first
/// operand for most, two for the long multiplies and `ldrd`, the list of
/// `pop`/`ldm`, plus any base register written back (`[rB, #n]!`, `[rB], #n`,
/// `rB!`).
fn generic_writes(m: &str, ops: &[String]) -> Regs {
    let mut writes = Regs::NONE;
    let is_store = m.starts_with("st") || m == "push";
    let is_list_load = m == "pop" || m.starts_with("ldm");
    if is_list_load {
        if let Some(list) = ops.last().and_then(|o| reg_list(o)) {
            writes = writes.or(list);
        }
    } else if TWO_DESTS.contains(&m) {
        for o in ops.iter().take(2) {
            if let Some(r) = reg(o) {
                writes = writes.with(r);
            }
        }
    } else if m.starts_with("strex") {
        if let Some(r) = ops.first().and_then(|o| reg(o)) {
            writes = writes.with(r);
        }
    } else if !NO_DEST.contains(&m) && !is_store && !m.starts_with("it") {
        if let Some(r) = ops.first().and_then(|o| reg(o)) {
            writes = writes.with(r);
        }
    }
    // Writebacks.
    for (i, o) in ops.iter().enumerate() {
        if let Some(r) = o.strip_suffix('!').and_then(reg) {
            writes = writes.with(r);
        }
        if let Some(inner) = o.strip_prefix('[') {
            let base = inner.split([',', ']']).next().map(str::trim).and_then(reg);
            let post_indexed = o.ends_with(']') && !o.contains(',') && i + 1 < ops.len();
            if let Some(b) = base {
                if o.ends_with("]!") || post_indexed {
                    writes = writes.with(b);
                }
            }
        }
    }
    writes
}

/// The registers whose values a store writes to memory.
fn stored_regs(m: &str, ops: &[String]) -> Regs {
    let regs = |range: std::ops::Range<usize>| {
        ops.get(range)
            .unwrap_or(&[])
            .iter()
            .filter_map(|o| reg(o))
            .fold(Regs::NONE, Regs::with)
    };
    match m {
        "str" | "strb" | "strh" => regs(0..1),
        "strd" => regs(0..2),
        "strex" | "strexb" | "strexh" => regs(1..2),
        "strexd" => regs(1..3),
        _ if m == "push" || m.starts_with("stm") => {
            ops.last().and_then(|o| reg_list(o)).unwrap_or(Regs::NONE)
        }
        _ => Regs::NONE,
    }
}

/// Splits operands at the commas outside `[]` and `{}`.
pub fn split_operands(s: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut depth = 0i32;
    let mut cur = String::new();
    for c in s.chars() {
        match c {
            '[' | '{' => depth += 1,
            ']' | '}' => depth -= 1,
            _ => {}
        }
        if c == ',' && depth == 0 {
            out.push(cur.trim().to_string());
            cur.clear();
        } else {
            cur.push(c);
        }
    }
    if !cur.trim().is_empty() {
        out.push(cur.trim().to_string());
    }
    out
}

/// A core register's number.
pub fn reg(s: &str) -> Option<Reg> {
    match s.trim() {
        "sp" | "r13" => Some(SP),
        "lr" | "r14" => Some(LR),
        "pc" | "r15" => Some(PC),
        "sb" => Some(9),
        "sl" => Some(10),
        "fp" => Some(11),
        "ip" => Some(12),
        s => s
            .strip_prefix('r')
            .and_then(|n| n.parse::<u8>().ok())
            .filter(|&n| n <= 12),
    }
}

/// `{r4, r5, lr}` or `{r4-r7}`.
fn reg_list(s: &str) -> Option<Regs> {
    let inner = s.trim().strip_prefix('{')?.strip_suffix('}')?;
    let mut set = Regs::NONE;
    for part in inner.split(',') {
        let part = part.trim();
        if let Some((a, b)) = part.split_once('-') {
            for r in reg(a)?..=reg(b)? {
                set = set.with(r);
            }
        } else {
            set = set.with(reg(part)?);
        }
    }
    Some(set)
}

/// The bytes of a VFP register list (`{d8, d9}`, `{s16-s31}`).
fn vfp_list_bytes(s: &str) -> Option<u32> {
    let inner = s.trim().strip_prefix('{')?.strip_suffix('}')?;
    let mut bytes = 0;
    for part in inner.split(',') {
        let part = part.trim();
        let (a, b) = part.split_once('-').unwrap_or((part, part));
        let size = match a.chars().next()? {
            'd' => 8,
            's' => 4,
            _ => return None,
        };
        let n = |r: &str| r.trim()[1..].parse::<u32>().ok();
        bytes += size * (n(b)?.checked_sub(n(a)?)? + 1);
    }
    Some(bytes)
}

/// `#0x1c`, `#12`, `#-0x10`.
pub fn parse_imm(s: &str) -> Option<i64> {
    let s = s.trim().strip_prefix('#')?;
    let (neg, digits) = match s.strip_prefix('-') {
        Some(d) => (true, d),
        None => (false, s),
    };
    let v = match digits.strip_prefix("0x") {
        Some(h) => i64::from_str_radix(h, 16).ok()?,
        None => digits.parse::<i64>().ok()?,
    };
    Some(if neg { -v } else { v })
}

/// `0x8004ba8` (a branch target, with or without its `<symbol>`).
fn parse_address(s: &str) -> Option<u32> {
    let s = s.split_whitespace().next()?;
    u32::from_str_radix(s.strip_prefix("0x")?, 16).ok()
}

fn target(ops: &[String]) -> Option<u32> {
    parse_address(ops.first()?)
}

/// `[rB]` or `[rB, #n]`.
fn mem_operand(s: &str) -> Option<(Reg, i32)> {
    let inner = s.trim().strip_prefix('[')?.strip_suffix(']')?;
    let mut parts = inner.split(',').map(str::trim);
    let base = reg(parts.next()?)?;
    let offset = match parts.next() {
        None => 0,
        Some(p) => i32::try_from(parse_imm(p)?).ok()?,
    };
    parts.next().is_none().then_some((base, offset))
}

/// `[rB, rI]`.
fn mem_index_operand(s: &str) -> Option<(Reg, Reg)> {
    let inner = s.trim().strip_prefix('[')?.strip_suffix(']')?;
    let mut parts = inner.split(',').map(str::trim);
    let base = reg(parts.next()?)?;
    let index = reg(parts.next()?)?;
    parts.next().is_none().then_some((base, index))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn op(m: &str, ops: &str) -> Op {
        decode(0x0800_0100, m, ops, false).unwrap().0
    }

    #[test]
    fn stack_forms() {
        let grow = |bytes| Op::Grow {
            bytes,
            saves: Regs::NONE,
        };
        assert_eq!(
            op("push", "{r4, r5, r6, r7, lr}"),
            Op::Grow {
                bytes: 20,
                saves: Regs(0b0100_0000_1111_0000)
            }
        );
        assert!(matches!(
            op("push.w", "{r8, r9, r10, r11}"),
            Op::Grow { bytes: 16, .. }
        ));
        assert!(matches!(
            op("stmdb", "sp!, {r4-r11}"),
            Op::Grow { bytes: 32, .. }
        ));
        assert!(matches!(
            op("str", "r11, [sp, #-4]!"),
            Op::Grow { bytes: 4, .. }
        ));
        assert_eq!(op("sub", "sp, #0x10"), grow(16));
        assert_eq!(op("sub.w", "sp, sp, #0x400"), grow(1024));
        assert_eq!(op("subw", "sp, sp, #1234"), grow(1234));
        assert_eq!(op("sub", "sp, r4"), Op::GrowBy(4));
        assert_eq!(op("vpush", "{d8, d9, d10}"), grow(24));
        assert_eq!(op("add", "sp, #0x10"), Op::Shrink { bytes: 16 });
        assert_eq!(op("pop", "{r4, r5, r7, pc}"), Op::PopReturn { bytes: 16 });
        assert_eq!(op("ldr", "r11, [sp], #4"), Op::Shrink { bytes: 4 });
        assert_eq!(op("ldr", "pc, [sp], #4"), Op::PopReturn { bytes: 4 });
        assert_eq!(op("mov", "sp, r7"), Op::SetSp { src: 7, add: 0 });
        assert_eq!(op("sub.w", "sp, r7, #0x10"), Op::SetSp { src: 7, add: -16 });
        assert_eq!(op("msr", "msp, r2"), Op::ResetStack(2));
        assert_eq!(op("cpsid", "i"), Op::Mask(true));
        assert_eq!(op("cpsie", "i"), Op::Mask(false));
        assert_eq!(op("msr", "primask, r4"), Op::SetMask(4));
        assert_eq!(op("mrs", "r4, primask"), Op::ReadMask(4));
    }

    #[test]
    fn unknown_stack_writes_are_errors() {
        for (m, ops) in [
            ("ldr", "sp, [r0]"),
            ("ldr", "pc, [r0, #4]"),
            ("add", "pc, r0"),
        ] {
            let e = decode(0x0800_0100, m, ops, false).unwrap_err();
            assert!(e.contains("0x8000100"), "{e}");
        }
    }

    #[test]
    fn control_forms() {
        assert_eq!(op("bl", "0x8004ba8 <defmt::x>"), Op::Call(0x0800_4ba8));
        assert_eq!(op("blx", "r5"), Op::CallReg(5));
        assert_eq!(op("bx", "lr"), Op::Return);
        assert_eq!(op("bx", "r1"), Op::JumpReg(1));
        let (o, cond, _, _, _) = decode(0x100, "bhi.w", "0x800071a <f+0x56e>", false).unwrap();
        assert_eq!((o, cond), (Op::Jump(0x0800_071a), true));
        let (o, cond, _, _, _) = decode(0x100, "blt", "0x200 <f>", false).unwrap();
        assert_eq!((o, cond), (Op::Jump(0x200), true));
        let (o, cond, _, _, _) = decode(0x100, "bls", "0x200 <f>", true).unwrap();
        assert_eq!((o, cond), (Op::Jump(0x200), true));
        let (o, cond, _, _, _) = decode(0x100, "blls", "0x200 <f>", true).unwrap();
        assert_eq!((o, cond), (Op::Call(0x200), true));
        let (o, cond, _, _, _) = decode(0x100, "popne", "{r4, pc}", true).unwrap();
        assert_eq!((o, cond), (Op::PopReturn { bytes: 8 }, true));
        assert_eq!(
            op("tbh", "[r1, r0, lsl #1]"),
            Op::Table {
                base: TableBase::Reg(1),
                halfwords: true
            }
        );
        assert_eq!(
            op("itte", "ne"),
            Op::It {
                count: 3,
                elses: 0b100
            }
        );
        assert_eq!(op("it", "eq"), Op::It { count: 1, elses: 0 });
    }

    #[test]
    fn constants_and_stores() {
        assert_eq!(
            op("ldr", "r0, [pc, #0x20]"),
            Op::LoadLiteral {
                dst: 0,
                addr: 0x0800_0124
            }
        );
        assert_eq!(
            op("adr.w", "r1, #12"),
            Op::MovImm {
                dst: 1,
                value: 0x0800_0110
            }
        );
        assert_eq!(
            op("movt", "r0, #0xe000"),
            Op::MovTop {
                dst: 0,
                value: 0xe000
            }
        );
        assert_eq!(
            op("strb", "r1, [r0, #0x25]"),
            Op::Store {
                src: 1,
                base: 0,
                offset: 0x25,
                index: None,
                bytes: 1
            }
        );
        let (_, _, w, _, _) = decode(0x100, "ldm", "r2!, {r3}", false).unwrap();
        assert_eq!(w, Regs::NONE.with(2).with(3));
        let (_, _, w, _, _) = decode(0x100, "umull", "r8, r9, r0, r1", false).unwrap();
        assert_eq!(w, Regs::NONE.with(8).with(9));
        let (_, _, w, _, _) = decode(0x100, "str", "r1, [r0], #4", false).unwrap();
        assert_eq!(w, Regs::NONE.with(0));
    }

    #[test]
    fn lines() {
        assert_eq!(
            parse_line("08000130 <__stext>:"),
            Line::Label(0x0800_0130, "__stext".into())
        );
        assert_eq!(
            parse_line(" 8000134:      \tldr\tr0, [pc, #0x20]         @ 0x8000158 <__stext+0x28>"),
            Line::Insn(0x0800_0134, "ldr".into(), "r0, [pc, #0x20]".into())
        );
        assert_eq!(
            parse_line(" 8000158: 60 3d 00 20  \t.word\t0x20003d60"),
            Line::Data(0x0800_0158)
        );
    }
}
