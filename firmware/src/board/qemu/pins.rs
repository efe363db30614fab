//! The stop input, the work switch and the status LED stand-ins (GPIO is
//! not emulated: the scenario moves the inputs).

use core::sync::atomic::{AtomicBool, Ordering::Relaxed};

/// Stand-in for the stop input pin PB10 (high = contact open = stop).
pub(super) static STOP_INPUT_OPEN: AtomicBool = AtomicBool::new(false);

/// Stand-in for the work switch pin PB11 (low = contact closed = unit
/// down); the scenario moves it.
pub(super) static WORK_SWITCH_CLOSED: AtomicBool = AtomicBool::new(false);

/// Status LED stand-in (GPIO is not emulated).
pub struct StatusLed;

impl StatusLed {
    /// Does nothing: QEMU has no LED.
    pub fn set(&mut self, _on: bool) {}
}

/// The stop input stand-in: PB10's level comes from the scenario.
pub struct StopInput;

impl StopInput {
    /// The contact is open: stop.
    pub fn is_open(&self) -> bool {
        STOP_INPUT_OPEN.load(Relaxed)
    }

    /// Nothing to acknowledge (the interrupt was pended by software).
    pub fn clear_interrupt(&mut self) {}
}

/// The work switch stand-in: PB11's level comes from the scenario.
pub struct WorkSwitchInput;

impl WorkSwitchInput {
    /// The contact is closed: the unit is down.
    pub fn is_closed(&self) -> bool {
        WORK_SWITCH_CLOSED.load(Relaxed)
    }
}
