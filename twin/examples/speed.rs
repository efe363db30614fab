//! The twin's speed, for `cargo xtask bench`: the profile A image with the
//! machine at Low 2 and the drum running in Fixed mode for 10 s of firmware
//! time. Prints `twin-speed firmware_s=F host_s=H`.
//!
//! `cargo run -p twin --release --example speed -- ELF`

use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let elf = PathBuf::from(std::env::args().nth(1).ok_or("usage: speed ELF")?);
    let mut twin = twin::Twin::new(&elf, twin::Options::default())?;
    let mut config = machine_sim::Config::noiseless();
    config.initial_gear = kinematics_gear();
    twin.attach_plant(config.build()?, twin::plant::Wiring::ProfileA);
    twin.connect_screen();
    let started = std::time::Instant::now();
    let t0 = twin.now_s();
    twin.run_until_screen(3000, |s| s.page() == 1)?;
    twin.tap("bfixed")?;
    twin.tap("bstart")?;
    twin.run_ms(10_000)?;
    let fw = twin.now_s() - t0;
    let host = started.elapsed().as_secs_f64();
    println!(
        "twin-speed firmware_s={fw:.3} host_s={host:.3} instructions={}",
        twin.state().instructions
    );
    Ok(())
}

fn kinematics_gear() -> Option<kinematics::consts::Gear> {
    kinematics::consts::Gear::ALL.get(1).copied()
}
