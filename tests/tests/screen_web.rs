//! The operator's screen in a real browser (Debian's `chromium`, headless,
//! over the DevTools protocol: `qemu_tests::browser`), docs/screen-web.md.
//!
//! * `the_qemu_board_is_driven_from_the_page`: the firmware in QEMU in
//!   real time, its USART1 joined to the page's WebSocket; the operator
//!   taps Speed-Adaptive, 7.0 cm, Low 2 and Start (press and release); the
//!   line is cut mid-run and restored; Stop. Checks the drum, the plants
//!   and the indices against the simulator's truth, the link state's time,
//!   the firmware's screen-loss handling, the Stop's period and that the
//!   page sent nothing but answers and the operator's touches.
//! * `every_component_on_its_page_and_nothing_sent_on_bad_input`: no
//!   firmware; the test writes the firmware's side. Every page of the
//!   contract, both machines, at 1024×600 and 1280×800: every component
//!   shown, every touch target ≥ 12 mm on a 7" screen; random bytes and
//!   bit-flipped instructions; the Web Serial transport with a stubbed
//!   `navigator.serial` (a headless browser cannot answer the port chooser):
//!   115 200 8N1, the adapter pulled and plugged back, a port in use.

use std::time::{Duration, Instant};

use hmi_proto::screen::{Kind, Page, Role, COMPONENTS};
use machine_sim::SpacingAccumulator;
use qemu_tests::browser::Browser;
use qemu_tests::screen_shots::page_bytes;
use qemu_tests::screen_web::ScreenServer;
use qemu_tests::{
    log_time_ms, number_after, qemu_firmware_elf, sim_samples, BootOptions, Firmware,
};

fn sel(page: u8, name: &str) -> String {
    format!("section[data-page=\"{page}\"] [data-name=\"{name}\"]")
}

/// Opens the page and checks its script runs (a syntax error shows here
/// with the browser's message).
fn open(b: &mut Browser, url: &str) {
    b.goto(url).unwrap();
    let ok = b
        .eval("typeof window.transplanterScreen === 'object'")
        .unwrap();
    assert!(
        ok == true,
        "the page's script did not run: {:?}",
        b.exceptions()
    );
}

fn wait_connected(server: &ScreenServer) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while !server.connected() {
        assert!(Instant::now() < deadline, "the page never connected");
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn value(b: &mut Browser, page: u8, name: &str) -> i64 {
    b.eval(&format!("transplanterScreen.value({page}, '{name}')"))
        .unwrap()
        .as_i64()
        .unwrap_or(i64::MIN)
}

/// The host's clock in ms since 1970 (the page's `Date.now()`).
fn wall_ms() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64() * 1000.0)
        .unwrap_or(0.0)
}

/// How long after `since_ms` (host clock) the page said the link was lost,
/// from the page's own record (a busy host delays the test's questions, not
/// the page's answer).
fn said_lost_after(b: &mut Browser, since_ms: f64) -> Duration {
    assert!(b
        .wait_for(
            "transplanterScreen.link() === 'lost'",
            Duration::from_secs(30)
        )
        .unwrap());
    let at = b
        .eval("transplanterScreen.lostAt()")
        .unwrap()
        .as_f64()
        .unwrap();
    Duration::from_secs_f64(((at - since_ms) / 1000.0).max(0.0))
}

/// The touch frames in what the page sent: (page, id, event).
fn touches(server: &ScreenServer) -> Vec<(u8, u8, u8)> {
    let mut all = Vec::new();
    for m in server.from_page() {
        all.extend(m.bytes);
    }
    let mut out = Vec::new();
    for f in qemu_tests::instructions(&all) {
        if let [0x65, p, id, ev] = f {
            out.push((*p, *id, *ev));
        }
    }
    out
}

fn id_of(page: Page, name: &str) -> u8 {
    COMPONENTS
        .iter()
        .find(|c| c.page == page && c.name() == name)
        .map(|c| c.id())
        .unwrap()
}

/// The script that tells, for every component of `page`, whether it is on
/// the page and shown (inside the window, and not cut off by a box that
/// scrolls or clips it), and the size of each touch target (CSS px).
fn check_script(page: Page) -> String {
    let list: Vec<String> = COMPONENTS
        .iter()
        .filter(|c| c.page == page)
        .map(|c| {
            format!(
                "[{}, \"{}\", {}]",
                c.id(),
                c.name(),
                matches!(c.kind(), Kind::Button)
                    || matches!(c.role, hmi_proto::screen::Role::Input(_))
            )
        })
        .collect();
    format!(
        "(() => {{ const out = []; for (const [id, name, target] of [{}]) {{ \
         const e = document.querySelector('section[data-page=\"{p}\"] [data-name=\"' + name + '\"][data-id=\"' + id + '\"]'); \
         const r = e ? e.getBoundingClientRect() : null; \
         let clipped = false; \
         for (let a = e && e.parentElement; a; a = a.parentElement) {{ \
           if (getComputedStyle(a).overflowY === 'visible') continue; \
           const q = a.getBoundingClientRect(); \
           if (r.top < q.top - 1 || r.bottom > q.bottom + 1 || r.left < q.left - 1 || r.right > q.right + 1) clipped = true; }} \
         out.push({{name, present: !!e, shown: !!(r && r.width > 0 && r.height > 0 && r.bottom <= innerHeight + 1 && r.right <= innerWidth + 1 && !clipped), \
         target, w: r ? r.width : 0, h: r ? r.height : 0}}); }} return out; }})()",
        list.join(","),
        p = page.id()
    )
}

/// Problems with `page` as shown: components missing or not shown, touch
/// targets below 12 mm on a 7" screen of this viewport.
fn page_problems(b: &mut Browser, page: Page, viewport: (u32, u32)) -> Vec<String> {
    let mm_per_px = 177.8 / f64::from(viewport.0).hypot(f64::from(viewport.1));
    let v = b.eval(&check_script(page)).unwrap();
    let mut problems = Vec::new();
    for c in v.as_array().unwrap() {
        let name = c["name"].as_str().unwrap_or("?");
        if c["present"] != true {
            problems.push(format!("page {} `{name}` missing", page.id()));
        } else if c["shown"] != true {
            problems.push(format!("page {} `{name}` not shown", page.id()));
        } else if c["target"] == true {
            let (w, h) = (
                c["w"].as_f64().unwrap_or(0.0) * mm_per_px,
                c["h"].as_f64().unwrap_or(0.0) * mm_per_px,
            );
            if w < 12.0 || h < 12.0 {
                problems.push(format!(
                    "page {} `{name}` {w:.1} x {h:.1} mm at {}x{}",
                    page.id(),
                    viewport.0,
                    viewport.1
                ));
            }
        }
    }
    problems
}

/// Every text the firmware can write into a component of `role` from a
/// fixed set (the labels of the settings, the live texts of the ground);
/// empty for the others (messages, the version).
fn role_texts(role: Role) -> Vec<String> {
    use hmi_proto::screen::{
        encoder_direction_label, placement_label, slip_text, work_switch_label, CalibrationKind,
        Gear, LinkParameter, MachineProfile, StatusText, TravelSource, TravelSourceInUse,
        SLIP_UNKNOWN, STATUS_TEXT_LEN,
    };
    let texts: Vec<&str> = match role {
        Role::GearLabel => Gear::ALL.map(Gear::label).to_vec(),
        Role::CalibrationLabel => {
            let mut kinds = vec![CalibrationKind::SpeedK1];
            while kinds.len() < 4 {
                kinds.push(kinds[kinds.len() - 1].next());
            }
            kinds.into_iter().map(CalibrationKind::label).collect()
        }
        Role::ProfileLabel => MachineProfile::ALL.map(MachineProfile::label).to_vec(),
        Role::EncoderDirectionLabel | Role::GroundWheelDirectionLabel => {
            vec![
                encoder_direction_label(false),
                encoder_direction_label(true),
            ]
        }
        Role::WorkSwitchLabel => vec![work_switch_label(false), work_switch_label(true)],
        Role::PlacementLabel => vec![placement_label(false), placement_label(true)],
        Role::LinkParameterLabel => LinkParameter::ALL.map(LinkParameter::label).to_vec(),
        Role::TravelSourceLabel => [
            TravelSource::HallGear,
            TravelSource::GroundWheel,
            TravelSource::Both,
        ]
        .map(TravelSource::label)
        .to_vec(),
        Role::StatusText(StatusText::TrackSlip) => {
            return [SLIP_UNKNOWN, -1000, 1000, i16::MIN + 1, i16::MAX]
                .map(|v| slip_text(v, &mut [0u8; STATUS_TEXT_LEN]).to_string())
                .to_vec();
        }
        Role::StatusText(StatusText::TravelSourceInUse) => [
            TravelSourceInUse::HallGear,
            TravelSourceInUse::GroundWheel,
            TravelSourceInUse::HallStandIn,
        ]
        .map(TravelSourceInUse::label)
        .to_vec(),
        _ => Vec::new(),
    };
    texts.into_iter().map(String::from).collect()
}

/// The widest value each number of `page` can show: five significant
/// digits at its decimals (99999, 9999.9, 999.99: a pass of 10 km, 99 999
/// plants), an input's range ends; and the longest text of each label and
/// live text ([`role_texts`]); written as the firmware writes them.
fn widest_values(page: Page) -> Vec<u8> {
    let mut out = Vec::new();
    for c in COMPONENTS.iter().filter(|c| c.page == page) {
        if let Some(longest) = role_texts(c.role).iter().max_by_key(|t| t.len()) {
            let obj = hmi_proto::ObjName::new(c.name()).unwrap();
            let mut buf = [0u8; hmi_proto::MAX_INSTRUCTION_LEN];
            let n = hmi_proto::Instruction::set_text(obj, longest)
                .unwrap()
                .emit(&mut buf)
                .unwrap();
            out.extend_from_slice(&buf[..n]);
            continue;
        }
        let values: Vec<i64> = match c.role {
            Role::Input(f) => {
                let (min, max) = f.range();
                vec![i64::from(min), i64::from(max)]
            }
            Role::Status(_) => vec![99_999],
            _ => continue,
        };
        if !matches!(c.kind(), Kind::Number | Kind::Xfloat(_)) {
            continue;
        }
        for v in values {
            out.extend_from_slice(format!("{}.val={v}", c.name()).as_bytes());
            out.extend_from_slice(&[0xFF; 3]);
        }
    }
    out
}

/// Texts on the shown page (and the top bar) that do not fit their box:
/// each text's laid-out extent (a Range, so what `overflow: hidden` clips
/// counts) against its element and its component, and each input's text
/// against its field. The monitor's event list is a log clipped by design.
const OVERFLOW_SCRIPT: &str = r#"
(() => {
  const bad = [];
  const page = document.querySelector('section[data-page="' + transplanterScreen.shown() + '"]');
  const inside = (t, b) => t.left >= b.left - 1 && t.right <= b.right + 1 &&
    t.top >= b.top - 1 && t.bottom <= b.bottom + 1;
  const name = (e) => (e.closest('[data-name]') || e).dataset.name || e.id || e.className;
  for (const root of [page, document.getElementById('bar')]) {
    for (const e of root.querySelectorAll('*')) {
      if (!e.getClientRects().length || e.closest('.events')) continue;
      const own = e.getBoundingClientRect();
      const comp = (e.closest('[data-name]') || e).getBoundingClientRect();
      if (e.tagName === 'INPUT') {
        if (e.scrollWidth > e.clientWidth + 1) bad.push(name(e) + ': "' + e.value + '" ' + e.scrollWidth + ' px in ' + e.clientWidth);
        continue;
      }
      for (const n of e.childNodes) {
        if (n.nodeType !== 3 || !n.textContent.trim()) continue;
        const r = document.createRange();
        r.selectNodeContents(n);
        const t = r.getBoundingClientRect();
        const view = { left: 0, top: 0, right: innerWidth, bottom: innerHeight };
        if (!inside(t, own) || !inside(t, comp) || !inside(t, view)) {
          bad.push(name(e) + ': "' + n.textContent.trim() + '" ' + Math.round(t.width) + 'x' + Math.round(t.height) +
            ' px in ' + Math.round(comp.width) + 'x' + Math.round(comp.height));
        }
      }
    }
  }
  return bad;
})()
"#;

/// The texts of `page` that overflow their box at this viewport.
fn overflows(b: &mut Browser, page: Page, viewport: (u32, u32)) -> Vec<String> {
    let found = b.eval(OVERFLOW_SCRIPT).unwrap();
    found
        .as_array()
        .map(|a| {
            a.iter()
                .map(|t| {
                    format!(
                        "page {} at {viewport:?}: {}",
                        page.name(),
                        t.as_str().unwrap_or("")
                    )
                })
                .collect()
        })
        .unwrap_or_default()
}

/// Reply frames a Nextion sends for an instruction (NIS §7): results,
/// `sendme`'s page, `get`'s data, `rest`'s start-up and ready.
const ANSWERS: &[u8] = &[
    0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x09, 0x11, 0x12, 0x1A, 0x1B, 0x1C, 0x1D, 0x1E, 0x1F,
    0x20, 0x23, 0x66, 0x70, 0x71, 0x88,
];

/// A Web Serial port the test controls, in place of `navigator.serial`.
const SERIAL_STUB: &str = r#"
(() => {
  const s = { opened: [], written: [], busy: false, gone: false, ctl: null };
  window.__serial = s;
  class FakePort {
    constructor() { this.readable = null; this.writable = null; }
    async open(opts) {
      if (s.busy) throw new DOMException('The port is already open.', 'InvalidStateError');
      if (s.gone) throw new DOMException('The device has been lost.', 'NetworkError');
      s.opened.push(opts);
      this.readable = new ReadableStream({ start: (c) => { s.ctl = c; } });
      this.writable = new WritableStream({ write: (chunk) => { s.written.push(...chunk); } });
    }
    async close() { this.readable = null; this.writable = null; }
    getInfo() { return { usbVendorId: 0x1a86, usbProductId: 0x7523 }; }
  }
  const port = new FakePort();
  let granted = [];
  const serial = new EventTarget();
  serial.requestPort = async () => { granted = [port]; return port; };
  serial.getPorts = async () => granted.slice();
  Object.defineProperty(navigator, 'serial', { value: serial, configurable: true });
  s.feed = (bytes) => s.ctl.enqueue(new Uint8Array(bytes));
  s.unplug = () => {
    s.gone = true; granted = [];
    s.ctl.error(new DOMException('The device has been lost.', 'NetworkError'));
    serial.dispatchEvent(new Event('disconnect'));
  };
  s.replug = () => { s.gone = false; granted = [port]; serial.dispatchEvent(new Event('connect')); };
})();
"#;

/// A small deterministic generator for the bad input.
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

#[test]
fn every_component_on_its_page_and_nothing_sent_on_bad_input() {
    let server = ScreenServer::start(0, None).unwrap();
    let mut b = Browser::launch(1280, 800).unwrap();
    open(&mut b, &server.url());
    wait_connected(&server);

    // Every page, both machines, two tablet sizes.
    let mut problems = Vec::new();
    for viewport in [(1024, 600), (1280, 800), (800, 480)] {
        b.viewport(viewport.0, viewport.1).unwrap();
        for page in Page::ALL {
            assert!(server.inject(&page_bytes(page, 1.0)));
            assert!(
                b.wait_for(
                    &format!("transplanterScreen.shown() === {}", page.id()),
                    Duration::from_secs(10)
                )
                .unwrap(),
                "page {} not shown",
                page.id()
            );
            problems.extend(page_problems(&mut b, page, viewport));
            // Every value and unit readable: the screenshots' run, then
            // the widest values.
            problems.extend(overflows(&mut b, page, viewport));
            let widest = widest_values(page);
            let before = b
                .eval("transplanterScreen.stats().instructions")
                .unwrap()
                .as_u64()
                .unwrap_or(0);
            server.inject(&widest);
            let count = qemu_tests::instructions(&widest).len();
            assert!(b
                .wait_for(
                    &format!(
                        "transplanterScreen.stats().instructions >= {}",
                        before + count as u64
                    ),
                    Duration::from_secs(10)
                )
                .unwrap());
            problems.extend(overflows(&mut b, page, viewport));
        }
        // The link buttons of the top bar are touch targets too.
        let mm_per_px = 177.8 / f64::from(viewport.0).hypot(f64::from(viewport.1));
        for tool in ["use-serial", "use-ws"] {
            let r = b
                .eval(&format!(
                    "(() => {{ const r = document.getElementById('{tool}').getBoundingClientRect(); return [r.width, r.height]; }})()"
                ))
                .unwrap();
            let (w, h) = (
                r[0].as_f64().unwrap_or(0.0) * mm_per_px,
                r[1].as_f64().unwrap_or(0.0) * mm_per_px,
            );
            if w < 12.0 || h < 12.0 {
                problems.push(format!("`{tool}` {w:.1} x {h:.1} mm at {viewport:?}"));
            }
        }
    }
    assert!(problems.is_empty(), "{problems:#?}");
    // The check fails when a component is missing (one taken out), and
    // when a value does not fit its box (one more digit than it can show).
    b.viewport(1280, 800).unwrap();
    server.inject(&page_bytes(Page::Adaptive, 1.0));
    b.wait_for("transplanterScreen.shown() === 3", Duration::from_secs(10))
        .unwrap();
    assert!(overflows(&mut b, Page::Adaptive, (1280, 800)).is_empty());
    b.eval(&format!(
        "document.querySelector('{} .value').textContent = '12345.678'",
        sel(3, "xtarget")
    ))
    .unwrap();
    let found = overflows(&mut b, Page::Adaptive, (1280, 800));
    assert!(
        found.len() == 1 && found[0].contains("xtarget"),
        "{found:?}"
    );
    b.eval(&format!(
        "document.querySelector('{}').remove()",
        sel(3, "xcv")
    ))
    .unwrap();
    assert_eq!(
        page_problems(&mut b, Page::Adaptive, (1280, 800)),
        vec!["page 3 `xcv` missing".to_string()]
    );
    // And when a box that clips cuts a component off (the live values'
    // column made too short for its last tiles).
    b.eval(
        "(() => { const v = document.querySelector('section[data-page=\"3\"] .values'); \
         v.style.height = '120px'; v.style.overflow = 'hidden'; })()",
    )
    .unwrap();
    let cut = page_problems(&mut b, Page::Adaptive, (1280, 800));
    assert!(
        cut.contains(&"page 3 `tground` not shown".to_string()),
        "{cut:?}"
    );
    assert!(touches(&server).is_empty(), "the page touched by itself");

    // Bad input from the firmware's side: random bytes, then every
    // instruction of a page change with one bit flipped, then an
    // instruction for a component the contract does not have.
    let before = server.from_page().len();
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    let random: Vec<u8> = (0..4096).map(|_| (rng.next() >> 24) as u8).collect();
    for chunk in random.chunks(256) {
        server.inject(chunk);
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut flipped = Vec::new();
    let every_page: Vec<u8> = (0..8)
        .flat_map(|_| Page::ALL.iter().flat_map(|p| page_bytes(*p, 2.0)))
        .collect();
    for ins in qemu_tests::instructions(&every_page) {
        let mut ins = ins.to_vec();
        let bit = (rng.next() % (ins.len() as u64 * 8)) as usize;
        ins[bit / 8] ^= 1 << (bit % 8);
        flipped.extend(ins);
        flipped.extend([0xFF; 3]);
    }
    let n_flipped = server.from_page().len();
    server.inject(&flipped);
    // The same instructions into the independent Nextion model (written
    // from the Nextion Instruction Set), from the same page: the same
    // answers, frame for frame.
    let mut model = nextion_model::Screen::new();
    model.receive(1_000, b"page 3\xFF\xFF\xFF");
    model.take_output();
    // The model's answer to each instruction.
    let mut expected: Vec<(String, Vec<u8>)> = Vec::new();
    for (i, ins) in qemu_tests::instructions(&flipped).into_iter().enumerate() {
        let mut one = ins.to_vec();
        one.extend([0xFF; 3]);
        model.receive(2_000 + i as u64 * 100, &one);
        for a in qemu_tests::instructions(&model.take_output()) {
            expected.push((String::from_utf8_lossy(ins).into_owned(), a.to_vec()));
        }
    }
    // The page's answers, once it has given as many as the model (and a
    // moment more, for any extra ones), or 30 s.
    let answered = || {
        let mut got = Vec::new();
        for m in &server.from_page()[n_flipped..] {
            got.extend_from_slice(&m.bytes);
        }
        qemu_tests::instructions(&got)
            .into_iter()
            .map(<[u8]>::to_vec)
            .collect::<Vec<Vec<u8>>>()
    };
    let deadline = Instant::now() + Duration::from_secs(30);
    while answered().len() < expected.len() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(200));
    let got = answered();
    if let Some(k) =
        (0..expected.len().max(got.len())).find(|&k| expected.get(k).map(|e| &e.1) != got.get(k))
    {
        panic!(
            "answer {k}: the page {:02x?}, the Nextion model {:02x?} (to {:?}; {} and {} answers)",
            got.get(k),
            expected.get(k).map(|e| &e.1),
            expected.get(k).map(|e| &e.0),
            got.len(),
            expected.len()
        );
    }
    server.inject(b"xfoo.val=12\xFF\xFF\xFF");
    // Taken once it has reached the page (everything before it has too).
    assert!(b
        .wait_for(
            "transplanterScreen.stats().unknown_names.xfoo === 1",
            Duration::from_secs(10)
        )
        .unwrap());
    std::thread::sleep(Duration::from_millis(100));
    let injected: Vec<u8> = random.iter().chain(&flipped).copied().collect();
    let terminated = qemu_tests::instructions(&injected).len() + 1;
    let answers: Vec<Vec<u8>> = server.from_page()[before..]
        .iter()
        .map(|m| m.bytes.clone())
        .collect();
    for a in &answers {
        assert!(
            a.len() >= 4 && a.ends_with(&[0xFF; 3]) && ANSWERS.contains(&a[0]),
            "not an answer: {a:02x?}"
        );
    }
    assert!(
        answers.len() <= terminated,
        "{} frames for {terminated} instructions",
        answers.len()
    );
    assert!(touches(&server).is_empty(), "a touch without an operator");
    assert!(b.exceptions().is_empty(), "{:?}", b.exceptions());
    let notice = b
        .eval("document.getElementById('notice').textContent")
        .unwrap();
    let stats = b.eval("transplanterScreen.stats()").unwrap();
    assert!(stats["garbled"].as_u64().unwrap_or(0) > 0, "{stats}");
    assert!(
        stats["unknown_names"]["xfoo"].as_u64().unwrap_or(0) == 1,
        "{stats}"
    );
    assert!(notice.as_str().unwrap_or("").contains("xfoo"), "{notice}");
    let events = b.eval("transplanterScreen.events()").unwrap().to_string();
    assert!(
        events.contains("Unreadable data from the controller"),
        "{events}"
    );
    // Still a screen: it answers the handshake.
    let n = server.from_page().len();
    server.inject(b"\xFF\xFF\xFFpage 3\xFF\xFF\xFFsendme\xFF\xFF\xFF");
    assert!(b
        .wait_for("transplanterScreen.shown() === 3", Duration::from_secs(10))
        .unwrap());
    let deadline = Instant::now() + Duration::from_secs(10);
    while server.from_page().len() == n && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(
        server
            .from_page()
            .get(n..)
            .unwrap_or(&[])
            .iter()
            .map(|m| m.bytes.clone())
            .collect::<Vec<_>>(),
        vec![vec![0x66, 3, 0xFF, 0xFF, 0xFF]]
    );

    // A second page on the simulator gets the busy code and says so.
    let mut second = Browser::launch(800, 480).unwrap();
    second.goto(&server.url()).unwrap();
    assert!(second
        .wait_for(
            "document.getElementById('link-detail').textContent.includes('another')",
            Duration::from_secs(10)
        )
        .unwrap());
    assert_eq!(server.sessions(), 1);
    drop(second);

    // Web Serial, stubbed: the operator chooses the port.
    b.before_page(SERIAL_STUB).unwrap();
    b.goto(&format!("http://127.0.0.1:{}/", server.port()))
        .unwrap();
    b.tap("#use-serial").unwrap();
    assert!(b
        .wait_for(
            "window.__serial.opened.length === 1",
            Duration::from_secs(10)
        )
        .unwrap());
    let opened = b.eval("window.__serial.opened[0]").unwrap();
    assert_eq!(opened["baudRate"], 115_200, "{opened}");
    assert_eq!(opened["dataBits"], 8);
    assert_eq!(opened["stopBits"], 1);
    assert_eq!(opened["parity"], "none");
    b.eval("window.__serial.feed([0xFF,0xFF,0xFF,0x73,0x65,0x6E,0x64,0x6D,0x65,0xFF,0xFF,0xFF])")
        .unwrap();
    assert!(b
        .wait_for(
            "JSON.stringify(window.__serial.written) === '[102,0,255,255,255]'",
            Duration::from_secs(10)
        )
        .unwrap());
    assert!(b
        .wait_for(
            "transplanterScreen.link() === 'ok'",
            Duration::from_secs(10)
        )
        .unwrap());
    // The adapter pulled: said within 1 s; plugged back: open again.
    let pulled = wall_ms();
    b.eval("window.__serial.unplug()").unwrap();
    let said = said_lost_after(&mut b, pulled);
    eprintln!("screen_web: adapter pulled, the page said so in {said:?}");
    assert!(said <= Duration::from_secs(1), "{said:?}");
    b.eval("window.__serial.replug()").unwrap();
    assert!(b
        .wait_for(
            "window.__serial.opened.length === 2",
            Duration::from_secs(10)
        )
        .unwrap());
    b.eval("window.__serial.feed([0x70,0x61,0x67,0x65,0x20,0x31,0xFF,0xFF,0xFF])")
        .unwrap();
    assert!(b
        .wait_for(
            "transplanterScreen.link() === 'ok' && transplanterScreen.shown() === 1",
            Duration::from_secs(10)
        )
        .unwrap());
    // Another baud rate: the adapter reports framing errors; the page says
    // the data is unreadable and opens the port again.
    b.eval("window.__serial.ctl.error(new DOMException('Framing error.', 'FramingError'))")
        .unwrap();
    assert!(b
        .wait_for(
            "window.__serial.opened.length === 3",
            Duration::from_secs(10)
        )
        .unwrap());
    assert!(b
        .wait_for(
            "document.getElementById('notice').textContent.includes('115 200 baud 8N1')",
            Duration::from_secs(10)
        )
        .unwrap());
    // The port in use (another tab or program): said plainly.
    b.eval("window.__serial.busy = true; window.__serial.unplug(); window.__serial.replug()")
        .unwrap();
    assert!(b
        .wait_for(
            "document.getElementById('link-detail').textContent.includes('in use')",
            Duration::from_secs(10)
        )
        .unwrap());
    assert_eq!(
        b.eval("window.__serial.written.length").unwrap(),
        5,
        "the serial page sent more than its one answer"
    );
    assert!(b.exceptions().is_empty(), "{:?}", b.exceptions());
}

/// The ISO 7256-1 indices of the simulator's plants after `from_ms`, in
/// 0.1 % (quality of feed, multiples, misses, precision CV), and the count.
fn true_indices(logs: &[String], from_ms: u32, spacing_m: f64) -> ([f64; 4], u32) {
    let mut acc = SpacingAccumulator::new(spacing_m, 0.1).unwrap();
    let mut n = 0;
    for l in logs.iter().filter(|l| l.contains(" sim: plant ")) {
        if log_time_ms(l).unwrap_or(0) < from_ms {
            continue;
        }
        if let Some(um) = number_after(l, " at ") {
            acc.push_plant(um / 1e6);
            n += 1;
        }
    }
    let m = acc.metrics(0.0);
    (
        [
            m.quality_of_feed_pct,
            m.multiple_index_pct,
            m.miss_index_pct,
            m.precision_pct,
        ],
        n,
    )
}

#[test]
fn the_qemu_board_is_driven_from_the_page() {
    let elf = qemu_firmware_elf().unwrap();
    // Real time, paced by the wall clock; the page answers when it does.
    let mut fw = Firmware::boot(
        &elf,
        &BootOptions {
            run_ms: Some(90_000),
            scenario: vec!["gear=2".into(), "plant_log=1".into(), "noise=0".into()],
            ..BootOptions::default()
        },
    )
    .unwrap();
    fw.pace_in_real_time().unwrap();
    let server = ScreenServer::start(0, Some(fw.serial_stream().unwrap())).unwrap();
    let mut b = Browser::launch(1280, 800).unwrap();
    open(&mut b, &server.url());
    assert!(
        b.wait_for("transplanterScreen.shown() === 1", Duration::from_secs(60))
            .unwrap(),
        "the firmware never set the page up; log:\n{}",
        fw.logs().join("\n")
    );
    let log_has = |fw: &Firmware, what: &str, secs: u64| {
        fw.wait_log(Duration::from_secs(secs), |l| l.contains(what))
            .unwrap_or_else(|| panic!("no `{what}` in the log:\n{}", fw.logs().join("\n")))
    };
    // The operator: Speed-Adaptive, 7.0 cm, Low 2, Start.
    b.tap(&sel(1, "badapt")).unwrap();
    assert!(b
        .wait_for("transplanterScreen.shown() === 3", Duration::from_secs(30))
        .unwrap());
    b.tap(&sel(3, "nspacing")).unwrap();
    b.eval(&format!(
        "document.querySelector('{}').select()",
        sel(3, "nspacing")
    ))
    .unwrap();
    b.type_text("7.0").unwrap();
    b.tap(&sel(3, "bapply")).unwrap();
    log_has(&fw, "screen: SetSpacing", 30);
    b.tap(&sel(3, "bgearup")).unwrap();
    assert!(b
        .wait_for(
            "transplanterScreen.text(3, 'tgear') === 'Low 2'",
            Duration::from_secs(30)
        )
        .unwrap());
    b.tap(&sel(3, "bstart")).unwrap();
    let running = log_has(&fw, "drum: Running", 30);
    let started_ms = log_time_ms(&running).unwrap();
    assert!(
        b.wait_for(
            "transplanterScreen.value(3, 'nplants') >= 10",
            Duration::from_secs(90)
        )
        .unwrap(),
        "no plants counted on the page: page {} shows {} plants, link {}; the simulator {:?}; log:\n{}",
        b.eval("transplanterScreen.shown()").unwrap(),
        value(&mut b, 3, "nplants"),
        b.eval("transplanterScreen.link()").unwrap(),
        sim_samples(&fw.logs()).last(),
        fw.logs().iter().filter(|l| !l.contains("sim:")).cloned().collect::<Vec<_>>().join("\n")
    );

    // The monitor's spacing over the last 10 s (plants and distance as
    // the firmware shows them: ±0.1 m over ≥ 10 plants).
    assert!(
        b.wait_for(
            "(() => { const r = transplanterScreen.recentSpacing(); return !!r && Math.abs(r.cm - 7) <= 1; })()",
            Duration::from_secs(60)
        )
        .unwrap(),
        "monitor spacing {}",
        b.eval("JSON.stringify(transplanterScreen.recentSpacing())").unwrap()
    );
    // The line cut mid-run, and kept out for 3.5 s.
    server.set_accepting(false);
    let cut_ms = wall_ms();
    let cut = Instant::now();
    server.cut();
    let said_in = said_lost_after(&mut b, cut_ms);
    assert!(said_in <= Duration::from_secs(1), "{said_in:?}");
    let silent = log_has(&fw, "touchscreen silent: running on the last settings", 60);
    std::thread::sleep(Duration::from_millis(800));
    server.set_accepting(true);
    let connected = fw
        .wait_log(Duration::from_secs(60), |l| {
            l.contains("touchscreen connected")
                && log_time_ms(l).unwrap_or(0) > log_time_ms(&silent).unwrap_or(0)
        })
        .expect("the firmware never took the page back");
    let reconnected_in = cut.elapsed();
    assert!(b
        .wait_for(
            "transplanterScreen.link() === 'ok' && transplanterScreen.shown() === 1",
            Duration::from_secs(30)
        )
        .unwrap());
    // The drum ran on the last settings while the screen was away.
    let logs = fw.logs();
    let during: Vec<_> = sim_samples(&logs)
        .into_iter()
        .filter(|s| {
            s.t_ms > log_time_ms(&silent).unwrap() && s.t_ms < log_time_ms(&connected).unwrap()
        })
        .collect();
    assert!(
        !during.is_empty() && during.iter().all(|s| s.drum_rpm > 1.0),
        "drum while the screen was lost: {:?}",
        during.iter().map(|s| s.drum_rpm).collect::<Vec<_>>()
    );
    assert!(!logs.iter().any(|l| l.contains("drum: Stopped")));
    eprintln!(
        "screen_web: drum while the screen was lost: {:.1} r/min mean over {} samples",
        during.iter().map(|s| s.drum_rpm).sum::<f64>() / during.len() as f64,
        during.len()
    );

    // Back to the run page, and Stop.
    b.tap(&sel(1, "badapt")).unwrap();
    assert!(b
        .wait_for("transplanterScreen.shown() === 3", Duration::from_secs(30))
        .unwrap());
    std::thread::sleep(Duration::from_millis(600));
    b.tap(&sel(3, "bstop")).unwrap();
    let taken = log_has(&fw, "screen: Stop", 30);
    let stopped = log_has(&fw, "drum: Stopped", 30);
    let (taken_ms, stopped_ms) = (log_time_ms(&taken).unwrap(), log_time_ms(&stopped).unwrap());
    assert!(
        stopped_ms >= taken_ms && stopped_ms <= taken_ms + 10,
        "Stop taken at {taken_ms} ms, drum stopped at {stopped_ms} ms"
    );
    // The values settle (status writes go on after the Stop).
    std::thread::sleep(Duration::from_millis(1500));
    let logs = fw.logs();
    let truth_plants = sim_samples(&logs).last().map(|s| s.plants).unwrap();
    let page_plants = value(&mut b, 3, "nplants");
    let (truth, n) = true_indices(&logs, started_ms, 0.07);
    let shown_idx = [
        value(&mut b, 3, "xqf"),
        value(&mut b, 3, "xmult"),
        value(&mut b, 3, "xmiss"),
        value(&mut b, 3, "xcv"),
    ];
    eprintln!(
        "screen_web: plants page {page_plants}, simulator {truth_plants} ({n} logged); indices \
         page {shown_idx:?} x0.1 %, simulator {truth:.2?} %; link lost said in {said_in:?}, \
         firmware back in {reconnected_in:?}; Stop taken {taken_ms} ms, drum stopped {stopped_ms} ms"
    );
    assert!(
        (page_plants - i64::from(truth_plants)).abs() <= 1,
        "plants: page {page_plants}, simulator {truth_plants}"
    );
    for (shown, truth) in shown_idx.iter().zip(truth) {
        assert!(
            (*shown as f64 / 10.0 - truth).abs() <= 0.5,
            "indices: page {shown_idx:?} x0.1 %, simulator {truth:?} %"
        );
    }
    // The monitor drew the last minute and logged the link's loss.
    let travel = b
        .eval("transplanterScreen.series('TravelSpeed').length")
        .unwrap();
    assert!(travel.as_u64().unwrap_or(0) > 20, "{travel}");
    let events = b.eval("transplanterScreen.events()").unwrap().to_string();
    assert!(
        events.contains("Link lost") && events.contains("Link restored"),
        "{events}"
    );
    // The page sent touches only for the operator's taps: Speed-Adaptive,
    // Apply, Gear +, Start (press, release), Speed-Adaptive, Stop (press,
    // release).
    let (m, a) = (Page::Mode, Page::Adaptive);
    assert_eq!(
        touches(&server),
        vec![
            (1, id_of(m, "badapt"), 0),
            (3, id_of(a, "bapply"), 0),
            (3, id_of(a, "bgearup"), 0),
            (3, id_of(a, "bstart"), 1),
            (3, id_of(a, "bstart"), 0),
            (1, id_of(m, "badapt"), 0),
            (3, id_of(a, "bstop"), 1),
            (3, id_of(a, "bstop"), 0),
        ]
    );
    assert!(b.exceptions().is_empty(), "{:?}", b.exceptions());
    qemu_tests::check_stack(&fw.logs()).unwrap();

    // The board reboots: the page hears nothing, says so, and follows the
    // new firmware's set-up without a reload.
    drop(fw);
    let rebooted = Instant::now();
    assert!(b
        .wait_for(
            "transplanterScreen.link() === 'lost'",
            Duration::from_secs(10)
        )
        .unwrap());
    let silent_in = rebooted.elapsed();
    let mut fw = Firmware::boot(
        &elf,
        &BootOptions {
            run_ms: Some(30_000),
            ..BootOptions::default()
        },
    )
    .unwrap();
    fw.pace_in_real_time().unwrap();
    server.set_upstream(fw.serial_stream().unwrap()).unwrap();
    log_has(&fw, "touchscreen connected", 60);
    assert!(b
        .wait_for(
            "transplanterScreen.link() === 'ok' && transplanterScreen.shown() === 1",
            Duration::from_secs(30)
        )
        .unwrap());
    // Set up three times: at the start, after the lost line, after the
    // reboot.
    let events = b.eval("transplanterScreen.events()").unwrap().to_string();
    assert_eq!(
        events.matches("Controller set the screen up").count(),
        3,
        "{events}"
    );
    eprintln!(
        "screen_web: board rebooted: the page said the controller was silent in {silent_in:?}, \
         back on the new firmware's home page in {:?}",
        rebooted.elapsed()
    );
    // Still nothing sent but answers.
    assert_eq!(touches(&server).len(), 8);
}

/// The lowest WCAG 2 contrast ratio of the shown page's visible texts
/// (and the top bar's) against the background they sit on, and where.
const CONTRAST_SCRIPT: &str = r#"
(() => {
  const rgb = (s) => (s.match(/[0-9.]+/g) || []).map(Number);
  const lum = ([r, g, b]) => {
    const f = (c) => { c /= 255; return c <= 0.03928 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4; };
    return 0.2126 * f(r) + 0.7152 * f(g) + 0.0722 * f(b);
  };
  const bg = (e) => {
    for (let x = e; x; x = x.parentElement) {
      const c = rgb(getComputedStyle(x).backgroundColor);
      if (c.length === 3 || (c.length === 4 && c[3] > 0.5)) return c.slice(0, 3);
    }
    return [255, 255, 255];
  };
  let worst = { ratio: 99, what: '' };
  const page = document.querySelector('section[data-page="' + transplanterScreen.shown() + '"]');
  for (const root of [page, document.getElementById('bar')]) {
    for (const e of [root, ...root.querySelectorAll('*')]) {
      if (!e.getClientRects().length) continue;
      if (![...e.childNodes].some((n) => n.nodeType === 3 && n.textContent.trim()) && e.tagName !== 'INPUT') continue;
      const [a, b] = [lum(rgb(getComputedStyle(e).color).slice(0, 3)), lum(bg(e))];
      const ratio = (Math.max(a, b) + 0.05) / (Math.min(a, b) + 0.05);
      if (ratio < worst.ratio) worst = { ratio, what: (e.dataset.name || e.id || e.className) + ': ' + e.textContent.trim().slice(0, 30) };
    }
  }
  return worst;
})()
"#;

/// What users expect of a field tool: the page fetches nothing (works
/// offline, also opened from a file), its texts are high-contrast, the link
/// state is plain and a touch without the link sends nothing, and a motor
/// start needs the operator's own press and release of Start.
#[test]
fn a_field_tool_offline_high_contrast_and_start_only_from_press_and_release() {
    // Opened from a file: the script runs, nothing is fetched.
    let file = std::env::temp_dir().join(format!("screen-web-{}.html", std::process::id()));
    std::fs::write(&file, qemu_tests::screen_web::page_html().unwrap()).unwrap();
    let mut b = Browser::launch(1280, 800).unwrap();
    open(&mut b, &format!("file://{}", file.display()));
    let fetched = b
        .eval("performance.getEntriesByType('resource').map((e) => e.name)")
        .unwrap();
    assert_eq!(
        fetched,
        serde_json::json!([]),
        "fetched from a file: {fetched}"
    );
    let _ = std::fs::remove_file(&file);

    let server = ScreenServer::start(0, None).unwrap();
    open(&mut b, &server.url());
    wait_connected(&server);
    let fetched = b
        .eval("performance.getEntriesByType('resource').map((e) => e.name)")
        .unwrap();
    assert_eq!(fetched, serde_json::json!([]), "fetched: {fetched}");
    let show = |b: &mut Browser| {
        assert!(server.inject(&page_bytes(Page::Adaptive, 1.0)));
        assert!(b
            .wait_for(
                "transplanterScreen.shown() === 3 && transplanterScreen.link() === 'ok'",
                Duration::from_secs(10)
            )
            .unwrap());
    };
    show(&mut b);

    // Contrast: every text at least 7:1 (WCAG's highest level), link OK.
    let mut worst = f64::MAX;
    for page in [
        Page::Mode,
        Page::Adaptive,
        Page::Belt,
        Page::Alarm,
        Page::Link,
    ] {
        server.inject(&page_bytes(page, 1.0));
        assert!(b
            .wait_for(
                &format!(
                    "transplanterScreen.shown() === {} && transplanterScreen.link() === 'ok'",
                    page.id()
                ),
                Duration::from_secs(10)
            )
            .unwrap());
        let w = b.eval(CONTRAST_SCRIPT).unwrap();
        let ratio = w["ratio"].as_f64().unwrap_or(0.0);
        assert!(ratio >= 7.0, "page {}: {w}", page.name());
        worst = worst.min(ratio);
    }
    eprintln!("screen_web: lowest text contrast {worst:.1}:1");

    // Start pressed, the finger slides off and lifts: the press only (the
    // firmware starts nothing without the release, docs/hmi.md §3).
    show(&mut b);
    let start = sel(3, "bstart");
    b.press(&start).unwrap();
    let (x, y) = b.centre(&sel(3, "bback")).unwrap();
    b.release_at(x, y).unwrap();
    // A script's clicks and events are not the operator's: nothing.
    b.eval(&format!(
        "(() => {{ const e = document.querySelector('{start}'); e.click(); \
         e.dispatchEvent(new PointerEvent('pointerdown', {{bubbles: true, pointerId: 7}})); \
         e.dispatchEvent(new PointerEvent('pointerup', {{bubbles: true, pointerId: 7}})); }})()"
    ))
    .unwrap();
    std::thread::sleep(Duration::from_millis(200));
    let start_id = id_of(Page::Adaptive, "bstart");
    assert_eq!(touches(&server), vec![(3, start_id, 1)]);

    // The link lost: said plainly, the buttons refuse, nothing is sent.
    server.set_accepting(false);
    server.cut();
    assert!(b
        .wait_for(
            "transplanterScreen.link() === 'lost' && document.getElementById('link-state').textContent === 'LINK LOST'",
            Duration::from_secs(10)
        )
        .unwrap());
    b.tap(&start).unwrap();
    std::thread::sleep(Duration::from_millis(200));
    assert!(b
        .eval("document.getElementById('notice').textContent")
        .unwrap()
        .as_str()
        .unwrap_or("")
        .contains("nothing was sent"));
    server.set_accepting(true);
    wait_connected(&server);
    show(&mut b);
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(touches(&server), vec![(3, start_id, 1)]);
    assert!(b.exceptions().is_empty(), "{:?}", b.exceptions());
}
