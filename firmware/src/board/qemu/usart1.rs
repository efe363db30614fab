//! USART1, the touchscreen's line, on QEMU's `netduino2` machine.
//!
//! The machine is QEMU's STM32F205 model. Its USARTs are the same QEMU model
//! as the STM32F100's (`stm32f2xx_usart`: the F1's register layout, SR, DR,
//! BRR, CR1–CR3), USART2 and USART3 sit at the F1's addresses and every
//! USART keeps the F1's interrupt number (USART1 = 37); only USART1 moves,
//! to 0x4001_1000 (RM0033's memory map), and at the F1's 0x4001_3800 lies
//! the F205's SYSCFG. The HAL's `Serial<USART1>` is built for the F1's
//! address, so USART1 is driven here, through the PAC's typed USART
//! registers at the F205's address, with the methods of the HAL's
//! `serial::Tx` and `serial::Rx` that the application calls.

use stm32f1xx_hal::{pac, serial};

/// USART1's register block on the STM32F205 (RM0033 §2.3, memory map;
/// QEMU's `hw/arm/stm32f205_soc.c`).
const USART1_BASE: usize = 0x4001_1000;

/// BRR for 115 200 Bd from the 8 MHz HSI (what the HAL would write: QEMU's
/// model keeps the value and ignores it).
const BRR_115200_FROM_HSI: u16 = (8_000_000 / 115_200) as u16;

fn regs() -> &'static pac::usart1::RegisterBlock {
    // SAFETY: on this machine USART1_BASE holds a USART with the register
    // layout of the PAC's `usart1::RegisterBlock`, mapped for the whole run;
    // the PAC's cells access it volatile. Only this module touches it, and
    // [`Tx`] and [`Rx`] use disjoint bits of it like the HAL's halves do.
    unsafe { &*(USART1_BASE as *const pac::usart1::RegisterBlock) }
}

/// Transmit half (the methods of the HAL's `serial::Tx`).
pub struct Tx {
    _private: (),
}

/// Receive half (the methods of the HAL's `serial::Rx`).
pub struct Rx {
    _private: (),
}

/// Enables USART1 for 115 200 Bd 8N1, transmit and receive, and splits it.
///
/// Takes the PAC's `USART1`: on this machine its address is the SYSCFG's,
/// so nothing else may drive it.
pub fn split(_f1_usart1: pac::USART1) -> (Tx, Rx) {
    let usart = regs();
    usart.brr().write(|w| {
        w.div_mantissa()
            .set(BRR_115200_FROM_HSI >> 4)
            .div_fraction()
            .set((BRR_115200_FROM_HSI & 0xF) as u8)
    });
    usart
        .cr1()
        .write(|w| w.ue().set_bit().te().set_bit().re().set_bit());
    (Tx { _private: () }, Rx { _private: () })
}

// The HAL's methods, whether or not the application calls each today.
#[allow(dead_code)]
impl Tx {
    /// Writes a byte if the data register is empty.
    pub fn write_u8(&mut self, word: u8) -> nb::Result<(), serial::Error> {
        let usart = regs();
        if usart.sr().read().txe().bit_is_set() {
            usart.dr().write(|w| w.dr().set(u16::from(word)));
            Ok(())
        } else {
            Err(nb::Error::WouldBlock)
        }
    }

    /// Whether the last byte has left (TC).
    pub fn flush(&mut self) -> nb::Result<(), serial::Error> {
        if self.is_tx_complete() {
            Ok(())
        } else {
            Err(nb::Error::WouldBlock)
        }
    }

    /// Enables the transmit-register-empty interrupt (TXEIE).
    pub fn listen(&mut self) {
        regs().cr1().modify(|_, w| w.txeie().set_bit());
    }

    /// Disables the transmit-register-empty interrupt.
    pub fn unlisten(&mut self) {
        regs().cr1().modify(|_, w| w.txeie().clear_bit());
    }

    /// The data register can take a byte (TXE).
    pub fn is_tx_empty(&self) -> bool {
        regs().sr().read().txe().bit_is_set()
    }

    /// The last byte has left (TC).
    pub fn is_tx_complete(&self) -> bool {
        regs().sr().read().tc().bit_is_set()
    }
}

#[allow(dead_code)]
impl Rx {
    /// The received byte, or the error the status register shows (read
    /// with DR, which clears it, as the HAL does).
    pub fn read(&mut self) -> nb::Result<u8, serial::Error> {
        let usart = regs();
        let sr = usart.sr().read();
        let error = if sr.pe().bit_is_set() {
            Some(serial::Error::Parity)
        } else if sr.fe().bit_is_set() {
            Some(serial::Error::FrameFormat)
        } else if sr.ne().bit_is_set() {
            Some(serial::Error::Noise)
        } else if sr.ore().bit_is_set() {
            Some(serial::Error::Overrun)
        } else {
            None
        };
        if let Some(error) = error {
            let _ = usart.dr().read();
            return Err(nb::Error::Other(error));
        }
        if sr.rxne().bit_is_set() {
            Ok(usart.dr().read().dr().bits() as u8)
        } else {
            Err(nb::Error::WouldBlock)
        }
    }

    /// Enables the receive-register-not-empty interrupt (RXNEIE).
    pub fn listen(&mut self) {
        regs().cr1().modify(|_, w| w.rxneie().set_bit());
    }

    /// Disables the receive-register-not-empty interrupt.
    pub fn unlisten(&mut self) {
        regs().cr1().modify(|_, w| w.rxneie().clear_bit());
    }

    /// A byte is waiting (RXNE).
    pub fn is_rx_not_empty(&self) -> bool {
        regs().sr().read().rxne().bit_is_set()
    }
}
