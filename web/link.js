// The link: its state, the WebSocket and Web Serial transports, start-up
// (one of the page's script parts: tests/src/screen_web.rs, SCRIPTS).

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
  if (!link.lostAt) {
    link.lostAt = performance.now();
    link.lostWall = Date.now(); // the host's clock, for the tests
  }
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
  // When the link was last seen lost (ms since 1970; the page said so then).
  lostAt: () => link.lostWall || null,
};
