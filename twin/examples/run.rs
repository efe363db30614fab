//! Runs an image on the twin: `cargo run -p twin --release --example run -- ELF MS`.
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let elf = PathBuf::from(args.next().ok_or("usage: run ELF MS")?);
    let ms: u64 = args.next().map_or(Ok(1000), |s| s.parse())?;
    let mut twin = twin::Twin::new(
        &elf,
        twin::Options {
            echo_logs: true,
            ..twin::Options::default()
        },
    )?;
    twin.connect_screen();
    twin.run_ms(ms)?;
    let logs = twin.logs();
    let zeros = twin.rtt_bytes.iter().filter(|&&b| b == 0).count();
    println!(
        "zeros in RTT stream {zeros}, lines {}; head {:02x?}",
        logs.len(),
        &twin.rtt_bytes[..twin.rtt_bytes.len().min(24)]
    );
    println!(
        "{} lines; firmware {:.3} s in {:.3} s host; core {:?}; pc {:#x}; resets {:?}; instr {}",
        logs.len(),
        twin.now_s(),
        twin.host_time.as_secs_f64(),
        twin.core,
        twin.reg(unicorn_engine::RegisterARM::PC),
        twin.resets,
        twin.state().instructions
    );
    println!("PA8 {:?} PB12 {:?}", twin.pin('A', 8), twin.pin('B', 12));
    Ok(())
}
