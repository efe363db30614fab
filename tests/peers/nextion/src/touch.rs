//! The operator: touches (docs/hmi.md §3: which events send their id;
//! NIS 7.21 the touch event frame; NIS 3.11/3.12 hidden or disabled
//! components take no touch; NIS 6.9 a touch asleep) and the numeric
//! keyboard.

use crate::codes;
use crate::contract::{self, ComponentSpec};
use crate::screen::{Keyboard, KeyboardError, Screen, Touch, TAP_HOLD_US};

impl Screen {
    // ----- the operator -----------------------------------------------------

    pub(crate) fn shown_component(&self, name: &str) -> Option<&'static ComponentSpec> {
        self.page_spec(self.dp).and_then(|p| p.component(name))
    }

    /// Checks common to a press and a release; `Err` is the outcome.
    fn touchable(&mut self, now_us: u64, name: &str) -> Result<&'static ComponentSpec, Touch> {
        self.advance(now_us);
        let t = self.now_us;
        if self.booting_until.is_some() {
            return Err(Touch::Booting);
        }
        if self.sys.sleep {
            if self.sys.thup == 1 {
                // NIS 6.9: the first touch only wakes.
                self.wake(t, true);
                return Err(Touch::Woke);
            }
            return Err(Touch::Asleep);
        }
        let c = self.shown_component(name).ok_or(Touch::NotShown)?;
        let st = self.comps.get(&(c.page, c.id)).ok_or(Touch::NotShown)?;
        if !st.visible {
            return Err(Touch::Hidden);
        }
        if !st.touch {
            return Err(Touch::Disabled);
        }
        self.last_touch_us = t;
        Ok(c)
    }

    /// Send the touch event frame of `c` if its event sends its id.
    pub(crate) fn touch_event(&mut self, at_us: u64, c: &ComponentSpec, press: bool) -> Touch {
        let sends = if press {
            c.sends_press
        } else {
            c.sends_release
        };
        if !sends {
            return Touch::Silent;
        }
        let frame = codes::frame(codes::TOUCH_EVENT, &[c.page, c.id, u8::from(press)]);
        self.tx.send(at_us, &frame);
        Touch::Sent
    }

    /// The operator puts a finger on component `name` of the page shown.
    pub fn press(&mut self, now_us: u64, name: &str) -> Touch {
        match self.touchable(now_us, name) {
            Err(t) => t,
            Ok(c) => {
                self.pressed = Some((c.page, c.id, self.load_count));
                self.touch_event(self.now_us, c, true)
            }
        }
    }

    /// The operator lifts the finger from component `name`. A release
    /// after a page load since the press is no event.
    pub fn release(&mut self, now_us: u64, name: &str) -> Touch {
        let c = match self.touchable(now_us, name) {
            Err(t) => return t,
            Ok(c) => c,
        };
        if let Some((p, id, load)) = self.pressed.take() {
            if (p, id) == (c.page, c.id) && load != self.load_count {
                return Touch::PageChanged;
            }
        }
        let t = self.now_us;
        let sent = self.touch_event(t, c, false);
        if c.keyboard && self.cfg.keyboard == Keyboard::Popup {
            // The editor's keyboard opens on the field's touch.
            self.keyboard_origin = Some((c.page, c.id));
            self.load_page(t, contract::KEYBOARD_PAGE.id);
            return Touch::Keyboard;
        }
        sent
    }

    /// Press, then release `hold_us` later.
    pub fn tap_held(&mut self, now_us: u64, name: &str, hold_us: u64) -> (Touch, Touch) {
        let p = self.press(now_us, name);
        let r = self.release(now_us + hold_us, name);
        (p, r)
    }

    /// A tap: press, release 100 ms later ([`TAP_HOLD_US`]).
    pub fn tap(&mut self, now_us: u64, name: &str) -> (Touch, Touch) {
        self.tap_held(now_us, name, TAP_HOLD_US)
    }

    /// The operator types `value` into the keyboard field `name` of the
    /// page shown and confirms (Popup: touch, keyboard page, OK, back).
    pub fn type_value(&mut self, now_us: u64, name: &str, value: i32) -> Result<(), KeyboardError> {
        let c = self.shown_component(name).ok_or(KeyboardError::NotAField)?;
        if !c.keyboard {
            return Err(KeyboardError::NotAField);
        }
        match self.cfg.keyboard {
            Keyboard::InPlace => {
                let c = self
                    .touchable(now_us, name)
                    .map_err(KeyboardError::NoTouch)?;
                if let Some(st) = self.comps.get_mut(&(c.page, c.id)) {
                    st.val = value;
                }
                Ok(())
            }
            Keyboard::Popup => {
                match self.tap_held(now_us, name, 0).1 {
                    Touch::Keyboard => {}
                    other => return Err(KeyboardError::NoTouch(other)),
                }
                self.keyboard_enter(now_us, value)
            }
        }
    }

    /// On the open keyboard page: type `value` and press OK. The value goes
    /// into the field, and the field's page is loaded again.
    pub fn keyboard_enter(&mut self, now_us: u64, value: i32) -> Result<(), KeyboardError> {
        self.advance(now_us);
        let (page, id) = self.keyboard_origin.ok_or(KeyboardError::NotOpen)?;
        if let Some(st) = self.comps.get_mut(&(page, id)) {
            st.val = value;
        }
        self.load_page(self.now_us, page);
        Ok(())
    }

    /// On the open keyboard page: leave without a value.
    pub fn keyboard_cancel(&mut self, now_us: u64) -> Result<(), KeyboardError> {
        self.advance(now_us);
        let (page, _) = self.keyboard_origin.ok_or(KeyboardError::NotOpen)?;
        self.load_page(self.now_us, page);
        Ok(())
    }
}
