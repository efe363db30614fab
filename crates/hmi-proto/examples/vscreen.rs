//! Runs the virtual screen against a byte stream: a TCP socket (QEMU's
//! `-chardev socket,…,server=on` USART) or a serial device already set up with
//! `stty -F /dev/ttyUSB0 115200 raw`.
//!
//! ```text
//! cargo run -p hmi-proto --features std --example vscreen -- tcp 127.0.0.1:4444
//! cargo run -p hmi-proto --features std --example vscreen -- tty /dev/ttyUSB0
//! ```
//!
//! Type operator actions on stdin: `tap NAME`, `set NAME VALUE`, `page`, `boot`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use std::io::{BufRead, Read, Write};
use std::sync::mpsc;
use std::time::Duration;

use hmi_proto::virtual_screen::VirtualScreen;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (kind, addr) = match (args.get(1), args.get(2)) {
        (Some(k), Some(a)) => (k.clone(), a.clone()),
        _ => {
            eprintln!("usage: vscreen tcp HOST:PORT | vscreen tty /dev/ttyX");
            std::process::exit(2);
        }
    };
    let (mut rx, mut tx): (Box<dyn Read + Send>, Box<dyn Write>) = if kind == "tcp" {
        let s = std::net::TcpStream::connect(&addr).expect("connect");
        s.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        (Box::new(s.try_clone().unwrap()), Box::new(s))
    } else {
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&addr)
            .expect("open");
        (Box::new(f.try_clone().unwrap()), Box::new(f))
    };
    let (bytes_tx, bytes_rx) = mpsc::channel::<Vec<u8>>();
    std::thread::spawn(move || {
        let mut buf = [0u8; 256];
        loop {
            match rx.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => bytes_tx.send(buf[..n].to_vec()).unwrap(),
                Err(e)
                    if e.kind() == std::io::ErrorKind::WouldBlock
                        || e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(_) => break,
            }
        }
    });
    let (line_tx, line_rx) = mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines() {
            line_tx.send(line.unwrap()).unwrap();
        }
    });

    let mut screen = VirtualScreen::with_contract();
    screen.boot();
    let mut logged = 0;
    loop {
        while let Ok(b) = bytes_rx.try_recv() {
            screen.feed(&b);
        }
        for ins in &screen.instructions()[logged..] {
            println!("MCU> {ins}");
        }
        logged = screen.instructions().len();
        while let Ok(line) = line_rx.try_recv() {
            let w: Vec<&str> = line.split_whitespace().collect();
            let r = match w.as_slice() {
                ["tap", n] => screen.tap(n),
                ["set", n, v] => screen.set_value(n, v.parse().unwrap_or(0)),
                ["page"] => {
                    println!("page {}", screen.page());
                    Ok(())
                }
                ["boot"] => {
                    screen.boot();
                    Ok(())
                }
                _ => {
                    println!("? tap NAME | set NAME VALUE | page | boot");
                    Ok(())
                }
            };
            if let Err(e) = r {
                println!("error: {e}");
            }
        }
        let out = screen.take_output();
        if !out.is_empty() {
            tx.write_all(&out).expect("write");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}
