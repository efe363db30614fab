//! The operator's screen in a browser (`web/`, docs/screen-web.md): the
//! page's build and a small server that serves it on the loopback interface
//! and joins its WebSocket to the QEMU board's USART1.
//!
//! [`page_html`] builds the one self-contained HTML file: `web/index.html`
//! with `web/style.css` and the script's parts (`web/screen.js`, `page.js`,
//! `monitor.js`, `link.js`) inlined, the screen contract from
//! `hmi_proto::export::contract_json` (pages, components, ids, roles, which
//! events send the id) and, from docs/hmi.md §6, the designer's button
//! captions and static texts. A contract button without a caption in the
//! document is an error, so the page cannot be built from a contract the
//! document has not caught up with.
//!
//! [`ScreenServer`] answers `GET /` with the page and `GET /ws` with a
//! WebSocket whose binary messages are the screen line's bytes: one page at
//! a time (a second one is closed with code 4001, which the page shows).
//! The tests also use it to cut the line, to refuse new connections for a
//! while (a cable pulled), to inject bytes on the firmware's side and to
//! read every byte the page sent.

use std::collections::BTreeMap;
use std::io::{self, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use tungstenite::protocol::frame::coding::CloseCode;
use tungstenite::protocol::CloseFrame;
use tungstenite::{Message, WebSocket};

const INDEX: &str = include_str!("../../web/index.html");
const STYLE: &str = include_str!("../../web/style.css");
/// The page's script, in parts (each a piece of one function: they share
/// its names), joined in this order.
const SCRIPTS: [&str; 4] = [
    include_str!("../../web/screen.js"),
    include_str!("../../web/page.js"),
    include_str!("../../web/monitor.js"),
    include_str!("../../web/link.js"),
];
const HMI_DOC: &str = include_str!("../../docs/hmi.md");

/// The close code a second page gets while one is connected.
pub const CLOSE_IN_USE: u16 = 4001;

/// JSON string literal.
fn json_string(s: &str) -> String {
    let mut out = String::from("\"");
    for ch in s.chars() {
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if u32::from(c) < 0x20 => out.push_str(&format!("\\u{:04x}", u32::from(c))),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// One row of a page table of docs/hmi.md §6.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DocRow {
    /// Page id.
    pub page: u8,
    /// Component id.
    pub id: u8,
    /// Object name.
    pub name: String,
    /// The "type" column (`Button "Apply"`, `Text`, …).
    pub kind: String,
    /// The "sends / receives" column.
    pub does: String,
}

/// The component rows of docs/hmi.md §6, page by page.
pub fn doc_rows(doc: &str) -> Vec<DocRow> {
    let mut rows = Vec::new();
    let mut page: Option<u8> = None;
    for line in doc.lines() {
        if let Some(rest) = line.strip_prefix("### Page ") {
            page = rest.split_whitespace().next().and_then(|n| n.parse().ok());
            continue;
        }
        if line.starts_with("## ") {
            page = None;
        }
        let Some(p) = page else { continue };
        let cols: Vec<&str> = line.split('|').map(str::trim).collect();
        // "| id | `name` | type | does |" splits into 6 parts.
        if cols.len() < 6 {
            continue;
        }
        let (Some(id), Some(name)) = (
            cols.get(1).and_then(|c| c.parse::<u8>().ok()),
            cols.get(2)
                .and_then(|c| c.strip_prefix('`'))
                .and_then(|c| c.strip_suffix('`')),
        ) else {
            continue;
        };
        rows.push(DocRow {
            page: p,
            id,
            name: name.to_string(),
            kind: cols.get(3).copied().unwrap_or("").to_string(),
            does: cols.get(4..cols.len() - 1).unwrap_or(&[]).join("|"),
        });
    }
    rows
}

/// The text between the first pair of `"` in `s`.
fn quoted(s: &str) -> Option<&str> {
    let start = s.find('"')? + 1;
    let len = s.get(start..)?.find('"')?;
    s.get(start..start + len)
}

/// The designer's texts of docs/hmi.md as JSON: `captions` (`"page.name"`
/// → the button's caption) and `statics` (components the controller never
/// writes, with their editor text). Fails when a button of the contract
/// has no row or no caption in the document.
pub fn doc_json(doc: &str) -> Result<String, String> {
    let rows = doc_rows(doc);
    let mut captions = BTreeMap::new();
    for c in hmi_proto::screen::COMPONENTS {
        let row = rows
            .iter()
            .find(|r| r.page == c.page.id() && r.id == c.id() && r.name == c.name())
            .ok_or_else(|| {
                format!(
                    "docs/hmi.md has no row `| {} | `{}` |` on page {}",
                    c.id(),
                    c.name(),
                    c.page.id()
                )
            })?;
        if c.kind() == hmi_proto::screen::Kind::Button {
            let caption = row
                .kind
                .strip_prefix("Button")
                .and_then(quoted)
                .ok_or_else(|| {
                    format!(
                        "docs/hmi.md gives button `{}` on page {} no caption (Button \"…\")",
                        c.name(),
                        c.page.id()
                    )
                })?;
            captions.insert(format!("{}.{}", c.page.id(), c.name()), caption.to_string());
        }
    }
    let mut out = String::from("{\"captions\":{");
    for (i, (k, v)) in captions.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        out.push_str(&json_string(k));
        out.push(':');
        out.push_str(&json_string(v));
    }
    out.push_str("},\"statics\":[");
    let statics: Vec<_> = rows
        .iter()
        .filter(|r| r.kind.contains("static"))
        .filter_map(|r| {
            let text = r.does.split("**").nth(1).and_then(quoted)?;
            Some(format!(
                "{{\"page\":{},\"id\":{},\"name\":{},\"text\":{}}}",
                r.page,
                r.id,
                json_string(&r.name),
                json_string(text)
            ))
        })
        .collect();
    out.push_str(&statics.join(","));
    out.push_str("]}");
    Ok(out)
}

/// Keeps `</` out of inline script text.
fn script_safe(s: &str) -> String {
    s.replace("</", "<\\/")
}

/// The self-contained page: one HTML file, nothing fetched.
pub fn page_html() -> Result<String, String> {
    let contract = hmi_proto::export::contract_json();
    let doc = doc_json(HMI_DOC)?;
    let script = format!("'use strict';\n(() => {{\n{}}})();\n", SCRIPTS.join("\n"));
    let mut html = INDEX.to_string();
    for (mark, text) in [
        ("/*STYLE*/", STYLE.to_string()),
        ("/*CONTRACT*/", script_safe(&contract)),
        ("/*DOC*/", script_safe(&doc)),
        ("/*SCRIPT*/", script_safe(&script)),
    ] {
        if !html.contains(mark) {
            return Err(format!("web/index.html lacks {mark}"));
        }
        html = html.replacen(mark, &text, 1);
    }
    Ok(html)
}

/// What the page sent, with when (since the server started).
#[derive(Clone, Debug)]
pub struct FromPage {
    /// Time since the server started.
    pub at: Duration,
    /// The bytes of one WebSocket message.
    pub bytes: Vec<u8>,
}

struct Shared {
    html: String,
    port: u16,
    started: Instant,
    upstream: Mutex<Option<TcpStream>>,
    client: Mutex<Option<Sender<Vec<u8>>>>,
    /// Incremented to cut the connected page's line.
    cut: AtomicU64,
    accepting: AtomicBool,
    mute_firmware: AtomicBool,
    from_page: Mutex<Vec<FromPage>>,
    to_page: Mutex<Vec<u8>>,
    sessions: AtomicU64,
}

/// The page's server (see the module documentation).
pub struct ScreenServer {
    shared: Arc<Shared>,
    port: u16,
}

impl ScreenServer {
    /// Serves the page on `127.0.0.1:port` (0: any free port); `upstream`
    /// is the firmware's USART1 (the QEMU board's socket), or `None`
    /// (bytes come from [`ScreenServer::inject`] only).
    pub fn start(port: u16, upstream: Option<TcpStream>) -> io::Result<Self> {
        let html = page_html().map_err(io::Error::other)?;
        let listener = TcpListener::bind(("127.0.0.1", port))?;
        let port = listener.local_addr()?.port();
        let shared = Arc::new(Shared {
            html,
            port,
            started: Instant::now(),
            upstream: Mutex::new(None),
            client: Mutex::new(None),
            cut: AtomicU64::new(0),
            accepting: AtomicBool::new(true),
            mute_firmware: AtomicBool::new(false),
            from_page: Mutex::new(Vec::new()),
            to_page: Mutex::new(Vec::new()),
            sessions: AtomicU64::new(0),
        });
        if let Some(up) = upstream {
            let reader = up.try_clone()?;
            if let Ok(mut slot) = shared.upstream.lock() {
                *slot = Some(up);
            }
            let s = shared.clone();
            thread::spawn(move || firmware_reader(reader, s));
        }
        let s = shared.clone();
        thread::spawn(move || {
            for stream in listener.incoming().map_while(Result::ok) {
                let s = s.clone();
                thread::spawn(move || {
                    let _ = serve(stream, &s);
                });
            }
        });
        Ok(Self { shared, port })
    }

    /// Joins the page to another firmware's USART1 (a board rebooted: a
    /// new QEMU); what the old one sends is no longer passed on.
    pub fn set_upstream(&self, upstream: TcpStream) -> io::Result<()> {
        let reader = upstream.try_clone()?;
        if let Ok(mut slot) = self.shared.upstream.lock() {
            if let Some(old) = slot.take() {
                let _ = old.shutdown(Shutdown::Both);
            }
            *slot = Some(upstream);
        }
        let s = self.shared.clone();
        thread::spawn(move || firmware_reader(reader, s));
        Ok(())
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// The page's address, connecting to the simulator by itself.
    pub fn url(&self) -> String {
        format!("http://127.0.0.1:{}/?link=ws", self.port)
    }

    /// Cuts the connected page's line at once (the page sees its WebSocket
    /// close, as when a cable is pulled or the board's server goes).
    pub fn cut(&self) {
        self.shared.cut.fetch_add(1, Ordering::SeqCst);
    }

    /// Whether new WebSocket connections are taken (`false`: refused, as
    /// while the cable stays out).
    pub fn set_accepting(&self, on: bool) {
        self.shared.accepting.store(on, Ordering::SeqCst);
    }

    /// Whether the firmware's bytes reach the page (`true`: dropped).
    pub fn mute_firmware(&self, on: bool) {
        self.shared.mute_firmware.store(on, Ordering::SeqCst);
    }

    /// Sends bytes to the page as if the firmware had sent them; `false`
    /// when no page is connected.
    pub fn inject(&self, bytes: &[u8]) -> bool {
        send_to_page(&self.shared, bytes.to_vec())
    }

    /// Whether a page is connected.
    pub fn connected(&self) -> bool {
        self.shared
            .client
            .lock()
            .map(|c| c.is_some())
            .unwrap_or(false)
    }

    /// WebSocket sessions accepted so far.
    pub fn sessions(&self) -> u64 {
        self.shared.sessions.load(Ordering::SeqCst)
    }

    /// Everything the page has sent.
    pub fn from_page(&self) -> Vec<FromPage> {
        self.shared
            .from_page
            .lock()
            .map(|v| v.clone())
            .unwrap_or_default()
    }

    /// Every byte passed to the page (firmware's and injected).
    pub fn to_page(&self) -> Vec<u8> {
        self.shared
            .to_page
            .lock()
            .map(|v| v.clone())
            .unwrap_or_default()
    }

    /// Time since the server started (the clock of [`FromPage::at`]).
    pub fn elapsed(&self) -> Duration {
        self.shared.started.elapsed()
    }
}

fn send_to_page(s: &Shared, bytes: Vec<u8>) -> bool {
    let sent = s
        .client
        .lock()
        .ok()
        .and_then(|c| c.as_ref().map(|tx| tx.send(bytes.clone()).is_ok()))
        .unwrap_or(false);
    if sent {
        if let Ok(mut log) = s.to_page.lock() {
            log.extend_from_slice(&bytes);
        }
    }
    sent
}

/// The firmware's bytes to the page; with no page connected they are lost,
/// as on a line with no screen.
fn firmware_reader(mut up: TcpStream, s: Arc<Shared>) {
    let mut buf = [0u8; 1024];
    loop {
        match up.read(&mut buf) {
            Ok(0) | Err(_) => return,
            Ok(n) => {
                if !s.mute_firmware.load(Ordering::SeqCst) {
                    send_to_page(&s, buf.get(..n).unwrap_or(&[]).to_vec());
                }
            }
        }
    }
}

/// The request line's path, once the whole head has arrived (peeked: the
/// bytes stay for the WebSocket handshake).
fn peek_path(stream: &TcpStream) -> io::Result<String> {
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut buf = [0u8; 4096];
    stream.set_read_timeout(Some(Duration::from_millis(50)))?;
    loop {
        match stream.peek(&mut buf) {
            Ok(0) => return Err(io::Error::other("closed before a request")),
            Ok(n) => {
                let head = buf.get(..n).unwrap_or(&[]);
                if head.windows(4).any(|w| w == b"\r\n\r\n") || n == buf.len() {
                    let text = String::from_utf8_lossy(head);
                    let path = text
                        .lines()
                        .next()
                        .and_then(|l| l.split_whitespace().nth(1))
                        .unwrap_or("/")
                        .to_string();
                    return Ok(path);
                }
            }
            Err(e)
                if e.kind() == io::ErrorKind::WouldBlock || e.kind() == io::ErrorKind::TimedOut => {
            }
            Err(e) => return Err(e),
        }
        if Instant::now() > deadline {
            return Err(io::Error::other("no request head"));
        }
        thread::sleep(Duration::from_millis(5));
    }
}

/// Reads and drops the request head (a plain HTTP request).
fn consume_head(stream: &mut TcpStream) -> io::Result<()> {
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") && head.len() < 16384 {
        if stream.read(&mut byte)? == 0 {
            break;
        }
        head.push(byte[0]);
    }
    Ok(())
}

fn serve(mut stream: TcpStream, s: &Arc<Shared>) -> io::Result<()> {
    let path = peek_path(&stream)?;
    if path == "/ws" || path.starts_with("/ws?") {
        return websocket(stream, s);
    }
    consume_head(&mut stream)?;
    let (status, kind, body) = if path == "/" || path.starts_with("/?") || path == "/index.html" {
        ("200 OK", "text/html; charset=utf-8", s.html.as_bytes())
    } else {
        ("404 Not Found", "text/plain", &b"not found"[..])
    };
    write!(
        stream,
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    stream.write_all(body)?;
    stream.flush()?;
    let _ = stream.shutdown(Shutdown::Write);
    Ok(())
}

fn websocket(stream: TcpStream, s: &Arc<Shared>) -> io::Result<()> {
    if !s.accepting.load(Ordering::SeqCst) {
        // Like a line with nothing on it: the connection goes nowhere.
        let _ = stream.shutdown(Shutdown::Both);
        return Ok(());
    }
    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
    let raw = stream.try_clone()?;
    // Only the page this server serves: another site open in the same
    // browser must not reach the machine's line (its Origin differs).
    let own = [
        format!("http://127.0.0.1:{}", s.port),
        format!("http://localhost:{}", s.port),
    ];
    // The error type is tungstenite's (its handshake callback's).
    #[allow(clippy::result_large_err)]
    let check = move |req: &tungstenite::handshake::server::Request,
                      resp: tungstenite::handshake::server::Response| {
        let origin = req
            .headers()
            .get("origin")
            .and_then(|o| o.to_str().ok())
            .map(str::to_string);
        match origin {
            Some(o) if !own.contains(&o) => {
                let mut refuse = tungstenite::handshake::server::ErrorResponse::new(Some(
                    "only the page this server serves".into(),
                ));
                *refuse.status_mut() = tungstenite::http::StatusCode::FORBIDDEN;
                Err(refuse)
            }
            _ => Ok(resp),
        }
    };
    let mut ws = tungstenite::accept_hdr(stream, check).map_err(io::Error::other)?;
    let (tx, rx): (Sender<Vec<u8>>, Receiver<Vec<u8>>) = mpsc::channel();
    {
        let mut client = s.client.lock().map_err(|_| io::Error::other("poisoned"))?;
        if client.is_some() {
            drop(client);
            let _ = ws.close(Some(CloseFrame {
                code: CloseCode::from(CLOSE_IN_USE),
                reason: "another page is connected".into(),
            }));
            let _ = ws.flush();
            return Ok(());
        }
        *client = Some(tx);
    }
    s.sessions.fetch_add(1, Ordering::SeqCst);
    let result = session(&mut ws, &raw, &rx, s);
    if let Ok(mut client) = s.client.lock() {
        *client = None;
    }
    let _ = raw.shutdown(Shutdown::Both);
    result
}

fn session(
    ws: &mut WebSocket<TcpStream>,
    raw: &TcpStream,
    rx: &Receiver<Vec<u8>>,
    s: &Arc<Shared>,
) -> io::Result<()> {
    let cut_at = s.cut.load(Ordering::SeqCst);
    raw.set_read_timeout(Some(Duration::from_millis(2)))?;
    loop {
        if s.cut.load(Ordering::SeqCst) != cut_at {
            // Pulled: no closing handshake.
            return Ok(());
        }
        match ws.read() {
            Ok(Message::Binary(bytes)) => {
                if let Ok(mut log) = s.from_page.lock() {
                    log.push(FromPage {
                        at: s.started.elapsed(),
                        bytes: bytes.to_vec(),
                    });
                }
                if let Ok(mut up) = s.upstream.lock() {
                    if let Some(up) = up.as_mut() {
                        up.write_all(&bytes)?;
                        up.flush()?;
                    }
                }
            }
            Ok(Message::Close(_)) => return Ok(()),
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if e.kind() == io::ErrorKind::WouldBlock || e.kind() == io::ErrorKind::TimedOut => {
            }
            Err(e) => return Err(io::Error::other(e)),
        }
        while let Ok(bytes) = rx.try_recv() {
            ws.send(Message::Binary(bytes.into()))
                .map_err(io::Error::other)?;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_contract_button_has_its_caption_from_the_document() {
        let doc = doc_json(HMI_DOC).unwrap();
        assert!(doc.contains("\"3.bstart\":\"Start\""), "{doc}");
        assert!(doc.contains("\"1.bfixed\":\"Fixed Mode\""), "{doc}");
        assert!(doc.contains("Control figures, not seedling fall"), "{doc}");
        // A document without page 3's Start row cannot build the page.
        let cut: String = HMI_DOC
            .lines()
            .filter(|l| !l.contains("`bstart` | Button"))
            .collect::<Vec<_>>()
            .join("\n");
        assert!(doc_json(&cut).is_err());
    }

    /// A WebSocket from another site's page is refused; the served page's
    /// own origin is taken.
    #[test]
    fn only_the_served_page_reaches_the_line() {
        let server = ScreenServer::start(0, None).unwrap();
        let url = format!("ws://127.0.0.1:{}/ws", server.port());
        let connect = |origin: &str| {
            let mut req =
                tungstenite::client::IntoClientRequest::into_client_request(url.as_str()).unwrap();
            req.headers_mut().insert("Origin", origin.parse().unwrap());
            let stream = TcpStream::connect(("127.0.0.1", server.port())).unwrap();
            tungstenite::client(req, stream).is_ok()
        };
        assert!(!connect("http://evil.example"));
        assert_eq!(server.sessions(), 0);
        assert!(connect(&format!("http://127.0.0.1:{}", server.port())));
        let deadline = Instant::now() + Duration::from_secs(5);
        while server.sessions() == 0 && Instant::now() < deadline {
            thread::sleep(Duration::from_millis(10));
        }
        assert_eq!(server.sessions(), 1);
    }

    #[test]
    fn the_page_is_one_file_with_the_contract_inlined() {
        let html = page_html().unwrap();
        for mark in ["/*STYLE*/", "/*CONTRACT*/", "/*DOC*/", "/*SCRIPT*/"] {
            assert!(!html.contains(mark), "{mark}");
        }
        assert!(html.contains("\"name\":\"nspacing\""));
        // Nothing fetched: no external script, style, font or image.
        for needle in ["src=\"http", "href=\"http", "url(http", "@import"] {
            assert!(!html.contains(needle), "{needle}");
        }
        // A link only to inline data (the empty icon that keeps the
        // browser from asking for favicon.ico).
        for tag in html.split("<link ").skip(1) {
            let tag = tag.split('>').next().unwrap_or("");
            assert!(tag.contains("href=\"data:"), "<link {tag}>");
        }
    }
}
