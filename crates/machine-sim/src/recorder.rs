//! Host-only list of plant positions (feature `std`).

use std::vec::Vec;

use crate::machine::Event;
use crate::metrics::{FieldMetrics, MetricsError, SpacingAccumulator};

/// Records every plant position from [`crate::Machine::step_events`] for
/// host reports and plots.
///
/// ```
/// use kinematics::consts::Gear;
/// use machine_sim::{Config, Inputs, Recorder};
/// let mut m = Config { initial_gear: Some(Gear::Low1), ..Config::noiseless() }.build()?;
/// let mut rec = Recorder::default();
/// let inputs = Inputs { drum_duty: 0.3, driver_enabled: true, ..Inputs::default() };
/// for _ in 0..5_000 {
///     m.step_events(1000, &inputs, &mut |e| rec.record(&e));
/// }
/// assert_eq!(rec.positions().len() as u32, m.plants_dropped());
/// # Ok::<(), machine_sim::Error>(())
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Recorder {
    positions: Vec<f64>,
}

impl Recorder {
    /// Keeps the position of a [`Event::Plant`]; ignores other events.
    pub fn record(&mut self, event: &Event) {
        if let Event::Plant { ground_m, .. } = event {
            self.positions.push(*ground_m);
        }
    }

    /// Plant ground positions in drop order, m.
    #[must_use]
    pub fn positions(&self) -> &[f64] {
        &self.positions
    }

    /// Spacings between consecutive plants, m.
    #[must_use]
    pub fn spacings(&self) -> Vec<f64> {
        self.positions
            .windows(2)
            .map(|w| match w {
                [a, b] => b - a,
                _ => 0.0,
            })
            .collect()
    }

    /// The field metrics of the recorded plants (theoretical count over
    /// `distance_m` of ground from position 0).
    pub fn metrics(
        &self,
        target_m: f64,
        tolerance: f64,
        distance_m: f64,
    ) -> Result<FieldMetrics, MetricsError> {
        let mut acc = SpacingAccumulator::new(target_m, tolerance)?;
        for &p in &self.positions {
            acc.push_plant(p);
        }
        Ok(acc.metrics(distance_m))
    }
}
