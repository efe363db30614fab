//! The outputs' safe states: the stop input's response, the safe state of a fault, the drivers' enable as set.

use super::*;

/// The stop input's response, from its interrupt: drum PWM compare 0 now
/// (the preloaded CCR1 = 0 is loaded at once by an update event, UG), the
/// drivers' enable PB12 low; profile B's feed step timer (TIM4) likewise.
/// On machine A TIM4 counts the ground wheel and is left alone: an update
/// event would reset the wheel's count.
/// Unlike [`safe_state`], the outputs stay armed: the control task drives
/// them again once the operator restarts.
pub fn stop_outputs() {
    // SAFETY: single writes to TIM1/TIM4 CCR1 and EGR and to GPIOB's BSRR,
    // which are write-only in effect (no read-modify-write), from the
    // highest-priority interrupt; the control task re-writes CCR1 and PB12
    // only when the stop latch allows it (under the same lock).
    unsafe {
        let gpiob = &*pac::GPIOB::ptr();
        gpiob.bsrr().write(|w| w.br12().set_bit());
        let tim1 = &*TIM1::ptr();
        tim1.ccr1().write(|w| w.ccr().set(0));
        tim1.egr().write(|w| w.ug().set_bit());
        if !tim4_counts_the_wheel() {
            let tim4 = &*pac::TIM4::ptr();
            tim4.ccr1().write(|w| w.ccr().set(0));
            tim4.egr().write(|w| w.ug().set_bit());
        }
    }
}

/// Drives the outputs to their safe state at once, with direct register writes
/// and no stack of its own to speak of, from any context (boot before the
/// clocks, panic, HardFault after a stack overflow, NMI, an unexpected
/// interrupt):
///
/// 1. PA8 (drum PWM / profile B planting STEP), PB12 (drivers' enable),
///    profile B's PB6 (feeding STEP) and PA1 (the RS-485 transceiver's
///    driver-enable: low receives and releases the motor driver's bus;
///    it floated from reset until `init` when the clock never came up)
///    become general-purpose push-pull
///    outputs driven low: ODR bits cleared through BRR (RM0008 §9.2.6), then
///    the pins' CRH/CRL nibbles = 0010 (§9.2.1, §9.2.2), the port clocks
///    switched on first (§7.3.7). This holds whatever state the timers are
///    in (unconfigured, clock off, stopped by a debug halt).
/// 2. The timers agree: TIM1 CH1 (and TIM4 CH1 on profile B) forced
///    inactive, OC1M = 100 (§14.4.7, §15.4.7: takes effect immediately,
///    unlike CCR1, which is preloaded and would wait for the next update —
///    up to a whole step period on TIM4); CCR1 = 0; TIM1's MOE cleared with
///    OSSI = OSSR = 1 so that its output stays driven at OIS1 = low
///    (§14.4.18, Table 83) rather than released (Hi-Z) as with OSSI = 0.
///    Writes to a timer whose clock is off are ignored, harmlessly.
///
/// Either step alone holds the pins low; the GPIO one does not depend on
/// any timer setting and the timer one keeps the pins low if a pin is ever
/// handed back to its timer.
///
/// Once machine A has made TIM4 the ground wheel's counter (encoder mode,
/// read from TIM4_SMCR), PB6 is the wheel's input and TIM4 has no output:
/// both are left alone, so that the MCU does not drive the wheel sensor's
/// line low against it. (From reset until `init` has read the settings,
/// a few milliseconds, PB6 is driven low on either machine: the sensor's
/// output must stand that, as an open-collector one does; a push-pull one
/// wants a series resistor, README pin map.)
#[inline(always)]
pub fn safe_state() {
    // SAFETY: single writes (and read-modify-writes of registers no
    // interrupt handler touches) of documented values; every caller either
    // never returns to the application or runs before it exists (boot).
    unsafe {
        let rcc = &*pac::RCC::ptr();
        // RCC_APB2ENR (§7.3.7): IOPAEN, IOPBEN.
        rcc.apb2enr()
            .modify(|_, w| w.iopaen().set_bit().iopben().set_bit());
        let gpioa = &*pac::GPIOA::ptr();
        let gpiob = &*pac::GPIOB::ptr();
        gpioa.brr().write(|w| w.br8().set_bit().br1().set_bit());
        let wheel = tim4_counts_the_wheel();
        gpiob.brr().write(|w| {
            w.br12().set_bit();
            if !wheel {
                w.br6().set_bit();
            }
            w
        });
        // CRL/CRH nibbles: CNF = 00 (general-purpose push-pull), MODE = 10
        // (output, 2 MHz).
        gpioa
            .crh()
            .modify(|_, w| w.mode8().output2().cnf8().push_pull());
        gpioa
            .crl()
            .modify(|_, w| w.mode1().output2().cnf1().push_pull());
        gpiob
            .crh()
            .modify(|_, w| w.mode12().output2().cnf12().push_pull());
        if !wheel {
            gpiob
                .crl()
                .modify(|_, w| w.mode6().output2().cnf6().push_pull());
        }
        // CCMR1: OC1M = 100 (forced inactive), OC1PE = 1; BDTR: OSSR =
        // OSSI = 1, MOE = 0 (the whole register written: no break, no lock).
        let tim1 = &*TIM1::ptr();
        tim1.ccmr1_output()
            .write(|w| w.oc1m().force_inactive().oc1pe().enabled());
        tim1.ccr1().write(|w| w.ccr().set(0));
        tim1.bdtr().write(|w| w.ossr().set_bit().ossi().set_bit());
        if !wheel {
            let tim4 = &*pac::TIM4::ptr();
            tim4.ccmr1_output()
                .write(|w| w.oc1m().force_inactive().oc1pe().enabled());
            tim4.ccr1().write(|w| w.ccr().set(0));
        }
    }
}

/// Whether the motor drivers' enable (PB12) is high, read back from its
/// output data register (RM0008 §9.2.4): the settings task erases flash only
/// while it is low.
pub fn drivers_enabled() -> bool {
    // SAFETY: a read of GPIOB_ODR, no side effect.
    unsafe { (*pac::GPIOB::ptr()).odr().read().odr12().bit_is_set() }
}
