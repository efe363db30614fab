// The screen side of the line: the Nextion model the page runs (the
// contract's pages and components, their values), the instructions it
// executes and the answers it sends (docs/screen-web.md). One of the
// page's script parts, joined in one function by `cargo xtask screen`
// (tests/src/screen_web.rs, SCRIPTS).
//
// The transplanter's operator screen in a browser (docs/screen-web.md).
//
// The page is a Nextion/TJC screen running the screen file of docs/hmi.md:
// it executes the controller's instructions (Nextion Instruction Set §1-§3,
// §6), answers `sendme` and `get` with the return frames of §7, and sends
// a component's id (0x65 page id event) when the operator touches it, on
// press and release exactly where the contract ticks "Send Component ID".
// Pages and components are built from the contract (crates/hmi-proto,
// exported as JSON into this file by `cargo xtask`); nothing here lists
// them. It never sends anything of its own: only answers to complete
// instructions and the operator's own touches, and touches only while the
// link is up (nothing is queued for later).

const CONTRACT = JSON.parse(document.getElementById('contract').textContent);
const DOC = JSON.parse(document.getElementById('doc').textContent);

// ---------------------------------------------------------------- model
/** Nextion return codes (NIS §7). */
const R = {
  INVALID_INSTRUCTION: 0x00, SUCCESS: 0x01, INVALID_COMPONENT: 0x02, INVALID_PAGE: 0x03,
  INVALID_BAUD: 0x11, INVALID_VARIABLE: 0x1a, INVALID_OPERATION: 0x1b,
  ASSIGNMENT_FAILED: 0x1c, INVALID_PARAMS: 0x1e, INVALID_ESCAPE: 0x20,
  TOUCH: 0x65, PAGE: 0x66, STRING: 0x70, NUMBER: 0x71, READY: 0x88,
};
const BAUDS = [2400, 4800, 9600, 19200, 31250, 38400, 57600, 115200, 230400, 250000,
  256000, 512000, 921600];
/** Longest instruction the screen buffers (Nextion: 1024 bytes). */
const RX_MAX = 1024;
/** Controller silent this long (ms) with the transport open: said so. */
const SILENT_MS = 2500;
/** The monitor's window (ms). */
const WINDOW_MS = 60000;

const pages = new Map(); // id -> {def, el, comps: [comp]}
const byName = new Map(); // "page.name" -> comp
let shown = 0; // the page shown (0 boot, as at power-on)
let bkcmd = 2;
const sys = { dims: 100, sleep: 0, baud: 115200, sys0: 0, sys1: 0, sys2: 0 };
const stats = { instructions: 0, garbled: 0, unknown: 0, answers: 0, touches: 0 };
/** Every byte sent, for the tests: [{t, bytes, why}] (why: 'answer' | 'touch'). */
const sent = [];

const $ = (sel) => document.querySelector(sel);
const el = (tag, cls, text) => {
  const e = document.createElement(tag);
  if (cls) e.className = cls;
  if (text !== undefined) e.textContent = text;
  return e;
};

function key(page, name) { return page + '.' + name; }

function format(comp) {
  if (comp.def.kind === 'xfloat') {
    const d = comp.def.decimals;
    const neg = comp.val < 0;
    const a = Math.abs(comp.val);
    const s = (a / 10 ** d).toFixed(d);
    return (neg ? '-' : '') + s;
  }
  return String(comp.val);
}

// -------------------------------------------------------------- transport
const link = {
  kind: null, // 'ws' | 'serial'
  open: false,
  lastRx: 0,
  lastInstruction: 0,
  since: performance.now(),
  detail: 'choose a link',
  lostAt: 0,
  lostWall: 0,
  send: null,
};

function transmit(bytes, why) {
  if (!link.open || !link.send) return false;
  try {
    link.send(bytes);
  } catch (e) {
    return false;
  }
  sent.push({ t: Date.now(), bytes: Array.from(bytes), why });
  if (sent.length > 2000) sent.splice(0, 1000);
  return true;
}

function frame(header, payload) {
  return Uint8Array.from([header, ...payload, 0xff, 0xff, 0xff]);
}

function answer(header, payload) {
  stats.answers++;
  transmit(frame(header, payload || []), 'answer');
}

function report(failure) {
  // NIS 6.13: bkcmd 0 nothing, 1 success only, 2 failures only, 3 both.
  if (failure === null) {
    if (bkcmd === 1 || bkcmd === 3) answer(R.SUCCESS);
  } else if (bkcmd === 2 || bkcmd === 3) {
    answer(failure);
  }
}

// ------------------------------------------------------ instruction input
let rx = [];
let ffRun = 0;
let garbledAt = [];
let unknownNames = new Map();

function receive(bytes) {
  link.lastRx = performance.now();
  for (const b of bytes) {
    if (b === 0xff) {
      ffRun++;
      if (ffRun === 3) {
        const ins = rx;
        rx = [];
        ffRun = 0;
        execute(ins);
      }
      continue;
    }
    // A lone FF or two inside an instruction: not 7-bit ASCII (the
    // controller never sends it, docs/hmi.md §5).
    for (; ffRun > 0; ffRun--) rx.push(0xff);
    rx.push(b);
    if (rx.length > RX_MAX) {
      // Nextion drops what does not fit; the page says so (it does not
      // answer 0x24: it answers complete instructions only).
      noteGarbled(rx.length);
      rx = [];
    }
  }
}

function noteGarbled(n) {
  stats.garbled += n;
  const now = performance.now();
  garbledAt.push(now);
  garbledAt = garbledAt.filter((t) => now - t < 5000);
  if (garbledAt.length >= 3) {
    notice('Unreadable data from the controller: check the line is 115 200 baud 8N1, ' +
      'TX to RX and GND connected.', 'line');
  }
}

function execute(bytes) {
  stats.instructions++;
  if (bytes.length === 0) return; // FF FF FF alone: nothing (ends a half instruction)
  // The controller sends 7-bit ASCII only (docs/hmi.md §5): anything
  // else is a line error, or bytes at another baud rate. The instruction
  // is still run as a Nextion runs it (and answered the same way).
  const printable = bytes.every((b) => b >= 0x20 && b < 0x7f);
  if (!printable) noteGarbled(bytes.length);
  else link.lastInstruction = performance.now();
  const s = String.fromCharCode(...bytes);
  let failure = null;
  let data = false;
  try {
    const r = run(s);
    if (r === 'data') data = true;
    else if (r !== undefined && r !== null) failure = r;
  } catch (e) {
    failure = R.INVALID_INSTRUCTION;
  }
  if (!data) report(failure);
}

function findComp(name) {
  const dot = name.indexOf('.');
  if (dot >= 0) {
    const p = pageId(name.slice(0, dot));
    if (p === null) return null;
    return byName.get(key(p, name.slice(dot + 1))) || null;
  }
  return byName.get(key(shown, name)) || null;
}

function pageId(s) {
  if (/^[0-9]+$/.test(s)) {
    const n = Number(s);
    return pages.has(n) ? n : null;
  }
  for (const [id, p] of pages) if (p.def.name === s) return id;
  return null;
}

function unknownComponent(name) {
  stats.unknown++;
  unknownNames.set(name, (unknownNames.get(name) || 0) + 1);
  notice('The controller wrote to "' + name + '", which this page does not have ' +
    '(page ' + shown + '): page and firmware from different versions, or a line error.',
  'unknown');
}

/** Index of the first character `want` outside a quoted text, or -1. */
function outsideQuotes(s, want) {
  let quoted = false;
  let escaped = false;
  for (let i = 0; i < s.length; i++) {
    const ch = s[i];
    if (quoted) {
      if (escaped) escaped = false;
      else if (ch === '\\') escaped = true;
      else if (ch === '"') quoted = false;
    } else if (ch === '"') {
      quoted = true;
    } else if (ch === want) {
      return i;
    }
  }
  return -1;
}

/** The operational commands of NIS §3 and §4, by name. */
const COMMANDS = new Set(['page', 'ref', 'click', 'ref_stop', 'ref_star', 'get', 'sendme',
  'covx', 'cov', 'touch_j', 'substr', 'vis', 'tsw', 'com_stop', 'com_star', 'randset', 'code_c',
  'prints', 'print', 'printh', 'add', 'addt', 'cle', 'rest', 'doevents', 'strlen', 'btlen',
  'wepo', 'repo', 'wept', 'rept', 'cfgpio', 'ucopy', 'move', 'play', 'twfile', 'delfile',
  'refile', 'findfile', 'rdfile', 'setlayer', 'newdir', 'deldir', 'redir', 'finddir', 'udelete',
  'crcrest', 'crcputs', 'crcputh', 'crcputu', 'spstr', 'newfile', 'cls', 'pic', 'picq', 'xpic',
  'xstr', 'fill', 'line', 'draw', 'draw3d', 'cir', 'cirs', 'qrcode']);

/**
 * Runs one instruction (NIS §1.x: a command word and its parameters, or
 * an assignment): undefined/null success, 'data' answered, or a code.
 */
function run(s) {
  const space = outsideQuotes(s, ' ');
  const word = space < 0 ? s : s.slice(0, space);
  const arg = space < 0 ? '' : s.slice(space + 1);
  if (COMMANDS.has(word)) return command(word, arg);
  const eq = outsideQuotes(s, '=');
  if (eq >= 0) {
    const op = '+-*/%'.includes(s[eq - 1]) ? s[eq - 1] : '';
    return assign(s.slice(0, op ? eq - 1 : eq), s.slice(eq + 1), op);
  }
  if (space < 0) {
    if (s.endsWith('++') || s.endsWith('--')) return assign(s.slice(0, -2), '1', s[s.length - 1]);
    return R.INVALID_VARIABLE; // a bare word
  }
  return R.INVALID_INSTRUCTION;
}

function command(name, arg) {
  if (name === 'sendme') {
    answer(R.PAGE, [shown]);
    return 'data';
  }
  if (name === 'page') {
    const id = pageId(arg.trim());
    if (id === null) return R.INVALID_PAGE;
    showPage(id);
    return null;
  }
  if (name === 'get') {
    const a = arg.trim();
    const dot = a.lastIndexOf('.');
    if (dot < 0) return R.INVALID_VARIABLE;
    const c = findComp(a.slice(0, dot));
    const attr = a.slice(dot + 1);
    if (!c) {
      unknownComponent(a.slice(0, dot));
      return R.INVALID_VARIABLE;
    }
    if (attr === 'val' && hasVal(c)) {
      const v = c.val | 0;
      answer(R.NUMBER, [v & 0xff, (v >> 8) & 0xff, (v >> 16) & 0xff, (v >>> 24) & 0xff]);
      return 'data';
    }
    if (attr === 'txt' && hasTxt(c)) {
      const t = Array.from(c.txt, (ch) => {
        const code = ch.charCodeAt(0);
        return code < 0x80 ? code : 0x3f;
      }).slice(0, 48);
      answer(R.STRING, t);
      return 'data';
    }
    return R.INVALID_VARIABLE;
  }
  if (name === 'rest') {
    showPage(0);
    bkcmd = 2;
    // A reset screen announces itself: the start-up frame, then ready.
    answer(0x00, [0x00, 0x00]);
    answer(R.READY);
    return 'data';
  }
  if (name === 'vis' || name === 'tsw') {
    const parts = arg.split(',');
    if (parts.length !== 2) return R.INVALID_PARAMS;
    const on = parts[1].trim();
    if (on !== '0' && on !== '1') return R.INVALID_OPERATION;
    const target = parts[0].trim();
    const list = target === '255' ? pages.get(shown).comps : [findComp(target)];
    if (list.some((c) => !c)) return R.INVALID_COMPONENT;
    for (const c of list) {
      if (name === 'vis') c.visible = on === '1';
      else c.touch = on === '1';
      paint(c);
    }
    return null;
  }
  if (name === 'ref') return findComp(arg.trim()) ? null : R.INVALID_COMPONENT;
  // `click` would make the screen send a touch the operator did not
  // make: this page never does. The other commands draw, print or use
  // files, which the contract does not use: taken, nothing done.
  return null;
}

function hasVal(c) { return c.def.kind === 'number' || c.def.kind === 'xfloat'; }
function hasTxt(c) { return c.def.kind === 'text' || c.def.kind === 'button'; }

/** A decimal or `0x` hex constant (NIS 1.18, 1.26), wrapped to 32 bits. */
function number(rhs) {
  if (/^0x([0-9A-Fa-f]{2}){1,4}$/.test(rhs)) return Number(rhs) | 0;
  if (!/^-?[0-9]+$/.test(rhs)) return null;
  const v = Number(rhs);
  return Number.isSafeInteger(v) ? v : null;
}

function arith(old, op, v) {
  switch (op) {
    case '': return v;
    case '+': return (old + v) | 0;
    case '-': return (old - v) | 0;
    case '*': return Math.imul(old, v);
    case '/': return v === 0 ? null : (old / v) | 0;
    case '%': return v === 0 ? null : (old % v) | 0;
    default: return null;
  }
}

function assign(lhs, rhs, op) {
  if (lhs in sys || lhs === 'dim' || lhs === 'bauds' || lhs === 'bkcmd') {
    const n = number(rhs);
    if (n === null) return R.INVALID_OPERATION;
    const v = arith(lhs === 'bkcmd' ? bkcmd : (sys[lhs === 'dim' ? 'dims' : lhs] || 0), op, n);
    if (v === null) return R.INVALID_OPERATION;
    if (lhs === 'bkcmd') {
      if (v < 0 || v > 3) return R.ASSIGNMENT_FAILED;
      bkcmd = v;
      // The controller sets the screen up after its start and after a
      // lost link (docs/hmi.md §2).
      logEvent('link', 'Controller set the screen up (its start, or the link back)');
    } else if (lhs === 'baud' || lhs === 'bauds') {
      if (!BAUDS.includes(v)) return R.INVALID_BAUD;
      sys.baud = v;
    } else if (lhs === 'dims' || lhs === 'dim') {
      sys.dims = Math.max(0, Math.min(100, v));
      document.documentElement.style.setProperty('--dim', String(Math.max(sys.dims, 30) / 100));
    } else {
      sys[lhs] = v | 0;
    }
    return null;
  }
  const dot = lhs.lastIndexOf('.');
  if (dot < 0) return R.INVALID_VARIABLE;
  const name = lhs.slice(0, dot);
  const attr = lhs.slice(dot + 1);
  const c = findComp(name);
  if (!c) {
    unknownComponent(name);
    return R.INVALID_VARIABLE;
  }
  if (attr === 'val' && hasVal(c)) {
    const n = number(rhs);
    const v = n === null ? null : arith(c.val, op, n | 0); // the screen keeps 32 bits
    if (v === null) return R.INVALID_OPERATION;
    setValue(c, v);
    return null;
  }
  if (attr === 'txt' && hasTxt(c)) {
    if (op !== '' && op !== '+') return R.INVALID_OPERATION;
    const u = unescape(rhs);
    if (u.code !== undefined) return u.code;
    const t = op === '' ? u.text : c.txt + u.text;
    setText(c, t.slice(0, 40));
    return null;
  }
  return R.INVALID_VARIABLE;
}

/** A quoted text with its escapes (NIS 1.x), or the failure's code. */
function unescape(rhs) {
  if (rhs.length < 2 || rhs[0] !== '"' || rhs[rhs.length - 1] !== '"') {
    return { code: R.INVALID_OPERATION };
  }
  const inner = rhs.slice(1, -1);
  let out = '';
  for (let i = 0; i < inner.length; i++) {
    const ch = inner[i];
    if (ch === '\\') {
      const n = inner[++i];
      if (n === '"') out += '"';
      else if (n === '\\') out += '\\';
      else if (n === 'r') out += '\n';
      else return { code: R.INVALID_ESCAPE };
    } else if (ch === '"') {
      return { code: R.INVALID_OPERATION }; // two texts, not one
    } else {
      out += ch;
    }
  }
  return { text: out };
}

// ------------------------------------------------------------ components
function setValue(c, v) {
  c.val = v;
  c.typed = null;
  paint(c);
  if (c.def.role === 'status') monitorValue(c);
}

function setText(c, t) {
  c.txt = t;
  paint(c);
  if (t && c.def.page !== 0 && (c.def.role === 'alarm' || c.def.role === 'message')) {
    logEvent(c.def.role === 'alarm' ? 'alarm' : 'message', t);
  }
}

function paint(c) {
  if (!c.el) return;
  c.el.hidden = !c.visible;
  c.el.classList.toggle('no-touch', !c.touch);
  if (c.valueEl) {
    if (c.def.role === 'input') {
      if (document.activeElement !== c.valueEl || c.typed === null) {
        c.valueEl.value = format(c);
      }
      c.valueEl.classList.remove('bad');
    } else if (hasVal(c)) {
      c.valueEl.textContent = format(c);
    } else {
      c.valueEl.textContent = c.txt;
    }
  }
}

function showPage(id) {
  shown = id;
  const p = pages.get(id);
  // A page load gives the page's components their editor defaults
  // (NIS 3.1); the static texts keep their design text.
  for (const c of p.comps) {
    c.val = 0;
    c.txt = c.static || '';
    c.visible = true;
    c.touch = true;
    c.typed = null;
    paint(c);
  }
  for (const [pid, q] of pages) q.el.hidden = pid !== id;
  $('#title').textContent = p.def.title;
  document.body.dataset.page = String(id);
  if (p.run) monitorPage(p);
}
