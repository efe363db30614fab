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
'use strict';
(() => {
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

  // ----------------------------------------------------------- touches
  const held = new Map(); // pointerId -> comp

  function touchFrame(c, event) {
    return frame(R.TOUCH, [c.def.page, c.def.id, event]);
  }

  function touchable(c) {
    return c.def.page === shown && c.visible && c.touch;
  }

  function refuse(c) {
    c.el.classList.add('refused');
    setTimeout(() => c.el.classList.remove('refused'), 400);
    notice('The link to the controller is not up: nothing was sent.', 'nolink');
  }

  function press(c, ev) {
    if (!ev.isTrusted || !touchable(c)) return;
    ev.preventDefault();
    if (linkState() !== 'ok') {
      refuse(c);
      return;
    }
    try { c.el.setPointerCapture(ev.pointerId); } catch (e) { /* not capturable */ }
    held.set(ev.pointerId, c);
    c.el.classList.add('down');
    if (c.def.press) {
      stats.touches++;
      transmit(touchFrame(c, 0x01), 'touch');
    }
  }

  function release(c, ev, cancelled) {
    if (held.get(ev.pointerId) !== c) return;
    held.delete(ev.pointerId);
    c.el.classList.remove('down');
    if (!ev.isTrusted || cancelled) return;
    // Released off the button: no release (a Start needs its release, so
    // a finger that slid away starts nothing; Stop acted on its press).
    const r = c.el.getBoundingClientRect();
    const inside = ev.clientX >= r.left && ev.clientX <= r.right &&
      ev.clientY >= r.top && ev.clientY <= r.bottom;
    if (!inside || !touchable(c) || !c.def.release || linkState() !== 'ok') return;
    stats.touches++;
    transmit(touchFrame(c, 0x00), 'touch');
  }

  function wireButton(c) {
    const b = c.el;
    b.addEventListener('pointerdown', (ev) => press(c, ev));
    b.addEventListener('pointerup', (ev) => release(c, ev, false));
    b.addEventListener('pointercancel', (ev) => release(c, ev, true));
    b.addEventListener('contextmenu', (ev) => ev.preventDefault());
    // Keyboard: Space or Enter held is a press, let go a release.
    b.addEventListener('keydown', (ev) => {
      if ((ev.key === ' ' || ev.key === 'Enter') && !ev.repeat && ev.isTrusted) {
        ev.preventDefault();
        if (!touchable(c)) return;
        if (linkState() !== 'ok') { refuse(c); return; }
        held.set('key', c);
        c.el.classList.add('down');
        if (c.def.press) transmit(touchFrame(c, 0x01), 'touch');
      }
    });
    b.addEventListener('keyup', (ev) => {
      if ((ev.key === ' ' || ev.key === 'Enter') && ev.isTrusted && held.get('key') === c) {
        ev.preventDefault();
        held.delete('key');
        c.el.classList.remove('down');
        if (touchable(c) && c.def.release && linkState() === 'ok') transmit(touchFrame(c, 0x00), 'touch');
      }
    });
  }

  function wireInput(c) {
    const i = c.valueEl;
    i.addEventListener('input', () => {
      const scale = 10 ** (c.def.kind === 'xfloat' ? c.def.decimals : 0);
      const t = i.value.trim().replace(',', '.');
      const ok = /^-?[0-9]*\.?[0-9]*$/.test(t) && /[0-9]/.test(t);
      const v = ok ? Math.round(Number(t) * scale) : NaN;
      if (!ok || !Number.isSafeInteger(v) || Math.abs(v) > 2147483647) {
        i.classList.add('bad');
        return;
      }
      i.classList.remove('bad');
      c.val = v; // what `get` answers, as a Nextion keyboard field holds it
      c.typed = t;
    });
    i.addEventListener('focus', () => i.select());
    i.addEventListener('keydown', (ev) => { if (ev.key === 'Enter') i.blur(); });
  }

  // ------------------------------------------------------------- building
  const PAIRS = {
    GearLabel: ['GearDown', 'GearUp'],
    CalibrationLabel: ['NextCalibration'],
    ProfileLabel: ['NextProfile'],
    EncoderDirectionLabel: ['ToggleEncoderDirection'],
    WorkSwitchLabel: ['ToggleWorkSwitch'],
    PlacementLabel: ['TogglePlacement'],
    LinkParameterLabel: ['NextLinkParameter'],
  };
  const NAV = /^(ShowPage|ShowHome|SelectMode)/;

  function makeComp(def) {
    const c = {
      def, val: 0, txt: '', visible: true, touch: true, typed: null, el: null, valueEl: null,
      static: null,
    };
    byName.set(key(def.page, def.name), c);
    return c;
  }

  function tag(e, c) {
    e.dataset.page = String(c.def.page);
    e.dataset.id = String(c.def.id);
    e.dataset.name = c.def.name;
    e.dataset.role = c.def.role;
  }

  function button(c, extra) {
    const b = el('button', 'btn ' + (extra || ''));
    b.type = 'button';
    b.textContent = DOC.captions[key(c.def.page, c.def.name)] || c.def.name;
    tag(b, c);
    if (c.def.stop) b.classList.add('stop');
    if (c.def.starts_motor) b.classList.add('start');
    c.el = b;
    wireButton(c);
    return b;
  }

  function unitSpan(u) { return u ? el('span', 'unit', u) : null; }

  function inputBox(c) {
    const i = el('input', 'field');
    i.type = 'text';
    i.inputMode = c.def.min < 0 ? 'text' : 'decimal';
    i.autocomplete = 'off';
    i.spellcheck = false;
    i.setAttribute('aria-label', c.def.label);
    tag(i, c);
    c.el = i;
    c.valueEl = i;
    wireInput(c);
    return i;
  }

  function tile(c) {
    const t = el('div', 'tile');
    tag(t, c);
    t.append(el('span', 'label', c.def.label || ''));
    const v = el('span', 'value');
    c.valueEl = v;
    t.append(v);
    const u = unitSpan(c.def.unit);
    if (u) t.append(u);
    c.el = t;
    return t;
  }

  function build() {
    const main = $('#pages');
    for (const pd of CONTRACT.pages) {
      const sec = el('section', 'page');
      sec.dataset.page = String(pd.id);
      sec.dataset.name = pd.name;
      sec.hidden = true;
      const p = { def: pd, el: sec, comps: [], run: false };
      pages.set(pd.id, p);
      const defs = CONTRACT.components.filter((d) => d.page === pd.id);
      const comps = defs.map(makeComp);
      p.comps = comps;
      const statics = (DOC.statics || []).filter((s) => s.page === pd.id);
      const used = new Set();
      const find = (pred) => comps.find((c) => !used.has(c) && pred(c));
      const left = el('div', 'controls');
      const right = el('div', 'values');
      const nav = el('div', 'nav');
      // Start and Stop first, large.
      const run = comps.filter((c) => c.def.starts_motor || c.def.stop);
      if (run.length) {
        const box = el('div', 'run');
        for (const c of run.sort((a, b) => Number(a.def.stop) - Number(b.def.stop))) {
          used.add(c);
          box.append(button(c));
        }
        left.append(box);
      }
      // An input with its Apply button.
      for (const c of comps.filter((c) => c.def.role === 'input')) {
        used.add(c);
        const row = el('div', 'row input-row');
        const lab = el('label', 'label', c.def.label);
        const box = el('div', 'inbox');
        box.append(inputBox(c));
        const u = unitSpan(c.def.unit);
        if (u) box.append(u);
        row.append(lab, box);
        const apply = find((a) => a.def.role === 'action' && a.def.detail === 'Apply(' + c.def.detail + ')');
        if (apply) {
          used.add(apply);
          row.append(button(apply));
        }
        left.append(row);
      }
      // A label and the buttons that change it.
      for (const c of comps.filter((c) => c.def.role === 'text' && PAIRS[c.def.detail])) {
        used.add(c);
        const row = el('div', 'row pair-row');
        const acts = PAIRS[c.def.detail].map((a) => find((b) => b.def.detail === a)).filter(Boolean);
        const t = el('div', 'ltext');
        tag(t, c);
        t.append(el('span', 'label', c.def.label));
        const v = el('span', 'value');
        t.append(v);
        c.el = t;
        c.valueEl = v;
        if (acts.length === 2) {
          used.add(acts[0]);
          used.add(acts[1]);
          row.append(button(acts[0], 'small'), t, button(acts[1], 'small'));
        } else {
          row.append(t);
          for (const a of acts) { used.add(a); row.append(button(a)); }
        }
        left.append(row);
      }
      // Other buttons: navigation at the bottom, the rest with the controls.
      const others = el('div', 'row buttons');
      for (const c of comps.filter((c) => c.def.kind === 'button' && !used.has(c))) {
        used.add(c);
        if (NAV.test(c.def.detail)) nav.append(button(c, 'navb'));
        else others.append(button(c));
      }
      if (others.childElementCount) left.append(others);
      // Live values and the other texts.
      const tiles = el('div', 'tiles');
      for (const c of comps.filter((c) => !used.has(c) && (c.def.role === 'status' ||
        (c.def.role === 'text' && c.def.label)))) {
        used.add(c);
        tiles.append(tile(c));
      }
      const hasStatus = comps.some((c) => c.def.role === 'status');
      if (tiles.childElementCount) (hasStatus ? right : left).append(tiles);
      for (const s of statics) {
        const sc = makeComp({ page: pd.id, id: s.id, name: s.name, kind: 'text', decimals: 0,
          role: 'static', detail: '', press: false, release: false, starts_motor: false,
          stop: false, label: null, unit: '' });
        sc.static = s.text;
        sc.txt = s.text;
        used.add(sc);
        const t = el('div', 'static-text');
        tag(t, sc);
        t.textContent = s.text;
        sc.el = t;
        p.comps.push(sc);
        right.append(t);
      }
      // Alarm text: the whole page.
      for (const c of comps.filter((c) => c.def.role === 'alarm')) {
        used.add(c);
        sec.classList.add('alarm-page');
        const a = el('div', 'alarm-text');
        tag(a, c);
        c.el = a;
        c.valueEl = a;
        left.prepend(a);
      }
      const msgs = comps.filter((c) => c.def.role === 'message' && !used.has(c));
      const foot = el('div', 'foot');
      for (const c of msgs) {
        used.add(c);
        const m = el('div', 'msg');
        tag(m, c);
        c.el = m;
        c.valueEl = m;
        foot.append(m);
      }
      // Anything the layout above does not know still appears (as a tile).
      for (const c of comps.filter((c) => !used.has(c))) {
        used.add(c);
        if (c.def.kind === 'button') others.append(button(c));
        else right.append(tile(c));
      }
      p.run = run.some((c) => c.def.starts_motor) && comps.some((c) => c.def.role === 'status');
      if (p.run) {
        right.append(monitorPanel(p));
      }
      if (!hasStatus) {
        sec.classList.add('wide');
        left.append(...right.childNodes);
      }
      const body = el('div', 'body');
      body.append(left, right);
      foot.prepend(nav);
      sec.append(body, foot);
      main.append(sec);
    }
    for (const p of pages.values()) for (const c of p.comps) paint(c);
    showPage(0);
    const boot = byName.get(key(0, 'tmsg'));
    if (boot) setText(boot, 'Waiting for the controller...');
  }

  // ------------------------------------------------------------- monitor
  const series = new Map(); // status detail -> [{t, v}]
  const events = []; // {t: Date, kind, text}
  const monitors = [];

  function monitorPanel(p) {
    const m = el('div', 'monitor');
    m.dataset.page = String(p.def.id);
    const head = el('div', 'mon-head');
    head.append(el('span', 'mon-title', 'Last minute'));
    const spacing = el('span', 'mon-spacing');
    head.append(spacing);
    const chart = document.createElementNS('http://www.w3.org/2000/svg', 'svg');
    chart.setAttribute('class', 'chart');
    chart.setAttribute('viewBox', '0 0 600 150');
    chart.setAttribute('preserveAspectRatio', 'none');
    const legend = el('div', 'legend');
    const log = el('ol', 'events');
    m.append(head, chart, legend, log);
    const statusOf = (d) => p.comps.find((c) => c.def.role === 'status' && c.def.detail === d);
    const lines = ['TravelSpeed', 'TravelSpeedMps', 'ActualDrumSpeed', 'TargetDrumSpeed',
      'PlantMotorSpeed', 'FeedMotorSpeed'].map(statusOf).filter(Boolean);
    const colours = ['#0044cc', '#b00000', '#007a33', '#6a1b9a', '#a05a00'];
    const mon = { p, chart, legend, spacing, log, lines, colours };
    legend.replaceChildren(...lines.map((c, i) => {
      const s = el('span', 'key');
      s.style.setProperty('--c', colours[i % colours.length]);
      s.textContent = c.def.label + (c.def.unit ? ' (' + c.def.unit + ')' : '');
      return s;
    }));
    monitors.push(mon);
    return m;
  }

  function monitorValue(c) {
    const now = performance.now();
    const s = series.get(c.def.detail) || [];
    s.push({ t: now, v: c.val / 10 ** (c.def.kind === 'xfloat' ? c.def.decimals : 0) });
    while (s.length && now - s[0].t > WINDOW_MS) s.shift();
    series.set(c.def.detail, s);
    if (c.def.detail === 'Plants') {
      const prev = monitorValue.plants;
      if (prev !== undefined && c.val > prev) monitorValue.landed += c.val - prev;
      monitorValue.plants = c.val;
    }
  }
  monitorValue.landed = 0;

  function monitorPage() { drawMonitors(); }

  function drawMonitors() {
    const now = performance.now();
    for (const m of monitors) {
      if (m.p.def.id !== shown) continue;
      const paths = [];
      let max = 0;
      const data = m.lines.map((c) => (series.get(c.def.detail) || []).filter((pt) => now - pt.t <= WINDOW_MS));
      // The chart spans the last minute, or the time since the first value.
      let first = now;
      for (const d of data) for (const pt of d) { max = Math.max(max, pt.v); first = Math.min(first, pt.t); }
      const span = Math.min(WINDOW_MS, Math.max(5000, now - first));
      max = max > 0 ? max * 1.1 : 1;
      data.forEach((d, i) => {
        if (!d.length) return;
        const pts = d.map((pt) => ((600 * (1 - (now - pt.t) / span)).toFixed(1)) + ',' +
          (150 - 150 * pt.v / max).toFixed(1)).join(' ');
        paths.push('<polyline fill="none" stroke-width="3" vector-effect="non-scaling-stroke" stroke="' +
          m.colours[i % m.colours.length] + '" points="' + pts + '"/>');
      });
      m.chart.innerHTML = '<rect x="0" y="0" width="600" height="150" fill="none" stroke="#444"/>' + paths.join('');
      const perm = m.p.comps.find((c) => c.def.detail === 'PlantsPerMetre');
      const parts = [];
      const showsDistance = m.p.comps.some((c) => c.def.detail === 'Distance');
      const last10 = showsDistance ? recentSpacing(now) : null;
      if (last10) parts.push('last 10 s ≈ ' + last10.cm.toFixed(1) + ' cm');
      if (perm && perm.val > 0) parts.push('since Start ' + (10000 / perm.val).toFixed(1) + ' cm');
      m.spacing.textContent = parts.length ? 'Spacing: ' + parts.join(', ') : '';
      const recent = events.slice(-4).reverse();
      m.log.replaceChildren(...recent.map((e) => {
        const li = el('li', 'ev ' + e.kind);
        li.append(el('time', '', e.t.toLocaleTimeString()), document.createTextNode(' ' + e.text));
        return li;
      }));
    }
  }

  /**
   * The mean spacing over the last 10 s from the plants and the distance
   * the firmware shows (the distance in 0.1 m: ±0.1 m over the plants
   * counted, so only from 10 plants on), or null.
   */
  function recentSpacing(now) {
    const at = (d) => (series.get(d) || []).filter((p) => now - p.t <= 10000);
    const plants = at('Plants');
    const dist = at('Distance');
    if (plants.length < 2 || dist.length < 2) return null;
    const n = plants[plants.length - 1].v - plants[0].v;
    const m = dist[dist.length - 1].v - dist[0].v;
    if (n < 10 || m <= 0) return null;
    return { cm: (100 * m) / n, plants: n };
  }

  function logEvent(kind, text) {
    const last = events[events.length - 1];
    if (last && last.text === text && Date.now() - last.t.getTime() < 2000) return;
    events.push({ t: new Date(), kind, text });
    if (events.length > 200) events.shift();
  }

  // -------------------------------------------------------------- notices
  let noticeTimer = null;
  function notice(text, kind) {
    const n = $('#notice');
    n.textContent = text;
    n.dataset.kind = kind;
    n.hidden = false;
    if (kind !== 'nolink') logEvent('warning', text);
    clearTimeout(noticeTimer);
    noticeTimer = setTimeout(() => { n.hidden = true; }, 8000);
  }

  // ------------------------------------------------------------ link state
  function linkState() {
    const now = performance.now();
    let state;
    let cls;
    let detail = link.detail;
    if (!link.kind) {
      state = 'NOT CONNECTED'; cls = 'off';
    } else if (!link.open) {
      state = 'LINK LOST'; cls = 'lost';
      if (link.lostAt) detail = link.detail + ' — ' + Math.round((now - link.lostAt) / 1000) + ' s';
    } else if (now - link.lastRx > SILENT_MS) {
      state = 'CONTROLLER SILENT'; cls = 'lost';
      detail = link.lastRx ? 'nothing received for ' + Math.round((now - link.lastRx) / 1000) + ' s' :
        'no data yet: is the controller on?';
    } else if (!link.lastInstruction) {
      state = 'CONNECTING'; cls = 'wait';
    } else {
      state = 'LINK OK'; cls = 'ok';
    }
    const box = $('#link');
    box.className = 'link ' + cls;
    box.dataset.state = cls;
    $('#link-state').textContent = state;
    $('#link-detail').textContent = detail;
    document.body.classList.toggle('link-down', cls !== 'ok');
    return cls;
  }

  function opened(kind, detail, send) {
    link.kind = kind;
    link.open = true;
    link.send = send;
    link.detail = detail;
    link.lastRx = performance.now();
    link.lastInstruction = 0;
    if (link.lostAt) logEvent('link', 'Link restored (' + detail + ')');
    link.lostAt = 0;
    rx = [];
    ffRun = 0;
    linkState();
  }

  function closed(detail) {
    if (link.open) logEvent('link', 'Link lost: ' + detail);
    link.open = false;
    link.send = null;
    link.detail = detail;
    if (!link.lostAt) link.lostAt = performance.now();
    // Touches held across the loss are forgotten (never sent later).
    for (const c of held.values()) c.el.classList.remove('down');
    held.clear();
    linkState();
  }

  // WebSocket to the simulator (cargo xtask qemu --screen).
  let ws = null;
  let wsTimer = null;
  function connectWs(url) {
    link.kind = 'ws';
    clearTimeout(wsTimer);
    let s;
    try {
      s = new WebSocket(url);
    } catch (e) {
      closed('simulator address refused');
      wsTimer = setTimeout(() => connectWs(url), 1000);
      return;
    }
    ws = s;
    s.binaryType = 'arraybuffer';
    s.onopen = () => opened('ws', 'simulator ' + new URL(url).host, (b) => s.send(b));
    s.onmessage = (ev) => { if (ws === s) receive(new Uint8Array(ev.data)); };
    s.onclose = (ev) => {
      if (ws !== s) return;
      let why = 'simulator connection closed';
      let retry = 500;
      if (ev.code === 4001) {
        why = 'another screen page is connected to the simulator';
        retry = 2000;
        notice('Another page is connected to the simulator: close it to use this one.', 'busy');
      }
      closed(why);
      wsTimer = setTimeout(() => connectWs(url), retry);
    };
  }

  // Web Serial (the field: a USB-serial adapter on USART1).
  const SERIAL_OPTIONS = { baudRate: 115200, dataBits: 8, stopBits: 1, parity: 'none', flowControl: 'none' };
  let port = null;
  let serialTimer = null;

  async function openSerial(p) {
    link.kind = 'serial';
    port = p;
    try {
      await p.open(SERIAL_OPTIONS);
    } catch (e) {
      const busy = e && (e.name === 'InvalidStateError' || e.name === 'NetworkError');
      const why = busy ? 'the port is in use (another tab or program has it open)' :
        'the port could not be opened (' + (e && e.name) + ')';
      closed(why);
      notice('USB serial: ' + why + '.', 'busy');
      serialTimer = setTimeout(() => retrySerial(), 2000);
      return;
    }
    const writer = p.writable.getWriter();
    opened('serial', 'USB serial 115 200 8N1', (b) => { writer.write(b).catch(() => {}); });
    try {
      const reader = p.readable.getReader();
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        if (value) receive(value);
      }
    } catch (e) {
      // Break, framing or parity errors come as a read error: wrong baud
      // rate or noise. The stream can be reopened.
      if (e && (e.name === 'BreakError' || e.name === 'FramingError' || e.name === 'ParityError')) {
        noteGarbled(1);
        noteGarbled(1);
        noteGarbled(1);
      }
    }
    try { writer.releaseLock(); } catch (e) { /* gone */ }
    try { await p.close(); } catch (e) { /* gone */ }
    closed('USB serial adapter gone or closed');
    serialTimer = setTimeout(() => retrySerial(), 500);
  }

  async function retrySerial() {
    clearTimeout(serialTimer);
    if (link.open || !navigator.serial) return;
    const ports = await navigator.serial.getPorts();
    const again = ports.includes(port) ? port : (ports.length === 1 ? ports[0] : null);
    if (again) openSerial(again);
    else serialTimer = setTimeout(() => retrySerial(), 1000);
  }

  async function chooseSerial() {
    if (!navigator.serial) {
      notice('This browser has no Web Serial: use Chrome or Edge on a computer, or Chrome 148 or later on Android.', 'serial');
      return;
    }
    try {
      const p = await navigator.serial.requestPort();
      clearTimeout(wsTimer);
      if (ws) { const s = ws; ws = null; s.close(); }
      openSerial(p);
    } catch (e) {
      notice('No port chosen.', 'serial');
    }
  }

  // One tab holds the link: a second tab of this page says so.
  function withLinkLock(start) {
    if (!navigator.locks) { start(); return; }
    navigator.locks.request('transplanter-screen-link', { ifAvailable: true }, (lock) => {
      if (!lock) {
        link.kind = link.kind || 'ws';
        closed('this page is open in another tab, which has the link');
        notice('This page is open in another tab: use that tab, or close it.', 'busy');
        setTimeout(() => withLinkLock(start), 2000);
        return undefined;
      }
      start();
      return new Promise(() => {}); // held while this tab lives
    });
  }

  function startLinks() {
    const q = new URLSearchParams(location.search);
    $('#use-serial').addEventListener('click', (ev) => { if (ev.isTrusted) withLinkLock(chooseSerial); });
    $('#use-ws').addEventListener('click', (ev) => {
      if (!ev.isTrusted) return;
      const url = q.get('ws') || ((location.protocol === 'https:' ? 'wss://' : 'ws://') + (location.host || '127.0.0.1:8080') + '/ws');
      withLinkLock(() => connectWs(url));
    });
    if (!navigator.serial) $('#use-serial').classList.add('unavailable');
    if (q.get('link') === 'ws') {
      const url = q.get('ws') || ('ws://' + location.host + '/ws');
      withLinkLock(() => connectWs(url));
    } else if (navigator.serial) {
      // A port this page was given before reopens by itself (after a reload).
      navigator.serial.getPorts().then((ports) => {
        if (ports.length === 1) withLinkLock(() => openSerial(ports[0]));
      });
      navigator.serial.addEventListener('connect', () => { if (link.kind === 'serial') retrySerial(); });
    }
  }

  build();
  startLinks();
  setInterval(() => { linkState(); drawMonitors(); }, 250);
  window.addEventListener('error', (e) => logEvent('warning', 'page error: ' + e.message));

  // For the browser tests and the screenshots (read only, sends nothing).
  window.transplanterScreen = {
    shown: () => shown,
    link: () => linkState(),
    stats: () => Object.assign({}, stats, { unknown_names: Object.fromEntries(unknownNames) }),
    sent: () => sent.slice(),
    events: () => events.map((e) => ({ t: e.t.getTime(), kind: e.kind, text: e.text })),
    value: (page, name) => { const c = byName.get(key(page, name)); return c ? c.val : null; },
    text: (page, name) => { const c = byName.get(key(page, name)); return c ? c.txt : null; },
    series: (d) => (series.get(d) || []).map((p) => p.v),
    landed: () => monitorValue.landed,
    recentSpacing: () => recentSpacing(performance.now()),
  };
})();
