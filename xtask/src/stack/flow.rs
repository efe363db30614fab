//! The analysis of one function: a data-flow pass over its control-flow
//! graph (branches, IT blocks, jump tables) that follows the stack pointer
//! and the registers holding constants or stack addresses.
//!
//! It yields how deep the function's own frame goes, each call with the
//! frame's depth at that point and its callees (calls through a register
//! resolved from the constants it can hold: literal-pool loads, `movw`/
//! `movt`, words read from read-only memory), and the constant stores
//! (which set interrupt priorities).

use std::collections::{BTreeMap, BTreeSet};

use super::image::Image;
use super::insn::{Insn, Op, Reg, Regs, TableBase, LR, PC, SP};

/// At most this many constants are tracked for one register; more are
/// "unknown".
const MAX_CONSTS: usize = 8;

/// What a register holds.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Val {
    /// Nothing known.
    Top,
    /// One of these constants (sorted, at most [`MAX_CONSTS`]).
    Consts(Vec<u32>),
    /// An address in the frame: the entry SP minus this many bytes.
    Stack(i64),
    /// PRIMASK as read (`mrs`): whether interrupts were masked.
    Mask(bool),
}

impl Val {
    fn one(v: u32) -> Val {
        Val::Consts(vec![v])
    }

    fn join(&self, other: &Val) -> Val {
        match (self, other) {
            (a, b) if a == b => a.clone(),
            (Val::Consts(a), Val::Consts(b)) => {
                let mut all: Vec<u32> = a.iter().chain(b).copied().collect();
                all.sort_unstable();
                all.dedup();
                if all.len() > MAX_CONSTS {
                    Val::Top
                } else {
                    Val::Consts(all)
                }
            }
            _ => Val::Top,
        }
    }

    fn map(&self, f: impl Fn(u32) -> Option<u32>) -> Val {
        match self {
            Val::Consts(vs) => {
                let mut out = Vec::with_capacity(vs.len());
                for &v in vs {
                    match f(v) {
                        Some(w) => out.push(w),
                        None => return Val::Top,
                    }
                }
                out.sort_unstable();
                out.dedup();
                Val::Consts(out)
            }
            _ => Val::Top,
        }
    }

    fn single(&self) -> Option<u32> {
        match self {
            Val::Consts(v) if v.len() == 1 => Some(v[0]),
            _ => None,
        }
    }
}

/// Which way an IT block's condition went on a path: the two ways are
/// followed apart through the block (its instructions often pop the frame
/// on one way only), then joined.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Track {
    /// Outside an IT block.
    Out,
    /// The condition held.
    Then,
    /// The condition failed.
    Else,
    /// An instruction in the block changed the flags: either way.
    Unknown,
}

/// The machine state at one instruction.
#[derive(Clone, Debug, PartialEq, Eq)]
struct State {
    /// Bytes below the entry SP (below the fresh stack's top once `fresh`).
    depth: i64,
    /// After `msr msp`: the stack started afresh.
    fresh: bool,
    /// The IT block's way.
    it: Track,
    /// Interrupts masked (PRIMASK set): no preemption here.
    masked: bool,
    regs: [Val; 16],
}

impl State {
    fn join(&self, other: &State, at: u32, image: &Image) -> Result<State, String> {
        if self.depth != other.depth || self.fresh != other.fresh {
            return Err(format!(
                "two paths reach {} with different stack depths ({} and {} B)",
                image.name(at),
                self.depth,
                other.depth
            ));
        }
        let mut regs = self.regs.clone();
        for (r, o) in regs.iter_mut().zip(&other.regs) {
            *r = r.join(o);
        }
        Ok(State {
            depth: self.depth,
            fresh: self.fresh,
            it: self.it,
            // Masked only if masked on both ways.
            masked: self.masked && other.masked,
            regs,
        })
    }
}

/// Whom a call reaches.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Callee {
    /// These functions (a direct call, or a register holding one of
    /// these addresses).
    Known(Vec<u32>),
    /// A function pointer the analysis cannot resolve.
    Unknown,
}

/// A call (or a tail call) in a function.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Site {
    /// The call instruction's address.
    pub at: u32,
    /// The frame's depth there (the callee's frame starts below it).
    pub depth: u32,
    /// On a fresh stack (after `msr msp`).
    pub fresh: bool,
    /// With interrupts masked.
    pub masked: bool,
    /// Whom it calls.
    pub callee: Callee,
}

/// A store of a constant address (the value `None` if not a constant).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Store {
    /// The byte address written.
    pub addr: u32,
    /// The value written, if constant.
    pub value: Option<u32>,
    /// Its width.
    pub bytes: u8,
}

/// What callers need to know about a callee.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Facts {
    /// The registers a call to it may change.
    pub clobbers: Regs,
    /// Whether a call to it may return.
    pub returns: bool,
}

impl Facts {
    /// A function called through a pointer: the procedure call standard
    /// holds (r4–r11 preserved), and it may return.
    pub const AAPCS: Facts = Facts {
        clobbers: Regs::CALLER_SAVED,
        returns: true,
    };
}

/// One function's analysis.
#[derive(Clone, Debug)]
pub struct Summary {
    /// The deepest its own frame goes below the entry SP.
    pub frame: u32,
    /// The deepest its own frame goes on a fresh stack, if it starts one.
    pub fresh_frame: Option<u32>,
    /// The deepest its own frame goes where interrupts may preempt it
    /// (`None`: nowhere).
    pub open_frame: Option<u32>,
    /// Its calls and tail calls.
    pub sites: Vec<Site>,
    /// Its stores to constant addresses.
    pub stores: Vec<Store>,
    /// What a call to it means for its caller.
    pub facts: Facts,
    /// Functions whose addresses it stores to memory, passes to a call or
    /// returns: they may be called through a pointer elsewhere.
    pub escapes: BTreeSet<u32>,
    /// The literal-pool words it loads as constants.
    pub literals: BTreeSet<u32>,
}

/// Analyses the function at `entry`, entered with interrupts masked or
/// not; `callee` gives what is known of the functions it calls.
pub fn analyse(
    image: &Image,
    entry: u32,
    masked: bool,
    callee: &mut dyn FnMut(u32) -> Result<Facts, String>,
) -> Result<Summary, String> {
    let mut states: BTreeMap<(u32, Track), State> = BTreeMap::new();
    let mut work = vec![(entry, Track::Out)];
    states.insert(
        (entry, Track::Out),
        State {
            depth: 0,
            fresh: false,
            it: Track::Out,
            masked,
            regs: std::array::from_fn(|_| Val::Top),
        },
    );
    let mut f = Walk {
        image,
        entry,
        entry_masked: masked,
        frame: 0,
        fresh_frame: None,
        open_frame: None,
        sites: BTreeMap::new(),
        stores: BTreeMap::new(),
        writes: Regs::NONE,
        saves: Regs::NONE,
        escapes: BTreeSet::new(),
        literals: BTreeSet::new(),
        tail_clobbers: Regs::NONE,
        restoring_tail_clobbers: Regs::NONE,
        returns: false,
    };
    let mut steps = 0usize;
    while let Some(key) = work.pop() {
        steps += 1;
        if steps > 200_000 {
            return Err(format!(
                "{}: the analysis does not converge",
                image.name(entry)
            ));
        }
        let state = states[&key].clone();
        let at = key.0;
        let insn = image.insns.get(&at).ok_or_else(|| {
            format!(
                "{}: control reaches {}, which is not an instruction",
                image.name(entry),
                image.name(at)
            )
        })?;
        for (next, s) in f.step(insn, &state, callee)? {
            let key = (next, s.it);
            match states.get(&key) {
                None => {
                    states.insert(key, s);
                    work.push(key);
                }
                Some(old) => {
                    let joined = old.join(&s, next, image)?;
                    if &joined != old {
                        states.insert(key, joined);
                        work.push(key);
                    }
                }
            }
        }
    }
    Ok(Summary {
        frame: f.frame,
        fresh_frame: f.fresh_frame,
        open_frame: f.open_frame,
        sites: f.sites.into_values().collect(),
        stores: f.stores.into_values().flatten().collect(),
        facts: Facts {
            clobbers: f
                .writes
                .with(LR)
                .or(f.restoring_tail_clobbers)
                .minus(f.saves)
                .or(f.tail_clobbers)
                .minus(Regs::NONE.with(SP).with(PC)),
            returns: f.returns,
        },
        escapes: f.escapes,
        literals: f.literals,
    })
}

/// The walk's findings so far.
struct Walk<'a> {
    image: &'a Image,
    entry: u32,
    entry_masked: bool,
    frame: u32,
    fresh_frame: Option<u32>,
    open_frame: Option<u32>,
    sites: BTreeMap<u32, Site>,
    stores: BTreeMap<u32, Vec<Store>>,
    writes: Regs,
    saves: Regs,
    escapes: BTreeSet<u32>,
    literals: BTreeSet<u32>,
    /// What the functions tail-called at depth 0 may change.
    tail_clobbers: Regs,
    /// What the functions tail-called with the frame still in place may
    /// change: they pop the frame (outlined epilogues), so the registers
    /// it saved come back restored.
    restoring_tail_clobbers: Regs,
    returns: bool,
}

impl Walk<'_> {
    fn err(&self, insn: &Insn, why: &str) -> String {
        format!(
            "{}: at {} `{}`: {why}",
            self.image.name(self.entry),
            self.image.name(insn.addr),
            insn.text
        )
    }

    /// The targets a register may hold, as functions.
    fn targets(&self, v: &Val) -> Callee {
        match v {
            Val::Consts(vs) if vs.iter().all(|&a| a & 1 == 1) => {
                Callee::Known(vs.iter().map(|&a| a & !1).collect())
            }
            _ => Callee::Unknown,
        }
    }

    /// What a call to `callee` does to the caller's registers and flow.
    fn facts(
        &self,
        c: &Callee,
        callee: &mut dyn FnMut(u32) -> Result<Facts, String>,
    ) -> Result<Facts, String> {
        match c {
            Callee::Unknown => Ok(Facts::AAPCS),
            Callee::Known(ts) => {
                let mut all = Facts {
                    clobbers: Regs::NONE,
                    returns: false,
                };
                for &t in ts {
                    let f = callee(t)?;
                    all.clobbers = all.clobbers.or(f.clobbers);
                    all.returns |= f.returns;
                }
                Ok(all)
            }
        }
    }

    fn site(&mut self, insn: &Insn, s: &State, callee: Callee) -> Result<(), String> {
        let depth = u32::try_from(s.depth.max(0)).map_err(|_| self.err(insn, "depth"))?;
        self.sites.insert(
            insn.addr,
            Site {
                at: insn.addr,
                depth,
                fresh: s.fresh,
                masked: s.masked,
                callee,
            },
        );
        Ok(())
    }

    /// Executes one instruction; returns its successors and their states.
    fn step(
        &mut self,
        insn: &Insn,
        s: &State,
        callee: &mut dyn FnMut(u32) -> Result<Facts, String>,
    ) -> Result<Vec<(u32, State)>, String> {
        // Inside an IT block, the path's way decides whether it runs.
        let runs = match (insn.it, s.it) {
            (Some(slot), Track::Then) => Some(slot.then),
            (Some(slot), Track::Else) => Some(!slot.then),
            _ => None,
        };
        let track = match insn.it {
            Some(slot) if slot.last => Track::Out,
            Some(_) if insn.sets_flags && runs != Some(false) => Track::Unknown,
            Some(_) => s.it,
            None => Track::Out,
        };
        let s = &State {
            it: track,
            ..s.clone()
        };
        if !s.masked && !s.fresh {
            let d = u32::try_from(s.depth.max(0)).unwrap_or(u32::MAX);
            self.open_frame = Some(self.open_frame.unwrap_or(0).max(d));
        }
        if runs == Some(false) {
            return Ok(insn.next.map(|n| (n, s.clone())).into_iter().collect());
        }
        let conditional = match insn.it {
            Some(_) => runs.is_none(),
            None => insn.cond,
        };
        if let Op::It { .. } = insn.op {
            let next = insn
                .next
                .ok_or_else(|| self.err(insn, "an IT block without instructions"))?;
            let way = |it| (next, State { it, ..s.clone() });
            return Ok(vec![way(Track::Then), way(Track::Else)]);
        }
        // Function addresses leaving the registers: stored, passed to a
        // call, returned.
        let leaving = match insn.op {
            Op::Call(_) | Op::CallReg(_) | Op::JumpReg(_) => Regs(0b1111),
            Op::Jump(t) if t != self.entry && self.image.functions.contains_key(&t) => Regs(0b1111),
            Op::Return | Op::PopReturn { .. } => Regs(0b11),
            _ => Regs::NONE,
        };
        for r in insn.stored.or(leaving).iter() {
            if let Val::Consts(vs) = &s.regs[usize::from(r)] {
                let image = self.image;
                self.escapes
                    .extend(vs.iter().filter_map(|&v| image.function_address(v)));
            }
        }
        let mut out = s.clone();
        for r in insn.writes.iter() {
            out.regs[usize::from(r)] = Val::Top;
        }
        self.writes = self.writes.or(insn.writes);
        let fall = |st: State| insn.next.map(|n| (n, st)).into_iter().collect::<Vec<_>>();
        // Successors when the instruction ends the path (a return, a tail
        // call): the next instruction only if it was conditional.
        let skip = if conditional {
            fall(s.clone())
        } else {
            Vec::new()
        };
        let reg = |r: Reg| &s.regs[usize::from(r)];
        let konst = |r: Reg| match reg(r) {
            Val::Consts(vs) => vs.iter().copied().max(),
            _ => None,
        };
        match &insn.op {
            Op::Unknown(why) => return Err(self.err(insn, why)),
            Op::Grow { bytes, saves } => {
                out.depth += i64::from(*bytes);
                if !s.fresh {
                    self.saves = self.saves.or(*saves);
                }
            }
            Op::GrowBy(r) => match konst(*r) {
                Some(n) => out.depth += i64::from(n),
                None => {
                    return Err(self.err(
                        insn,
                        "the stack grows by an amount the analysis cannot bound",
                    ))
                }
            },
            Op::Shrink { bytes } => out.depth -= i64::from(*bytes),
            Op::ShrinkBy(r) => match reg(*r).single() {
                Some(n) => out.depth -= i64::from(n),
                None => return Err(self.err(insn, "the stack shrinks by an unknown amount")),
            },
            Op::SetSp { src, add } => match reg(*src) {
                Val::Stack(d) => out.depth = d - i64::from(*add),
                _ => {
                    return Err(
                        self.err(insn, "SP is set from a register the analysis cannot follow")
                    )
                }
            },
            Op::ResetStack(_) => {
                out.depth = 0;
                out.fresh = true;
            }
            Op::Mask(m) => out.masked = *m,
            Op::SetMask(r) => {
                // A value the analysis cannot follow is a critical
                // section's saved state (critical-section's `release`, the
                // logger's): it restores interrupts as they were when the
                // section began, in the context this function was entered
                // in.
                out.masked = match reg(*r) {
                    Val::Mask(m) => *m,
                    Val::Consts(vs) => vs.iter().all(|v| v & 1 == 1),
                    _ => self.entry_masked,
                };
            }
            Op::ReadMask(r) => out.regs[usize::from(*r)] = Val::Mask(s.masked),
            Op::PopReturn { .. } | Op::Return => {
                if !s.fresh {
                    self.returns = true;
                }
                return Ok(skip);
            }
            Op::Trap => return Ok(skip),
            Op::Call(t) => {
                let c = Callee::Known(vec![*t]);
                return self.call(insn, s, out, c, conditional, callee);
            }
            Op::CallReg(r) => {
                let c = self.targets(reg(*r));
                return self.call(insn, s, out, c, conditional, callee);
            }
            Op::Jump(t) => {
                if *t != self.entry && self.image.functions.contains_key(t) {
                    let c = Callee::Known(vec![*t]);
                    return self.tail(insn, s, c, callee, skip);
                }
                let mut succ = vec![(
                    *t,
                    State {
                        it: Track::Out,
                        ..out
                    },
                )];
                if conditional {
                    succ.extend(fall(s.clone()));
                }
                return Ok(succ);
            }
            Op::JumpReg(r) => {
                let c = self.targets(reg(*r));
                return self.tail(insn, s, c, callee, skip);
            }
            Op::Table { base, halfwords } => {
                let table = match base {
                    TableBase::Pc => insn.addr + 4,
                    TableBase::Reg(r) => reg(*r)
                        .single()
                        .ok_or_else(|| self.err(insn, "a jump table at an unknown address"))?,
                };
                let targets = self.table_targets(insn, table, *halfwords);
                if targets.is_empty() {
                    return Err(self.err(insn, "a jump table the analysis cannot read"));
                }
                return Ok(targets.into_iter().map(|t| (t, out.clone())).collect());
            }
            Op::LoadLiteral { dst, addr } => {
                self.literals.insert(*addr);
                out.regs[usize::from(*dst)] = match self.image.word(*addr) {
                    Some(w) => Val::one(w),
                    None => Val::Top,
                };
            }
            Op::Load { dst, base, offset } => {
                let image = self.image;
                out.regs[usize::from(*dst)] =
                    reg(*base).map(|a| image.word(a.wrapping_add_signed(*offset)));
            }
            Op::MovImm { dst, value } => out.regs[usize::from(*dst)] = Val::one(*value),
            Op::MovTop { dst, value } => {
                out.regs[usize::from(*dst)] = reg(*dst).map(|v| Some((v & 0xffff) | (value << 16)));
            }
            Op::Copy { dst, src } => {
                out.regs[usize::from(*dst)] = match *src {
                    SP => Val::Stack(s.depth),
                    PC => Val::Top,
                    r => reg(r).clone(),
                };
            }
            Op::AddImm { dst, src, imm } => {
                out.regs[usize::from(*dst)] = match (*src, reg(*src)) {
                    (SP, _) => Val::Stack(s.depth - i64::from(*imm)),
                    (_, Val::Stack(d)) => Val::Stack(d - i64::from(*imm)),
                    (_, v) => v.map(|a| Some(a.wrapping_add_signed(*imm))),
                };
            }
            Op::Store {
                src,
                base,
                offset,
                index,
                bytes,
            } => {
                let mut addr = reg(*base).map(|a| Some(a.wrapping_add_signed(*offset)));
                if let Some(i) = index {
                    addr = match (addr.single(), reg(*i).single()) {
                        (Some(a), Some(i)) => Val::one(a.wrapping_add(i)),
                        _ => Val::Top,
                    };
                }
                if let Val::Consts(addrs) = addr {
                    let value = reg(*src).single();
                    let many = addrs.len() > 1;
                    let stores = addrs
                        .into_iter()
                        .map(|addr| Store {
                            addr,
                            value: if many { None } else { value },
                            bytes: *bytes,
                        })
                        .collect();
                    self.stores.insert(insn.addr, stores);
                }
            }
            Op::It { .. } | Op::Other => {}
        }
        if out.fresh {
            let d = u32::try_from(out.depth.max(0)).unwrap_or(u32::MAX);
            self.fresh_frame = Some(self.fresh_frame.unwrap_or(0).max(d));
        } else {
            self.frame = self
                .frame
                .max(u32::try_from(out.depth.max(0)).unwrap_or(u32::MAX));
        }
        let after = if conditional {
            s.join(&out, insn.addr, self.image)?
        } else {
            out
        };
        match insn.next {
            Some(n) => Ok(vec![(n, after)]),
            None => Err(self.err(insn, "the code runs into data")),
        }
    }

    fn call(
        &mut self,
        insn: &Insn,
        s: &State,
        mut out: State,
        c: Callee,
        conditional: bool,
        callee: &mut dyn FnMut(u32) -> Result<Facts, String>,
    ) -> Result<Vec<(u32, State)>, String> {
        let facts = self.facts(&c, callee)?;
        self.site(insn, s, c)?;
        for r in facts.clobbers.with(LR).iter() {
            out.regs[usize::from(r)] = Val::Top;
        }
        // A callee that never returns changes nothing its caller sees.
        if facts.returns {
            self.writes = self.writes.or(facts.clobbers);
        }
        let mut succ = Vec::new();
        if let Some(n) = insn.next {
            if facts.returns && !self.image.functions.contains_key(&n) {
                succ.push((n, out));
            }
            if conditional {
                succ.push((n, s.clone()));
            }
        }
        Ok(succ)
    }

    fn tail(
        &mut self,
        insn: &Insn,
        s: &State,
        c: Callee,
        callee: &mut dyn FnMut(u32) -> Result<Facts, String>,
        skip: Vec<(u32, State)>,
    ) -> Result<Vec<(u32, State)>, String> {
        let facts = self.facts(&c, callee)?;
        self.site(insn, s, c)?;
        if !facts.returns {
            // Nothing to see for the caller.
        } else if s.depth > 0 {
            self.restoring_tail_clobbers = self.restoring_tail_clobbers.or(facts.clobbers);
        } else {
            self.tail_clobbers = self.tail_clobbers.or(facts.clobbers);
        }
        if !s.fresh {
            self.returns |= facts.returns;
        }
        Ok(skip)
    }

    /// A jump table's targets: its entries, up to the first one that does
    /// not lead to an instruction of the same function beyond the table
    /// (the padding or the literal pool after the table; LLVM places the
    /// code a table leads to after it), and never past the data that
    /// holds the table.
    fn table_targets(&self, insn: &Insn, table: u32, halfwords: bool) -> Vec<u32> {
        let image = self.image;
        let func = image.function_at(insn.addr).map(|(s, _)| s);
        let end = image
            .insns
            .range(table..)
            .next()
            .map(|(a, _)| *a)
            .unwrap_or(u32::MAX);
        let width = if halfwords { 2 } else { 1 };
        let mut targets = Vec::new();
        let mut at = table;
        while at + width <= end {
            let Some(b) = image.bytes(at, width) else {
                break;
            };
            let entry = if halfwords {
                u32::from(u16::from_le_bytes([b[0], b[1]]))
            } else {
                u32::from(b[0])
            };
            let t = insn.addr + 4 + 2 * entry;
            let same_function = image.function_at(t).map(|(s, _)| s) == func;
            if t <= table || !image.insns.contains_key(&t) || !same_function {
                break;
            }
            targets.push(t);
            at += width;
        }
        targets.sort_unstable();
        targets.dedup();
        targets
    }
}
