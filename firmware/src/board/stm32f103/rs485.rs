//! USART2, the RS-485 line to the drum driver, with its driver-enable (PA1).

use super::*;

/// Longest Modbus RTU frame this link sends or takes (its replies are at
/// most 9 bytes; anything longer is garbage and fails its CRC).
pub(super) const DRIVE_FRAME_MAX: usize = 16;

/// USART2, the RS-485 line to the drum driver, interrupt-driven
/// (docs/drive-link.md, "Board layer"):
///
/// - [`DriveLine::send`] drives DE (PA1) high *before* the first byte is
///   written, then enables TXEIE; the interrupt writes each next byte on
///   TXE, and after the last one switches from TXEIE to TCIE;
/// - on TC (the last stop bit has left the shift register: RM0008 §27.3.2,
///   "TC … set when the transmission of a frame containing data is
///   complete"), not TXE (which only says the data register is free while
///   the last byte is still shifting out), DE goes low and the time is
///   noted for [`DriveLine::sent`];
/// - each received byte is stored with its time; a frame ends after 3.5
///   characters of silence ([`DriveLine::receive`], polled by the link task
///   every 1 ms: the F103's idle-line flag is one character, too short for
///   RTU). Bytes while DE is high (an echo) are dropped.
pub struct DriveLine {
    pub(super) _tx: Tx<USART2>,
    pub(super) usart_rx: Rx<USART2>,
    pub(super) de: PA1<Output<PushPull>>,
    pub(super) out: [u8; DRIVE_FRAME_MAX],
    pub(super) out_len: u8,
    pub(super) out_pos: u8,
    pub(super) sent_at: Option<u64>,
    pub(super) sending: bool,
    pub(super) rx: [u8; DRIVE_FRAME_MAX],
    pub(super) rx_len: u8,
    pub(super) rx_last_us: u64,
    pub(super) silent_us: u32,
}

/// USART2's clock: PCLK1 = 36 MHz.
pub(super) const PCLK1_HZ: u32 = 36_000_000;

impl DriveLine {
    pub(super) fn regs() -> &'static pac::usart1::RegisterBlock {
        // SAFETY: USART2's registers; only this type touches them after
        // `init` (it owns USART2's Tx and Rx).
        unsafe { &*USART2::ptr() }
    }

    /// Sets the line's speed: BRR = PCLK1 / baud, rounded (RM0008
    /// §27.3.4: 36 MHz / 9600 = 3750.0; / 115 200 = 312.5 → 313, +0.16 %).
    /// Called while the line is idle, by the link task when it starts:
    /// the receive interrupt is on from then.
    pub fn set_baud(&mut self, baud: u32) {
        let brr = PCLK1_HZ.saturating_add(baud / 2) / baud.max(1);
        self.silent_us = drive_link::timing::silent_interval_us(baud).unwrap_or(4_011);
        // BRR (§27.6.3): DIV_Mantissa in bits 15:4, DIV_Fraction in 3:0.
        let brr = u16::try_from(brr).unwrap_or(u16::MAX);
        Self::regs().brr().write(|w| {
            w.div_mantissa()
                .set(brr >> 4)
                .div_fraction()
                .set((brr & 0xF) as u8)
        });
        self.usart_rx.listen();
    }

    /// Sends a request frame: DE high, then the bytes from the interrupt.
    pub fn send(&mut self, frame: &[u8], _now_us: u64) {
        let n = frame.len().min(DRIVE_FRAME_MAX);
        if let (Some(dst), Some(src)) = (self.out.get_mut(..n), frame.get(..n)) {
            dst.copy_from_slice(src);
        }
        self.out_len = n as u8;
        self.out_pos = 0;
        self.sending = true;
        self.rx_len = 0;
        // DE high before the first bit: the byte is written only by the
        // TXE interrupt this enables.
        self.de.set_high();
        // CR1 (§27.6.4) TXEIE set (read-modify-write from priority 3, the
        // only task that touches CR1 after `init`).
        Self::regs().cr1().modify(|_, w| w.txeie().set_bit());
    }

    /// The request's last stop bit has left (TC; DE is low): its time, once.
    pub fn sent(&mut self, _now_us: u64) -> Option<u64> {
        self.sent_at.take()
    }

    /// A received frame, once 3.5 characters of silence have followed its
    /// last byte.
    pub fn receive(&mut self, now_us: u64, buf: &mut [u8]) -> Option<usize> {
        if self.rx_len == 0 || now_us.saturating_sub(self.rx_last_us) < u64::from(self.silent_us) {
            return None;
        }
        let n = usize::from(self.rx_len).min(buf.len());
        buf.get_mut(..n)?.copy_from_slice(self.rx.get(..n)?);
        self.rx_len = 0;
        Some(n)
    }

    /// Whether bytes have arrived that no frame has been handed over with
    /// yet (a frame on the line, not yet ended by its silence).
    pub fn receiving(&mut self, _now_us: u64) -> bool {
        self.rx_len > 0
    }

    /// USART2's interrupt.
    pub fn on_interrupt(&mut self, now_us: u64) {
        let r = Self::regs();
        // SR (§27.6.1) and CR1 (§27.6.4).
        let sr = r.sr().read();
        let cr1 = r.cr1().read();
        if sr.rxne().bit_is_set() {
            // Reading DR after SR clears RXNE and the error flags.
            let byte = r.dr().read().dr().bits() as u8;
            if !self.sending {
                if let Some(slot) = self.rx.get_mut(usize::from(self.rx_len)) {
                    *slot = byte;
                    self.rx_len += 1;
                }
                self.rx_last_us = now_us;
            }
        }
        if cr1.txeie().bit_is_set() && sr.txe().bit_is_set() {
            match self.out.get(usize::from(self.out_pos)) {
                Some(&b) if self.out_pos < self.out_len => {
                    // A byte into DR (clears TC after the SR read).
                    r.dr().write(|w| w.dr().set(u16::from(b)));
                    self.out_pos += 1;
                }
                _ => {
                    // All bytes are in: wait for TC, not TXE.
                    r.cr1()
                        .modify(|_, w| w.txeie().clear_bit().tcie().set_bit());
                }
            }
        } else if cr1.tcie().bit_is_set() && sr.tc().bit_is_set() {
            self.de.set_low();
            r.cr1().modify(|_, w| w.tcie().clear_bit());
            self.sending = false;
            self.sent_at = Some(now_us);
        }
    }
}
