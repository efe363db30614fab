//! A real browser for the screen page's tests and screenshots: Debian's
//! `chromium`, headless, driven over the Chrome DevTools Protocol
//! (<https://chromedevtools.github.io/devtools-protocol/>) on a WebSocket.
//!
//! Only what the tests need: a page, `Runtime.evaluate`, trusted mouse
//! presses and releases (`Input.dispatchMouseEvent`, which the page sees as
//! pointer events like a finger's), typed text (`Input.insertText`), the
//! viewport (`Emulation.setDeviceMetricsOverride`), a script run before the
//! page's own (`Page.addScriptToEvaluateOnNewDocument`, for a stubbed
//! Web Serial port) and screenshots. Uncaught exceptions of the page are
//! kept ([`Browser::exceptions`]).

use std::io::{self, BufRead, BufReader};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use serde_json::{json, Value};
use tungstenite::{Message, WebSocket};

/// The browser binary: `$CHROMIUM`, else Debian's `chromium`.
pub fn chromium_path() -> PathBuf {
    std::env::var_os("CHROMIUM")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("chromium"))
}

/// A headless Chromium with one page.
pub struct Browser {
    child: Child,
    ws: WebSocket<TcpStream>,
    next_id: u64,
    session: String,
    exceptions: Vec<String>,
    profile: PathBuf,
}

impl Browser {
    /// Starts Chromium (a fresh profile, nothing fetched from the network)
    /// with a page of `width` × `height` CSS pixels.
    pub fn launch(width: u32, height: u32) -> io::Result<Self> {
        static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let profile = std::env::temp_dir().join(format!("screen-web-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&profile);
        std::fs::create_dir_all(&profile)?;
        let mut child = Command::new(chromium_path())
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--remote-debugging-port=0",
                "--no-first-run",
                "--no-default-browser-check",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--disable-default-apps",
                "--disable-extensions",
                "--mute-audio",
                "--hide-scrollbars",
                "--force-color-profile=srgb",
                &format!("--window-size={width},{height}"),
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg("about:blank")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| {
                io::Error::new(
                    e.kind(),
                    format!(
                        "cannot start {}: {e} (`apt-get install chromium`; cargo xtask installs it)",
                        chromium_path().display()
                    ),
                )
            })?;
        let stderr = child
            .stderr
            .take()
            .ok_or_else(|| io::Error::other("no chromium stderr"))?;
        let (tx, rx) = mpsc::channel();
        thread::spawn(move || {
            let mut sent = false;
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if !sent {
                    if let Some(at) = line.find("ws://") {
                        let _ = tx.send(line[at..].trim().to_string());
                        sent = true;
                    }
                }
            }
        });
        let url = match rx.recv_timeout(Duration::from_secs(30)) {
            Ok(url) => url,
            Err(_) => {
                let _ = child.kill();
                return Err(io::Error::other("chromium printed no DevTools address"));
            }
        };
        let addr = url
            .trim_start_matches("ws://")
            .split('/')
            .next()
            .unwrap_or("")
            .to_string();
        let stream = TcpStream::connect(&addr)?;
        stream.set_nodelay(true)?;
        let (ws, _) = tungstenite::client(url.as_str(), stream).map_err(io::Error::other)?;
        let mut b = Self {
            child,
            ws,
            next_id: 0,
            session: String::new(),
            exceptions: Vec::new(),
            profile,
        };
        let target = b.call("Target.createTarget", json!({"url": "about:blank"}))?;
        let target_id = target["targetId"].as_str().unwrap_or("").to_string();
        let attached = b.call(
            "Target.attachToTarget",
            json!({"targetId": target_id, "flatten": true}),
        )?;
        b.session = attached["sessionId"].as_str().unwrap_or("").to_string();
        b.call("Runtime.enable", json!({}))?;
        b.call("Page.enable", json!({}))?;
        b.viewport(width, height)?;
        Ok(b)
    }

    /// Sends one DevTools command (to the page once attached) and waits for
    /// its result.
    pub fn call(&mut self, method: &str, params: Value) -> io::Result<Value> {
        self.next_id += 1;
        let id = self.next_id;
        let mut msg = json!({"id": id, "method": method, "params": params});
        if !self.session.is_empty() {
            msg["sessionId"] = json!(self.session);
        }
        self.ws
            .send(Message::Text(msg.to_string().into()))
            .map_err(io::Error::other)?;
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if Instant::now() > deadline {
                return Err(io::Error::other(format!("no answer to {method}")));
            }
            let m = self.ws.read().map_err(io::Error::other)?;
            let Message::Text(text) = m else { continue };
            let v: Value = serde_json::from_str(text.as_str()).map_err(io::Error::other)?;
            if v["method"] == "Runtime.exceptionThrown" {
                let d = &v["params"]["exceptionDetails"];
                self.exceptions.push(format!(
                    "{} {}",
                    d["text"].as_str().unwrap_or(""),
                    d["exception"]["description"].as_str().unwrap_or("")
                ));
            }
            if v["id"].as_u64() == Some(id) {
                if let Some(e) = v.get("error") {
                    return Err(io::Error::other(format!("{method}: {e}")));
                }
                return Ok(v["result"].clone());
            }
        }
    }

    /// The page's uncaught exceptions so far.
    pub fn exceptions(&mut self) -> Vec<String> {
        // Events arrive with the next answer.
        let _ = self.eval("0");
        self.exceptions.clone()
    }

    /// Sets the viewport (CSS pixels, device scale 1).
    pub fn viewport(&mut self, width: u32, height: u32) -> io::Result<()> {
        self.call(
            "Emulation.setDeviceMetricsOverride",
            json!({"width": width, "height": height, "deviceScaleFactor": 1, "mobile": false}),
        )
        .map(|_| ())
    }

    /// A script to run in every new document before the page's own.
    pub fn before_page(&mut self, source: &str) -> io::Result<()> {
        self.call(
            "Page.addScriptToEvaluateOnNewDocument",
            json!({"source": source}),
        )
        .map(|_| ())
    }

    /// Opens `url` and waits for it to load.
    pub fn goto(&mut self, url: &str) -> io::Result<()> {
        self.call("Page.navigate", json!({"url": url}))?;
        let deadline = Instant::now() + Duration::from_secs(30);
        while Instant::now() < deadline {
            if self.eval("document.readyState")? == json!("complete") {
                return Ok(());
            }
            thread::sleep(Duration::from_millis(20));
        }
        Err(io::Error::other(format!("{url} did not load")))
    }

    /// Evaluates `expression` in the page (promises awaited) and returns
    /// its value.
    pub fn eval(&mut self, expression: &str) -> io::Result<Value> {
        let r = self.call(
            "Runtime.evaluate",
            json!({"expression": expression, "returnByValue": true, "awaitPromise": true}),
        )?;
        if let Some(e) = r.get("exceptionDetails") {
            return Err(io::Error::other(format!("{expression}: {e}")));
        }
        Ok(r["result"]["value"].clone())
    }

    /// Evaluates until the value is `true`, or `timeout`.
    pub fn wait_for(&mut self, expression: &str, timeout: Duration) -> io::Result<bool> {
        let deadline = Instant::now() + timeout;
        loop {
            if self.eval(expression)? == json!(true) {
                return Ok(true);
            }
            if Instant::now() > deadline {
                return Ok(false);
            }
            thread::sleep(Duration::from_millis(20));
        }
    }

    /// The centre of the first element matching `selector`, if shown.
    pub fn centre(&mut self, selector: &str) -> io::Result<(f64, f64)> {
        let v = self.eval(&format!(
            "(() => {{ const e = document.querySelector({s}); if (!e) return null; \
             const r = e.getBoundingClientRect(); if (!r.width) return null; \
             return [r.left + r.width / 2, r.top + r.height / 2]; }})()",
            s = serde_json::to_string(selector).unwrap_or_default()
        ))?;
        match (v[0].as_f64(), v[1].as_f64()) {
            (Some(x), Some(y)) => Ok((x, y)),
            _ => Err(io::Error::other(format!("{selector} is not shown"))),
        }
    }

    fn mouse(&mut self, kind: &str, x: f64, y: f64) -> io::Result<()> {
        self.call(
            "Input.dispatchMouseEvent",
            json!({"type": kind, "x": x, "y": y, "button": "left", "buttons": if kind == "mousePressed" { 1 } else { 0 }, "clickCount": 1, "pointerType": "mouse"}),
        )
        .map(|_| ())
    }

    /// A finger (the mouse) goes down on `selector`.
    pub fn press(&mut self, selector: &str) -> io::Result<(f64, f64)> {
        let (x, y) = self.centre(selector)?;
        self.mouse("mouseMoved", x, y)?;
        self.mouse("mousePressed", x, y)?;
        Ok((x, y))
    }

    /// The finger comes up at `(x, y)`.
    pub fn release_at(&mut self, x: f64, y: f64) -> io::Result<()> {
        self.mouse("mouseMoved", x, y)?;
        self.mouse("mouseReleased", x, y)
    }

    /// Press and release on `selector`.
    pub fn tap(&mut self, selector: &str) -> io::Result<()> {
        let (x, y) = self.press(selector)?;
        thread::sleep(Duration::from_millis(40));
        self.release_at(x, y)
    }

    /// Types `text` where the focus is.
    pub fn type_text(&mut self, text: &str) -> io::Result<()> {
        self.call("Input.insertText", json!({"text": text}))
            .map(|_| ())
    }

    /// A PNG of the viewport.
    pub fn screenshot(&mut self) -> io::Result<Vec<u8>> {
        let r = self.call(
            "Page.captureScreenshot",
            json!({"format": "png", "captureBeyondViewport": false}),
        )?;
        let data = r["data"].as_str().unwrap_or("");
        data_encoding::BASE64
            .decode(data.as_bytes())
            .map_err(io::Error::other)
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.ws.close(None);
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.profile);
    }
}
