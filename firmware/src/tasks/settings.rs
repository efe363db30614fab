//! The settings task: a Save, only with the motors stopped.

use rtic::Mutex as _;
use rtic_monotonics::systick::prelude::*;
use supervisor::drum::RunState;
use supervisor::machine::Machine;
use supervisor::planter::PlanterState;
use supervisor::settings::store::SettingsStore;

use super::control::CONTROL_PERIOD_MS;
use crate::app::settings;
use crate::{board, Mono};

/// The settings store on the board's flash.
pub type Store = SettingsStore<board::SettingsFlash>;

/// Whether the machine's motors are commanded to run (profile A: the
/// drum; profile B: the steppers).
fn motors_commanded(machine: &Machine) -> bool {
    match machine {
        Machine::DrumBelt(sup) => sup.run_state() == RunState::Running,
        Machine::SeedlingBelt(belt) => belt.planter().state() == PlanterState::Running,
    }
}

/// Control periods the settings task waits for the drivers' enable to
/// go low after a Stop before it refuses to save.
const SAVE_WAIT_PERIODS: u32 = 3;

/// Persists the settings when the operator saves, only while the motors
/// are stopped: a flash page erase stalls the CPU, and with it the
/// control loop, for up to 40 ms.
///
/// The screen's Save was accepted with the motors stopped, but a Start
/// in the same batch of touches may have run since. So the run state is
/// checked again here, right before the erase, together with the
/// drivers' enable pin as the control task last set it (after a Stop it
/// goes low at the next control period; the task waits up to three).
/// That check and the erase are one stretch of code with no `await`:
/// the hmi task, which takes Start, shares priority 1 with this task,
/// and RTIC 2 runs tasks of one priority to completion between awaits,
/// so no command can come in between; the tasks above (control at 2,
/// Hall at 3, USART at 4) never start the motors by themselves. A Save
/// refused here says so on the screen and in the log and changes
/// nothing stored.
///
/// - Priority 1.
/// - Released by each Save.
/// - Budget: 50 ms (one page erase and ≤ 130 half-word programs), plus
///   up to 30 ms of waiting (not CPU time).
pub async fn settings(mut cx: settings::Context<'_>) {
    while let Ok(()) = cx.local.saves_out.recv().await {
        let mut waited = 0;
        let text = loop {
            // The check and the save under one lock: nothing can start
            // the motors in between.
            let store = &mut *cx.local.store;
            let done = cx.shared.machine.lock(|m| {
                if motors_commanded(m) {
                    defmt::warn!("settings: save refused, the motors were started after Save");
                    Some("Motors running: settings not saved")
                } else if !board::drivers_enabled() {
                    // From here to the end of the save: no await.
                    Some(save_settings(store, m))
                } else {
                    None
                }
            });
            if let Some(text) = done {
                break text;
            }
            if waited >= SAVE_WAIT_PERIODS {
                defmt::warn!("settings: save refused, the motor drivers are still enabled");
                break "Motors running: settings not saved";
            }
            waited += 1;
            Mono::delay(CONTROL_PERIOD_MS.millis()).await;
        };
        cx.shared.hmi.lock(|hmi| {
            let _ = hmi.show_message(text);
        });
    }
}

/// The save itself, in its own stack frame: inlined into the priority-1
/// tasks' dispatcher, its record buffers (≈ 0.7 KB) sat under every
/// priority-1 task and under the control task preempting them.
#[inline(never)]
fn save_settings(store: &mut Option<Store>, machine: &Machine) -> &'static str {
    match store.as_mut().map(|s| s.save(machine.settings())) {
        Some(Ok(sequence)) => {
            defmt::info!("settings: saved as record {=u32}", sequence);
            "Settings saved"
        }
        Some(Err(e)) => {
            defmt::error!("settings: save failed: {}", e);
            "Save failed: settings not stored"
        }
        None => "No settings store on this board",
    }
}
