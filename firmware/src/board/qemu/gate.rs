//! The lock-step gate's screen bytes and the touchscreen's receive half.

use stm32f1xx_hal::{pac, serial};

use super::usart1;

/// Most screen bytes one lock-step period carries (a real line carries
/// ≈ 115 per 10 ms; the tests send at most this many).
pub(super) const GATE_BYTES: usize = 32;

/// Screen bytes delivered through the lock-step gate, for [`HmiRx`].
pub(super) type GateQueue = heapless::spsc::Queue<u8, { GATE_BYTES + 1 }>;

/// Receive half of the touchscreen UART. In lock-step the screen's bytes
/// come through the gate at the start of a control period (see
/// [`Sensors::sample`](super::Sensors::sample)) and are read here first, through the same USART1
/// interrupt task; otherwise from the emulated USART1.
pub struct HmiRx {
    pub(super) uart: usart1::Rx,
    pub(super) gate: heapless::spsc::Consumer<'static, u8>,
}

impl HmiRx {
    /// The next received byte.
    pub fn read(&mut self) -> nb::Result<u8, serial::Error> {
        match self.gate.dequeue() {
            Some(byte) => {
                if self.gate.ready() {
                    // More to come: the interrupt task runs again.
                    pac::NVIC::pend(pac::Interrupt::USART1);
                }
                Ok(byte)
            }
            None => self.uart.read(),
        }
    }
}
