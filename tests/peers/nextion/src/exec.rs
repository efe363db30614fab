//! Executing one instruction (NIS §2 assignments, §3 operational commands,
//! §6 system variables) and reporting its result (NIS 6.13, §7).

use crate::codes;
use crate::contract::{self, Attr, ComponentSpec};
use crate::parse::{self, AssignOp, Instr, Seg};
use crate::screen::{Executed, NoteKind, Screen, ScreenError};

/// A value an operand or `get` yields.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Value {
    Num(i32),
    Text(Vec<u8>),
}

/// Where an assignment goes.
#[derive(Clone, Copy, Debug)]
enum Target {
    Attr(&'static ComponentSpec, Attr),
    Sys(&'static str),
}

/// System variables (NIS §6): name, min, max, writable. `dp`, `baud`,
/// `bauds`, `ussp`, `thsp`, `wup` and `delay` have their own rules.
const SYSVARS: &[(&str, i64, i64, bool)] = &[
    ("dp", 0, 255, true),
    ("dim", 0, 100, true),
    ("dims", 0, 100, true),
    ("baud", 0, 921_600, true),
    ("bauds", 0, 921_600, true),
    ("spax", 0, 65_535, true),
    ("spay", 0, 65_535, true),
    ("thc", 0, 65_535, true),
    ("thdra", 0, 1, true),
    ("ussp", 0, 65_535, true),
    ("thsp", 0, 65_535, true),
    ("thup", 0, 1, true),
    ("sendxy", 0, 1, true),
    ("delay", -1, 65_535, true),
    ("sleep", 0, 1, true),
    ("bkcmd", 0, 3, true),
    ("rand", 0, 0, false),
    ("sys0", i32::MIN as i64, i32::MAX as i64, true),
    ("sys1", i32::MIN as i64, i32::MAX as i64, true),
    ("sys2", i32::MIN as i64, i32::MAX as i64, true),
    ("wup", 0, 255, true),
    ("usup", 0, 1, true),
    ("tch0", 0, 0, false),
    ("tch1", 0, 0, false),
    ("tch2", 0, 0, false),
    ("tch3", 0, 0, false),
    ("addr", 0, 2815, true),
    ("recmod", 0, 1, true),
];

/// Valid baud rates (NIS 6.3).
const BAUDS: &[u32] = &[
    2400, 4800, 9600, 19200, 31250, 38400, 57600, 115_200, 230_400, 250_000, 256_000, 512_000,
    921_600,
];

/// What a successful instruction reports: `Ack` the 0x01 of bkcmd 1/3;
/// `Data` instructions answer with their data only.
enum Done {
    Ack,
    Data,
}

type Outcome = Result<Done, u8>;

impl Screen {
    /// Execute one complete instruction at `at_us` and report its result.
    pub(crate) fn execute(&mut self, at_us: u64, bytes: &[u8]) {
        if self.sys.sleep && !allowed_asleep(bytes) {
            self.note(
                at_us,
                NoteKind::IgnoredAsleep,
                String::from_utf8_lossy(bytes).into_owned(),
            );
            return;
        }
        let outcome = match parse::instruction(bytes) {
            Instr::Empty => match self.cfg.empty_instruction {
                None => {
                    self.executed.push(Executed {
                        at_us,
                        instruction: Vec::new(),
                        failure: None,
                    });
                    return;
                }
                Some(code) => Err(code),
            },
            Instr::Assign { target, op, value } => self.assign(at_us, target, op, value),
            Instr::Command { name, params } => self.command(at_us, bytes, name, &params),
            Instr::Bare => Err(codes::INVALID_VARIABLE),
            Instr::Invalid => Err(codes::INVALID_INSTRUCTION),
        };
        let failure = outcome.as_ref().err().copied();
        self.executed.push(Executed {
            at_us,
            instruction: bytes.to_vec(),
            failure,
        });
        let ack = matches!(outcome, Ok(Done::Ack));
        if failure.is_some() || ack {
            let sent = codes::reported(self.sys.bkcmd, failure);
            if let Some(code) = failure {
                self.errors.push(ScreenError {
                    at_us,
                    code,
                    instruction: bytes.to_vec(),
                    sent,
                });
            }
            if sent {
                let code = failure.unwrap_or(codes::SUCCESS);
                self.tx.send(at_us, &codes::frame(code, &[]));
            }
        }
    }

    // ----- names ------------------------------------------------------------

    /// Resolve a component path (segments before the attribute).
    fn component(&self, segs: &[Seg<'_>]) -> Result<&'static ComponentSpec, u8> {
        let (page, comp) = match segs {
            [c] => (self.page_spec(self.dp).ok_or(codes::INVALID_VARIABLE)?, c),
            [p, c] => {
                let page = match *p {
                    Seg::Ident(n) => self.page_named(n),
                    Seg::Index(b'p', id) => u8::try_from(id).ok().and_then(|i| self.page_spec(i)),
                    Seg::Index(..) => None,
                }
                .ok_or(codes::INVALID_VARIABLE)?;
                (page, c)
            }
            _ => return Err(codes::INVALID_VARIABLE),
        };
        let c = match *comp {
            Seg::Ident(n) => page.component(n),
            Seg::Index(b'b', id) => u8::try_from(id).ok().and_then(|i| page.component_id(i)),
            Seg::Index(..) => None,
        }
        .ok_or(codes::INVALID_VARIABLE)?;
        // A local component exists only while its page is loaded.
        if c.page != self.dp && !c.global() {
            return Err(codes::INVALID_VARIABLE);
        }
        Ok(c)
    }

    fn target(&self, name: &[u8]) -> Result<Target, u8> {
        let segs = parse::name(name)?;
        match segs.as_slice() {
            [Seg::Ident(n)] => SYSVARS
                .iter()
                .find(|v| v.0 == *n)
                .map(|v| Target::Sys(v.0))
                .ok_or(codes::INVALID_VARIABLE),
            [path @ .., Seg::Ident(attr)] if !path.is_empty() => {
                let c = self.component(path)?;
                let a = contract::attr(c.kind, attr).ok_or(codes::INVALID_VARIABLE)?;
                Ok(Target::Attr(c, a))
            }
            _ => Err(codes::INVALID_VARIABLE),
        }
    }

    fn read(&mut self, t: Target) -> Value {
        match t {
            Target::Sys(n) => Value::Num(self.read_sys(n)),
            Target::Attr(c, a) => {
                let st = self.comps.get(&(c.page, c.id));
                match (a.name, st) {
                    ("txt", Some(s)) => Value::Text(s.txt.clone()),
                    ("val", Some(s)) => Value::Num(s.val),
                    (name, s) => Value::Num(
                        s.and_then(|s| s.attrs.get(name).copied())
                            .unwrap_or_else(|| self.design_attr(c, name)),
                    ),
                }
            }
        }
    }

    fn design_attr(&self, c: &ComponentSpec, name: &str) -> i32 {
        match name {
            "type" => c.kind.type_code(),
            "id" => i32::from(c.id),
            "vscope" => i32::from(c.global()),
            "txt_maxl" => i32::try_from(self.txt_maxl(c)).unwrap_or(i32::MAX),
            "key" => i32::from(c.keyboard),
            "vvs1" => match c.kind {
                contract::Kind::Xfloat { decimals } => i32::from(decimals),
                _ => 0,
            },
            _ => 0,
        }
    }

    pub(crate) fn txt_maxl(&self, c: &ComponentSpec) -> usize {
        self.cfg.txt_maxl.max(c.design_txt.len())
    }

    fn read_sys(&mut self, n: &str) -> i32 {
        let s = &mut self.sys;
        match n {
            "dp" => i32::from(self.dp),
            "dim" => s.dim,
            "dims" => s.dims,
            "baud" => i32::try_from(self.tx.baud()).unwrap_or(i32::MAX),
            "bauds" => i32::try_from(s.bauds).unwrap_or(i32::MAX),
            "bkcmd" => i32::from(s.bkcmd),
            "sleep" => i32::from(s.sleep),
            "thup" => s.thup,
            "usup" => s.usup,
            "ussp" => s.ussp,
            "thsp" => s.thsp,
            "wup" => s.wup,
            "sendxy" => s.sendxy,
            "sys0" => s.sys[0],
            "sys1" => s.sys[1],
            "sys2" => s.sys[2],
            "rand" => {
                // xorshift32: deterministic, the model has no entropy.
                let mut x = s.rand_state;
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                s.rand_state = x;
                x as i32
            }
            other => s.other.get(other).copied().unwrap_or(0),
        }
    }

    /// A numeric expression (NIS 1.12: left to right).
    fn eval_num(&mut self, at_us: u64, s: &[u8]) -> Result<i32, u8> {
        let (operands, ops) = parse::numeric_terms(s)?;
        let mut acc = self.operand(at_us, operands[0])?;
        for (op, o) in ops.iter().zip(&operands[1..]) {
            let v = self.operand(at_us, o)?;
            acc = parse::apply(*op, acc, v).ok_or(codes::INVALID_OPERATION)?;
        }
        Ok(acc)
    }

    fn operand(&mut self, at_us: u64, o: &[u8]) -> Result<i32, u8> {
        if let Some((v, wrapped)) = parse::number(o)? {
            if wrapped {
                self.note(
                    at_us,
                    NoteKind::ValueWrapped,
                    format!("{} taken as {v}", String::from_utf8_lossy(o)),
                );
            }
            return Ok(v);
        }
        // NIS 7.12: `j0.val=abc` is an invalid operation; a dotted name that
        // does not exist is an invalid variable.
        let t = self.target(o).map_err(|e| {
            if o.contains(&b'.') {
                e
            } else {
                codes::INVALID_OPERATION
            }
        })?;
        match self.read(t) {
            Value::Num(v) => Ok(v),
            Value::Text(_) => Err(codes::INVALID_OPERATION),
        }
    }

    /// A text expression: quoted texts and text attributes joined by `+`.
    fn eval_text(&mut self, s: &[u8]) -> Result<Vec<u8>, u8> {
        let mut out = Vec::new();
        for term in parse::split_outside_quotes(s, b'+') {
            if term.starts_with(b"\"") {
                out.extend(parse::text_literal(term)?);
                continue;
            }
            if term.is_empty() || !term.contains(&b'.') {
                // `t0.txt=abc`, `t0.txt=23` (NIS 7.12).
                return Err(codes::INVALID_OPERATION);
            }
            let t = self.target(term)?;
            match self.read(t) {
                Value::Text(v) => out.extend(v),
                Value::Num(_) => return Err(codes::INVALID_OPERATION),
            }
        }
        Ok(out)
    }

    /// A `get`/`print` operand: a number, a quoted text, or an attribute.
    fn eval_any(&mut self, at_us: u64, s: &[u8]) -> Result<Value, u8> {
        if s.starts_with(b"\"") {
            return self.eval_text(s).map(Value::Text);
        }
        if parse::number(s)?.is_some() || s.iter().any(|b| b"+-*/%".contains(b)) {
            return self.eval_num(at_us, s).map(Value::Num);
        }
        let t = self.target(s)?;
        Ok(self.read(t))
    }

    // ----- assignments ------------------------------------------------------

    fn assign(&mut self, at_us: u64, target: &[u8], op: AssignOp, value: &[u8]) -> Outcome {
        let t = self.target(target)?;
        match t {
            Target::Attr(c, a) => {
                if !a.writable {
                    return Err(codes::ASSIGNMENT_FAILED);
                }
                if a.text {
                    self.assign_text(at_us, c, op, value)?;
                } else {
                    let old = match self.read(t) {
                        Value::Num(v) => v,
                        Value::Text(_) => 0,
                    };
                    let v = self.combine(at_us, old, op, value)?;
                    if let Some(st) = self.comps.get_mut(&(c.page, c.id)) {
                        if a.name == "val" {
                            st.val = v;
                        } else {
                            st.attrs.insert(a.name, v);
                        }
                    }
                }
                Ok(Done::Ack)
            }
            Target::Sys(name) => {
                let old = self.read_sys(name);
                let v = self.combine(at_us, old, op, value)?;
                self.set_sys(at_us, name, v)
            }
        }
    }

    fn combine(&mut self, at_us: u64, old: i32, op: AssignOp, value: &[u8]) -> Result<i32, u8> {
        let rhs = match op {
            AssignOp::Inc | AssignOp::Dec => 1,
            _ => self.eval_num(at_us, value)?,
        };
        let sym = match op {
            AssignOp::Set => return Ok(rhs),
            AssignOp::Add | AssignOp::Inc => b'+',
            AssignOp::Sub | AssignOp::Dec => b'-',
            AssignOp::Mul => b'*',
            AssignOp::Div => b'/',
            AssignOp::Rem => b'%',
        };
        parse::apply(sym, old, rhs).ok_or(codes::INVALID_OPERATION)
    }

    fn assign_text(
        &mut self,
        at_us: u64,
        c: &'static ComponentSpec,
        op: AssignOp,
        value: &[u8],
    ) -> Result<(), u8> {
        let old = self
            .comps
            .get(&(c.page, c.id))
            .map(|s| s.txt.clone())
            .unwrap_or_default();
        let mut new = match op {
            AssignOp::Set => self.eval_text(value)?,
            AssignOp::Add => {
                let mut t = old;
                t.extend(self.eval_text(value)?);
                t
            }
            AssignOp::Sub => {
                // NIS 2.3: `t0.txt-=4` removes the last 4 characters.
                let n = self.eval_num(at_us, value)?;
                let keep = old.len().saturating_sub(usize::try_from(n).unwrap_or(0));
                old[..keep].to_vec()
            }
            _ => return Err(codes::INVALID_OPERATION),
        };
        let maxl = self.txt_maxl(c);
        if new.len() > maxl {
            self.note(
                at_us,
                NoteKind::TextTruncated,
                format!("{}: {} bytes cut to txt_maxl {maxl}", c.name, new.len()),
            );
            new.truncate(maxl);
        }
        if let Some(st) = self.comps.get_mut(&(c.page, c.id)) {
            st.txt = new;
        }
        Ok(())
    }

    fn set_sys(&mut self, at_us: u64, name: &'static str, v: i32) -> Outcome {
        let &(_, min, max, writable) = SYSVARS
            .iter()
            .find(|s| s.0 == name)
            .ok_or(codes::INVALID_VARIABLE)?;
        if !writable {
            return Err(codes::ASSIGNMENT_FAILED);
        }
        let wide = i64::from(v);
        match name {
            "baud" | "bauds" => {
                let b = u32::try_from(v)
                    .ok()
                    .filter(|b| BAUDS.contains(b))
                    .ok_or(codes::INVALID_BAUD)?;
                if name == "bauds" {
                    self.sys.bauds = b;
                }
                self.tx.set_baud(at_us, b);
                return Ok(Done::Ack);
            }
            // 0 switches the timer off, else 3..=65535 s.
            "ussp" | "thsp" if (1..3).contains(&wide) => return Err(codes::ASSIGNMENT_FAILED),
            "wup" if v != 255 && self.page_spec(u8::try_from(v).unwrap_or(255)).is_none() => {
                return Err(codes::ASSIGNMENT_FAILED)
            }
            _ => {}
        }
        if !(min..=max).contains(&wide) {
            return Err(codes::ASSIGNMENT_FAILED);
        }
        let s = &mut self.sys;
        match name {
            "dp" => {
                let p = u8::try_from(v).map_err(|_| codes::ASSIGNMENT_FAILED)?;
                if self.page_spec(p).is_none() {
                    return Err(codes::ASSIGNMENT_FAILED);
                }
                self.load_page(at_us, p);
            }
            "dim" => s.dim = v,
            "dims" => {
                s.dim = v;
                s.dims = v;
            }
            "bkcmd" => s.bkcmd = u8::try_from(v).unwrap_or(2),
            "sleep" => {
                if v == 1 {
                    s.sleep = true;
                } else {
                    self.wake(at_us, false);
                }
            }
            "thup" => s.thup = v,
            "usup" => s.usup = v,
            "ussp" => s.ussp = v,
            "thsp" => s.thsp = v,
            "wup" => s.wup = v,
            "sendxy" => {
                s.sendxy = v;
                if v == 1 {
                    self.note(
                        at_us,
                        NoteKind::NotModelled,
                        "sendxy=1: 0x67/0x68 frames are not sent".into(),
                    );
                }
            }
            "sys0" => s.sys[0] = v,
            "sys1" => s.sys[1] = v,
            "sys2" => s.sys[2] = v,
            "delay" => {} // its time is taken in `duration`
            "addr" | "recmod" => {
                if v != 0 {
                    self.note(
                        at_us,
                        NoteKind::NotModelled,
                        format!("{name}={v}: the model keeps the plain protocol"),
                    );
                }
                self.sys.other.insert(name, v);
            }
            other => {
                s.other.insert(other, v);
            }
        }
        Ok(Done::Ack)
    }

    // ----- commands -----------------------------------------------------------

    fn command(&mut self, at_us: u64, bytes: &[u8], name: &str, params: &[&[u8]]) -> Outcome {
        let count = |n: usize| {
            if params.len() == n {
                Ok(())
            } else {
                Err(codes::INVALID_PARAMETER_COUNT)
            }
        };
        match name {
            "page" => {
                count(1)?;
                let p = params[0];
                let spec = match std::str::from_utf8(p).ok() {
                    Some(t) if !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit()) => {
                        t.parse::<u8>().ok().and_then(|id| self.page_spec(id))
                    }
                    Some(t) => self.page_named(t),
                    None => None,
                }
                .ok_or(codes::INVALID_PAGE)?;
                self.load_page(at_us, spec.id);
                Ok(Done::Ack)
            }
            "sendme" => {
                count(0)?;
                self.tx
                    .send(at_us, &codes::frame(codes::CURRENT_PAGE, &[self.dp]));
                Ok(Done::Data)
            }
            "get" => {
                count(1)?;
                let frame = match self.eval_any(at_us, params[0])? {
                    Value::Num(v) => codes::frame(codes::NUMERIC_DATA, &v.to_le_bytes()),
                    Value::Text(t) => codes::frame(codes::STRING_DATA, &t),
                };
                self.tx.send(at_us, &frame);
                Ok(Done::Data)
            }
            "print" | "prints" => {
                count(if name == "print" { 1 } else { 2 })?;
                let mut raw = match self.eval_any(at_us, params[0])? {
                    Value::Num(v) => v.to_le_bytes().to_vec(),
                    Value::Text(t) => t,
                };
                if name == "prints" {
                    let n = self.eval_num(at_us, params[1])?;
                    if n > 0 {
                        raw.truncate(usize::try_from(n).unwrap_or(usize::MAX));
                    }
                }
                self.tx.send(at_us, &raw);
                Ok(Done::Data)
            }
            "printh" => {
                let raw = params
                    .iter()
                    .map(|p| {
                        std::str::from_utf8(p)
                            .ok()
                            .filter(|h| h.len() == 2)
                            .and_then(|h| u8::from_str_radix(h, 16).ok())
                    })
                    .collect::<Option<Vec<u8>>>()
                    .filter(|r| !r.is_empty())
                    .ok_or(codes::INVALID_INSTRUCTION)?;
                self.tx.send(at_us, &raw);
                Ok(Done::Data)
            }
            "vis" | "tsw" => {
                count(2)?;
                let on = self.eval_num(at_us, params[1])? != 0;
                for id in self.component_ids(params[0])? {
                    if let Some(st) = self.comps.get_mut(&(self.dp, id)) {
                        if name == "vis" {
                            st.visible = on;
                        } else {
                            st.touch = on;
                        }
                    }
                }
                Ok(Done::Ack)
            }
            "ref" => {
                count(1)?;
                self.component_ids(params[0])?;
                Ok(Done::Ack)
            }
            "click" => {
                count(2)?;
                let ids = self.component_ids(params[0])?;
                let event = self.eval_num(at_us, params[1])?;
                if !(0..=1).contains(&event) {
                    return Err(codes::INVALID_OPERATION);
                }
                let page = self.page_spec(self.dp);
                if let Some(c) = ids.first().and_then(|&id| page?.component_id(id)) {
                    self.touch_event(at_us, c, event == 1);
                }
                Ok(Done::Ack)
            }
            "rest" => {
                count(0)?;
                self.power_on(at_us);
                Ok(Done::Data)
            }
            "code_c" => {
                count(0)?;
                self.note(at_us, NoteKind::Cleared, "code_c".into());
                self.clear_queue();
                Ok(Done::Ack)
            }
            "com_stop" => {
                count(0)?;
                self.com_stopped = true;
                Ok(Done::Ack)
            }
            "com_star" | "ref_stop" | "ref_star" | "doevents" => {
                count(0)?;
                Ok(Done::Ack)
            }
            _ => {
                self.note(
                    at_us,
                    NoteKind::NotModelled,
                    String::from_utf8_lossy(bytes).into_owned(),
                );
                Ok(Done::Ack)
            }
        }
    }

    /// The ids a `vis`/`tsw`/`ref`/`click` parameter names on the page
    /// shown: an `.objname`, an `.id`, 0 (the page) or 255 (all) (NIS 3.11).
    fn component_ids(&self, p: &[u8]) -> Result<Vec<u8>, u8> {
        let page = self.page_spec(self.dp).ok_or(codes::INVALID_COMPONENT)?;
        let t = std::str::from_utf8(p).map_err(|_| codes::INVALID_COMPONENT)?;
        if let Ok(id) = t.parse::<u8>() {
            return match id {
                0 => Ok(Vec::new()),
                255 => Ok(page.components.iter().map(|c| c.id).collect()),
                _ => page
                    .component_id(id)
                    .map(|c| vec![c.id])
                    .ok_or(codes::INVALID_COMPONENT),
            };
        }
        page.component(t)
            .map(|c| vec![c.id])
            .ok_or(codes::INVALID_COMPONENT)
    }
}

/// NIS 6.12: "A get/print/printh/wup/sleep instruction can be executed
/// during sleep mode."
fn allowed_asleep(bytes: &[u8]) -> bool {
    [
        &b"get "[..],
        b"print ",
        b"prints ",
        b"printh ",
        b"wup=",
        b"sleep=",
    ]
    .iter()
    .any(|p| bytes.starts_with(p))
}
