//! The independent watchdog (IWDG).

use super::*;

/// IWDG reload: 313 counts of LSI / 32, i.e. 10 016 LSI cycles.
pub(super) const IWDG_RELOAD: u16 = 312;
/// Bound on the wait for the prescaler and reload to reach the LSI domain
/// (PVU, RVU: "up to 5 RC 40 kHz oscillator cycles", RM0008 §19.4.4: 167 µs
/// at the LSI's slowest 30 kHz); each poll is a few cycles of the 8 MHz HSI.
pub(super) const IWDG_UPDATE_POLLS: u32 = 20_000;

/// The independent watchdog: 313 × 32 = 10 016 LSI cycles, 250 ms at the
/// LSI's nominal 40 kHz, 166.9–333.9 ms over its 30–60 kHz spread
/// (datasheet STM32F103xB, "LSI oscillator characteristics"). Fed only by
/// the control task when it ran on time (every 10 ms). The longest time the
/// CPU cannot feed it is a flash page erase: tERASE ≤ 40 ms (datasheet,
/// "Flash memory characteristics"), far inside the shortest 166.9 ms.
pub struct Watchdog {
    pub(super) iwdg: IWDG,
}

impl Watchdog {
    /// Starts the watchdog first thing at boot (RM0008 §19.3.2), the
    /// sequence of ST's reference driver: 0xCCCC starts it (LSI on; it
    /// counts from 0xFFF at the reset prescaler /4, 273–546 ms) and cannot
    /// be stopped again; 0x5555 unlocks PR and RLR; once PVU and RVU clear,
    /// 0xAAAA reloads the counter with the new timeout.
    pub(super) fn start(iwdg: IWDG) -> Self {
        // The key values and register fields of RM0008 §19.4.1–§19.4.4:
        // KR 0xCCCC (start), 0x5555 (unlock); PR = 011 (LSI / 32); RLR.
        iwdg.kr().write(|w| w.key().start());
        iwdg.kr().write(|w| w.key().unlock());
        iwdg.pr().write(|w| w.pr().divide_by32());
        iwdg.rlr().write(|w| w.rl().set(IWDG_RELOAD));
        // SR (§19.4.4): PVU or RVU set while the update is on its way.
        let updating = || {
            let sr = iwdg.sr().read();
            sr.pvu().bit_is_set() || sr.rvu().bit_is_set()
        };
        let mut polls = 0;
        while updating() {
            polls += 1;
            if polls >= IWDG_UPDATE_POLLS {
                // The LSI does not run: the watchdog cannot either. Said
                // once; the machine still works.
                defmt::error!(
                    "watchdog: prescaler/reload update did not complete (LSI not running?)"
                );
                break;
            }
        }
        iwdg.kr().write(|w| w.key().feed());
        Self { iwdg }
    }

    /// Reloads the watchdog counter.
    pub fn feed(&mut self) {
        // KR 0xAAAA, the reload key (RM0008 §19.4.1 IWDG_KR).
        self.iwdg.kr().write(|w| w.key().feed());
    }
}
