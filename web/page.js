// The page's layout from the contract and the operator's touches (one of
// the page's script parts: tests/src/screen_web.rs, SCRIPTS).

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
  TravelSourceLabel: ['NextTravelSource'],
  GroundWheelDirectionLabel: ['ToggleGroundWheelDirection'],
};
const NAV = /^(ShowPage|ShowHome|SelectMode)/;
// The buttons that close a page's work: in the bottom bar, after the
// navigation (the settings page's rows fill the screen above it).
const CLOSING = /^SaveSettings$/;

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
    // Other buttons: navigation (and Save settings) at the bottom, the rest
    // with the controls.
    const others = el('div', 'row buttons');
    const closing = [];
    for (const c of comps.filter((c) => c.def.kind === 'button' && !used.has(c))) {
      used.add(c);
      if (NAV.test(c.def.detail)) nav.append(button(c, 'navb'));
      else if (CLOSING.test(c.def.detail)) closing.push(c);
      else others.append(button(c));
    }
    for (const c of closing) nav.append(button(c, 'navb'));
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
