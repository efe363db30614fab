//! The stop input (PB10), the work switch (PB11) and the status LED (PC13).

use super::*;

/// The stop input on PB10: a normally closed contact to ground with the
/// internal pull-up (datasheet: PB10 is a 5 V tolerant "FT" pin). An open
/// contact, a cut wire or an unplugged connector read high: stop.
pub struct StopInput {
    pub(super) pin: PB10<Input<PullUp>>,
}

impl StopInput {
    /// The contact is open (the pin reads high): stop.
    pub fn is_open(&self) -> bool {
        self.pin.is_high()
    }

    /// Acknowledges the pin's EXTI interrupt.
    pub fn clear_interrupt(&mut self) {
        self.pin.clear_interrupt_pending_bit();
    }
}

/// The work switch on PB11: a contact to ground that closes while the
/// planting unit is down, with the internal pull-up (PB11 is a 5 V
/// tolerant "FT" pin). An open contact, a cut wire or an unplugged
/// connector read high: up, not planting (the safe side).
pub struct WorkSwitchInput {
    pub(super) pin: PB11<Input<PullUp>>,
}

impl WorkSwitchInput {
    /// The contact is closed (the pin reads low): the unit is down.
    pub fn is_closed(&self) -> bool {
        self.pin.is_low()
    }
}

/// The status LED on PC13 (active low).
pub struct StatusLed(pub(super) PC13<Output<PushPull>>);

impl StatusLed {
    /// Lights or darkens the LED.
    pub fn set(&mut self, on: bool) {
        if on {
            self.0.set_low();
        } else {
            self.0.set_high();
        }
    }
}
