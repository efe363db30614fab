//! First-order drum-motor plant with dead time, simulated in f64.
//!
//! `τ·dn/dt = K·u(t − θ) − n` where `u` is the commanded speed in r/min (the
//! PWM duty `D = u / 44.7` times `n_max` = 44.7 r/min, SPEC eq. 8), `K` the
//! plant gain (1 = the feed-forward model is exact), `τ = 25 ms`, `θ = 5 ms`.
//! Integrated exactly over 0.5 ms sub-steps with zero-order hold on `u`.

use std::collections::VecDeque;

pub const TS: f64 = 0.010;
const SUB: usize = 20;
const DT: f64 = TS / SUB as f64;

pub struct Plant {
    pub n: f64,
    gain: f64,
    /// Additive load disturbance on the steady-state speed, r/min.
    pub load: f64,
    decay: f64,
    delay: VecDeque<f64>,
}

impl Plant {
    pub fn new(gain: f64) -> Self {
        Self::with(gain, 0.025, 0.005)
    }

    pub fn with(gain: f64, tau: f64, dead: f64) -> Self {
        let steps = (dead / DT).round() as usize;
        Self {
            n: 0.0,
            gain,
            load: 0.0,
            decay: (-DT / tau).exp(),
            delay: std::iter::repeat_n(0.0, steps).collect(),
        }
    }

    /// Apply `u` (r/min) for one control period.
    pub fn advance(&mut self, u: f64) {
        for _ in 0..SUB {
            self.delay.push_back(u);
            let ud = self.delay.pop_front().unwrap();
            let target = self.gain * ud + self.load;
            self.n = target + (self.n - target) * self.decay;
        }
    }
}
