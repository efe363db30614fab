//! USART1's transmitter, the touchscreen's line out, driven by its
//! interrupt (both boards: the same USART registers, RM0008 §27.6).
//!
//! The hmi task puts bytes into a ring and pends USART1 ([`kick`]); the
//! USART1 interrupt writes them while the data register is empty (TXE,
//! RM0008 §27.6.1: set when the byte has moved into the shift register) and
//! keeps TXEIE on while bytes remain, so each TXE brings the next. The task
//! never waits on the line, and its receive queue is drained while the
//! screen's instructions go out. QEMU's USART model sends each byte at once
//! (TXE is always set): there the first interrupt sends the whole ring.

use heapless::spsc::Consumer;
use stm32f1xx_hal::pac;

use super::ScreenUsartTx;

/// The touchscreen's transmitter (on each board its USART1 transmit half,
/// [`ScreenUsartTx`], with the HAL's `write_u8`, `is_tx_empty`, `listen`
/// and `unlisten`).
pub struct HmiTx {
    tx: ScreenUsartTx,
}

impl HmiTx {
    pub(super) fn new(tx: ScreenUsartTx) -> Self {
        Self { tx }
    }

    /// From the USART1 interrupt: writes `ring`'s bytes while the data
    /// register takes them; TXEIE stays on while bytes remain. Only this
    /// interrupt writes USART1's CR1 after `init`.
    pub fn send(&mut self, ring: &mut Consumer<'static, u8>) {
        while self.tx.is_tx_empty() {
            let Some(b) = ring.dequeue() else { break };
            let _ = self.tx.write_u8(b);
        }
        if ring.ready() {
            self.tx.listen();
        } else {
            self.tx.unlisten();
        }
    }
}

/// Runs the USART1 interrupt, to start sending what the task queued.
pub fn kick() {
    cortex_m::peripheral::NVIC::pend(pac::Interrupt::USART1);
}
