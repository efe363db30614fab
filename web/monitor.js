// The planting monitor of the run pages and the notices (one of the
// page's script parts: tests/src/screen_web.rs, SCRIPTS).

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
