//! The simulated machine's truth for the log lines.

use super::sim::Sensors;

impl Sensors {
    /// Profile B's truth for the log: plants, their mean spacing (µm) and
    /// CV (0.01 %) since the metrics were last reset, ground position (mm).
    pub fn truth_b(&self) -> (u32, u32, u32, u32) {
        let m = self.machine.metrics();
        (
            m.plants,
            (m.mean_spacing_m * 1e6) as u32,
            (m.cv_pct * 100.0) as u32,
            (self.machine.ground_position_m() * 1000.0) as u32,
        )
    }

    /// The model's own view, for the log: ground travel speed (µm/s: the
    /// tests compare the drum with eq. 7 to 0.1 %, finer than 1 mm/s of
    /// 140 mm/s), drum speed (r/min × 1000), plants dropped, ground
    /// position (mm), Hall edges delivered.
    pub fn truth(&self) -> (u32, u32, u32, u32, u32) {
        (
            (self.machine.travel_speed_m_s() * 1e6) as u32,
            (self.machine.drum_speed_rpm() * 1000.0) as u32,
            self.machine.plants_dropped(),
            (self.machine.ground_position_m() * 1000.0) as u32,
            self.machine.hall_edges(),
        )
    }
}
