//! The pulse input, TIM2 CH1 input capture on PA0: profile A's Hall teeth, profile B's feeding-roller index.

use super::*;

/// Frequency of the Hall capture timer: one tick is 1 µs.
pub(super) const HALL_TIMER_HZ: u32 = 1_000_000;

/// TIM2 CH1 input capture of Hall edges at 1 MHz, extended to 32 bits with
/// the timer's update (overflow) events.
pub struct HallCapture {
    pub(super) tim2: TIM2,
    pub(super) extender: CaptureExtender,
}

impl HallCapture {
    pub(super) fn new(tim2: TIM2) -> Self {
        let psc = (TIMER_CLOCK_HZ / HALL_TIMER_HZ - 1) as u16;
        // PSC = 71 (1 MHz) and ARR = 0xFFFF, non-zero before UG and CEN
        // (RM0008 §15.4.11, §15.4.12).
        tim2.psc().write(|w| w.psc().set(psc));
        tim2.arr().write(|w| w.arr().set(u16::MAX));
        // RM0008 §15.4: CCMR1 (§15.4.7) CC1S =
        // 01 (IC1 on TI1), IC1F = 1111 (fDTS/32 with fDTS = fCK_INT = 72 MHz,
        // N = 8: a level must hold 8 × 0.44 µs = 3.6 µs); CCER (§15.4.9) CC1E,
        // CC1P (falling edge); DIER (§15.4.4) CC1IE and UIE.
        tim2.ccmr1_input()
            .write(|w| w.cc1s().ti1().ic1f().fdts_div32_n8());
        tim2.ccer().write(|w| w.cc1e().set_bit().cc1p().set_bit());
        tim2.egr().write(|w| w.ug().set_bit());
        // SR (§15.4.5) is rc_w0: zeros clear every flag (the register
        // written is 0, as from reset).
        tim2.sr().write(|w| {
            w.uif()
                .clear()
                .cc1if()
                .clear()
                .cc2if()
                .clear()
                .cc3if()
                .clear()
                .cc4if()
                .clear()
                .tif()
                .clear()
                .cc1of()
                .clear()
                .cc2of()
                .clear()
                .cc3of()
                .clear()
                .cc4of()
                .clear()
        });
        tim2.dier().write(|w| w.cc1ie().set_bit().uie().set_bit());
        tim2.cr1().write(|w| w.cen().set_bit());
        Self {
            tim2,
            extender: CaptureExtender::new(),
        }
    }

    /// Handles the TIM2 interrupt: returns the edge captured, if any, as a
    /// 32-bit timestamp in 1 µs ticks, and whether edges were lost before it.
    ///
    /// Reads, in this order (RM0008 §15.4.5 TIMx_SR, §15.4.13 TIMx_CCR1):
    /// SR; CCR1 if CC1IF (the read clears CC1IF, so the flag is never
    /// written: a capture landing between the read and a write would be
    /// lost); SR again (UIF and CC1OF as they stand after the capture
    /// read); CNT. The capture is extended with UIF and the counter read
    /// after it (`CaptureExtender::extend_at`: exact up to a whole wrap,
    /// 65.5 ms, of interrupt delay — a 40 ms flash erase stall included);
    /// then UIF and CC1OF are cleared (rc_w0: only the bits seen are written
    /// 0, the others 1) and the overflow is accounted.
    ///
    /// CC1OF set means a capture came while the previous one was unread: at
    /// least one Hall edge was lost, and CCR1 holds the newest capture, so
    /// the edge read here follows the loss (`after_lost`) and the estimator
    /// must not measure the interval ending at it. If CC1IF is set again at
    /// the second SR read, the loss may instead lie after the edge just read
    /// (two captures since): CC1OF is then left set, so that the next edge
    /// (its interrupt is already pending) is marked too — one window too
    /// many discarded rather than one measured wrong.
    pub fn on_interrupt(&mut self) -> Option<crate::board::HallEdge> {
        let captured = self.tim2.sr().read().cc1if().bit_is_set();
        let ccr = captured.then(|| self.tim2.ccr1().read().ccr().bits());
        let sr = self.tim2.sr().read();
        let counter = self.tim2.cnt().read().cnt().bits();
        let overflowed = sr.uif().bit_is_set();
        let lost = sr.cc1of().bit_is_set();
        let clear_lost = lost && sr.cc1if().bit_is_clear();
        if overflowed || clear_lost {
            // rc_w0 flags: the writer starts with every flag written 1
            // (left untouched, CC1IF included); only the flags seen are
            // written 0, which clears exactly them. (The reserved bits are
            // written 0, as RM0008 asks.)
            self.tim2.sr().write(|w| {
                if overflowed {
                    w.uif().clear();
                }
                if clear_lost {
                    w.cc1of().clear();
                }
                w
            });
        }
        let edge = ccr.map(|ccr| crate::board::HallEdge {
            stamp: self.extender.extend_at(ccr, overflowed, counter).0,
            after_lost: lost,
        });
        if overflowed {
            self.extender.on_overflow();
        }
        edge
    }

    /// The capture timer's time, 1 MHz, extended to 32 bits: the counter
    /// read between two reads of UIF (`CaptureExtender::now_between`).
    pub fn now(&self) -> u32 {
        let before = self.tim2.sr().read().uif().bit_is_set();
        let counter = self.tim2.cnt().read().cnt().bits();
        let after = self.tim2.sr().read().uif().bit_is_set();
        self.extender.now_between(before, counter, after).0
    }
}
