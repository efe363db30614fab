//! The travel-speed estimate the drum followed before the current one, kept
//! here (host code, the bench only) so that §11 can set the two side by
//! side on the same Hall edges: the M/T estimator whose tooth shares were
//! learnt against the revolution centred on each gap (behind a curvature
//! and a slope gate, a running mean of 14 samples), whose window was always
//! the gaps since the last update, and the predictor that carried the last
//! slope between two windows (±10 %) and returned the estimator's bound on
//! an overdue edge. A line-by-line port of `kinematics::speed::MtEstimator`
//! and `supervisor::drum::predictor` as they were (no glitch hold, no
//! steady runs, no noisy flag); the edge rules, timeout and settings are
//! the product's defaults.

const Z: usize = kinematics::consts::Z1 as usize;
const RING: usize = 32 + 32 / 2 + 4;
const ONE_Q16: u32 = 1 << 16;
const CURVATURE_GATE: u64 = 400;
const SLOPE_GATE: u64 = 40;
const STEADY_GATE: u64 = 1000;
const SHARE_SAMPLES: u8 = 14;
const TIMER_HZ: u64 = 1_000_000;
const STOP_TIMEOUT: u32 = 1_500_000;
const MIN_EDGE_GAP: u32 = 500;
const GLITCH_SHIFT: u32 = 2;
const FROM_REST_MIN_GAP: u32 = 20_000;

/// What the estimator said this period.
#[derive(Clone, Copy, PartialEq, Eq)]
enum State {
    Stopped,
    Starting,
    Measured,
    Holding,
    Decaying,
}

struct Measurement {
    bits: u32,
    state: State,
    edges: u32,
    window: u32,
    since: u32,
}

/// The estimator and the predictor as they were.
pub struct Legacy {
    stamps: [u32; RING],
    head: usize,
    tooth: usize,
    has_last: bool,
    edges_total: u32,
    valid_run: u32,
    glitch_ref: u32,
    from_rest: bool,
    ref_stamp: u32,
    ref_edges: u32,
    ref_valid: bool,
    learned_upto: u32,
    samples: [u8; Z],
    weights: [u32; Z],
    weight_sum: u32,
    held: u32,
    // The predictor.
    last: Option<(i64, u32)>,
    slope: (i64, i64),
    period: u32,
}

fn ring_prev(i: usize, back: usize) -> usize {
    (i + RING - back % RING) % RING
}

impl Legacy {
    pub fn new() -> Self {
        Self {
            stamps: [0; RING],
            head: 0,
            tooth: 0,
            has_last: false,
            edges_total: 0,
            valid_run: 0,
            glitch_ref: 0,
            from_rest: false,
            ref_stamp: 0,
            ref_edges: 0,
            ref_valid: false,
            learned_upto: 0,
            samples: [0; Z],
            weights: [ONE_Q16; Z],
            weight_sum: ONE_Q16 * Z as u32,
            held: 0,
            last: None,
            slope: (0, 0),
            period: 0,
        }
    }

    fn newest(&self) -> u32 {
        self.stamps[self.head]
    }

    pub fn push_edge(&mut self, t: u32) {
        if self.has_last {
            let dt = t.wrapping_sub(self.newest());
            let expected_min = if self.glitch_ref == 0 {
                if self.from_rest {
                    FROM_REST_MIN_GAP
                } else {
                    0
                }
            } else {
                self.glitch_ref >> GLITCH_SHIFT
            };
            if dt < MIN_EDGE_GAP || dt < expected_min {
                return;
            }
            if dt > STOP_TIMEOUT {
                self.restart();
            } else {
                self.from_rest = false;
                self.glitch_ref = if self.glitch_ref == 0 {
                    dt
                } else {
                    dt.min(self.glitch_ref.saturating_mul(2))
                };
            }
        }
        self.head = (self.head + 1) % RING;
        self.stamps[self.head] = t;
        if self.has_last {
            self.tooth = (self.tooth + 1) % Z;
        }
        self.has_last = true;
        self.edges_total = self.edges_total.wrapping_add(1);
        self.valid_run = self.valid_run.saturating_add(1);
    }

    fn restart(&mut self) {
        self.from_rest = true;
        self.valid_run = 0;
        self.glitch_ref = 0;
        self.ref_valid = false;
        self.held = 0;
    }

    fn window_weight(&self, m: u32) -> u64 {
        let full = u64::from(m / Z as u32);
        let rem = (m % Z as u32) as usize;
        let mut sum = full * u64::from(self.weight_sum);
        let mut idx = self.tooth;
        for _ in 0..rem {
            sum += u64::from(self.weights[idx]);
            idx = if idx == 0 { Z - 1 } else { idx - 1 };
        }
        sum
    }

    fn rpm_bits(&self, w: u64, ticks: u32) -> u32 {
        let den = u128::from(self.weight_sum) * u128::from(ticks);
        if den == 0 {
            return u32::MAX;
        }
        let scale = u128::from(TIMER_HZ * 60) << 20;
        u32::try_from(u128::from(w) * scale / den).unwrap_or(u32::MAX)
    }

    fn learn(&mut self) {
        let half = Z / 2;
        let fresh = self.edges_total.wrapping_sub(self.learned_upto);
        self.learned_upto = self.edges_total;
        let tol = ONE_Q16 / 25;
        let q = half / 2;
        let mut learnt = false;
        for b in 0..fresh.min(4) as usize {
            let p = b + half + q;
            let reach = b + Z + 2 * q;
            if reach >= RING || reach as u32 >= self.valid_run {
                break;
            }
            let stamp = |back: usize| self.stamps[ring_prev(self.head, back)];
            let rev = |end: usize| stamp(end).wrapping_sub(stamp(end + Z));
            let gap = |end: usize| stamp(end).wrapping_sub(stamp(end + 1));
            let second = |a: u32, c: u32, n: u32| {
                (i64::from(a) + i64::from(n) - 2 * i64::from(c)).unsigned_abs()
            };
            let e = p - half;
            let (r_before, r_centre, r_after) = (rev(e + q), rev(e), rev(e.saturating_sub(q)));
            let g = gap(p);
            let slope = u64::from(r_before.abs_diff(r_after));
            if r_centre == 0
                || second(r_before, r_centre, r_after) * CURVATURE_GATE > u64::from(r_centre)
                || slope * SLOPE_GATE > u64::from(r_centre)
            {
                continue;
            }
            let w_new =
                u32::try_from(u64::from(g) * Z as u64 * u64::from(ONE_Q16) / u64::from(r_centre))
                    .unwrap_or(u32::MAX);
            if w_new.abs_diff(ONE_Q16) > tol {
                continue;
            }
            let tooth = (self.tooth + 2 * Z - p % Z) % Z;
            let n = self.samples[tooth];
            let steady = slope * STEADY_GATE <= u64::from(r_centre);
            let k = u32::from(n) + if steady { 1 } else { 2 };
            let w = self.weights[tooth];
            self.weights[tooth] = if w_new >= w {
                w + (w_new - w) / k
            } else {
                w - (w - w_new) / k
            };
            self.samples[tooth] = (n + 1).min(SHARE_SAMPLES);
            learnt = true;
        }
        if learnt {
            self.weight_sum = self.weights.iter().sum();
        }
    }

    fn update(&mut self, now: u32) -> Measurement {
        let newest = self.newest();
        let since = now.wrapping_sub(newest);
        let since = if !self.has_last || since > 1 << 31 {
            0
        } else {
            since
        };
        let mut out = Measurement {
            bits: 0,
            state: State::Stopped,
            edges: 0,
            window: 0,
            since,
        };
        if !self.has_last {
            return out;
        }
        let new = self.edges_total.wrapping_sub(self.ref_edges);
        if new > 0 && self.valid_run > 0 {
            self.learn();
            let (m, start) = if self.ref_valid && new < self.valid_run {
                (new, self.ref_stamp)
            } else {
                let back = (self.valid_run - 1).min(RING as u32 - 1);
                (back, self.stamps[ring_prev(self.head, back as usize)])
            };
            self.ref_stamp = newest;
            self.ref_edges = self.edges_total;
            self.ref_valid = true;
            let window = newest.wrapping_sub(start);
            if m == 0 || window == 0 {
                out.state = State::Starting;
                return out;
            }
            self.held = self.rpm_bits(self.window_weight(m), window);
            out.state = State::Measured;
            out.edges = m;
            out.window = window;
            out.bits = self.held;
            return out;
        }
        if !self.ref_valid || since > STOP_TIMEOUT {
            if self.ref_valid {
                self.restart();
            }
            out.state = if self.ref_valid || self.valid_run == 0 {
                State::Stopped
            } else {
                State::Starting
            };
            return out;
        }
        let next = (self.tooth + 1) % Z;
        let cap = self.rpm_bits(u64::from(self.weights[next]), since);
        if cap < self.held {
            out.state = State::Decaying;
            out.bits = cap;
        } else {
            out.state = State::Holding;
            out.bits = self.held;
        }
        out
    }

    /// The predicted gear speed at `now` (the control step's), U12F20 bits.
    pub fn predict(&mut self, now: u32) -> u32 {
        let m = self.update(now);
        match m.state {
            State::Measured if m.edges > 0 => {
                let v = i64::from(m.bits);
                let center = now.wrapping_sub(m.since).wrapping_sub(m.window / 2);
                if let Some((v0, t0)) = self.last {
                    let dt = i64::from(center.wrapping_sub(t0));
                    self.slope = if dt > 0 { (v - v0, dt) } else { (0, 1) };
                }
                self.last = Some((v, center));
                self.period = m.window / m.edges;
            }
            State::Measured | State::Holding => {}
            State::Decaying => return m.bits,
            State::Stopped | State::Starting => {
                self.last = None;
                self.slope = (0, 0);
                self.period = 0;
                return m.bits;
            }
        }
        let Some((v, center)) = self.last else {
            return m.bits;
        };
        let age = i64::from(now.wrapping_sub(center)).min(2 * i64::from(self.period));
        let (dv, dt) = self.slope;
        let bound = (v / 10).max(0);
        let step = dv
            .saturating_mul(age)
            .checked_div(dt)
            .unwrap_or(0)
            .clamp(-bound, bound);
        u32::try_from((v + step).clamp(0, i64::from(u32::MAX))).unwrap_or(0)
    }
}
