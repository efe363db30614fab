//! Deterministic pseudo-random numbers: xorshift64* seeded through splitmix64.
//!
//! No external crate: the generator is eight bytes of state and a handful of
//! integer operations, so a run is reproducible bit for bit from its seed on
//! every target (host and thumbv7m).

/// splitmix64 finaliser: a good 64-bit hash, also used to spread seeds.
#[must_use]
pub(crate) const fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform value in `[-1, 1)` derived from a 64-bit hash (no state).
#[must_use]
pub(crate) fn hash_signed_unit(h: u64) -> f32 {
    let u = (h >> 40) as f32 / (1u64 << 24) as f32;
    2.0 * u - 1.0
}

/// xorshift64* generator (Vigna 2016).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Rng(u64);

impl Rng {
    /// A generator from any seed (0 included: the seed is hashed first).
    #[must_use]
    pub(crate) const fn new(seed: u64) -> Self {
        let s = splitmix64(seed);
        Self(if s == 0 { 0x2545_F491_4F6C_DD1D } else { s })
    }

    /// Next 64 random bits.
    pub(crate) fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in `[0, 1)` with 24 bits of resolution.
    pub(crate) fn uniform(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in `[-1, 1)`.
    pub(crate) fn signed(&mut self) -> f32 {
        hash_signed_unit(self.next_u64())
    }

    /// Approximately standard normal: the Irwin–Hall sum of four uniforms,
    /// centred and scaled to unit variance (bounded at ±2√3 σ, which is what
    /// a simulator of a bounded physical disturbance wants anyway).
    pub(crate) fn normal(&mut self) -> f32 {
        let s = self.uniform() + self.uniform() + self.uniform() + self.uniform();
        (s - 2.0) * 1.732_050_8
    }

    /// Exponentially distributed with the given mean (inverse CDF).
    pub(crate) fn exponential(&mut self, mean: f32) -> f32 {
        // 1 − u is in (0, 1], so the logarithm is finite.
        -mean * libm::logf(1.0 - self.uniform())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_and_normal_have_the_textbook_moments() {
        // Uniform [0,1): mean 1/2, variance 1/12. Normal: mean 0, variance 1.
        let mut r = Rng::new(7);
        let n = 200_000;
        let (mut su, mut su2, mut sn, mut sn2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for _ in 0..n {
            let u = f64::from(r.uniform());
            let g = f64::from(r.normal());
            su += u;
            su2 += u * u;
            sn += g;
            sn2 += g * g;
        }
        let nf = f64::from(n);
        let mu = su / nf;
        assert!((mu - 0.5).abs() < 0.005, "{mu}");
        assert!((su2 / nf - mu * mu - 1.0 / 12.0).abs() < 0.002);
        let mn = sn / nf;
        assert!(mn.abs() < 0.01, "{mn}");
        assert!((sn2 / nf - mn * mn - 1.0).abs() < 0.02);
    }

    #[test]
    fn exponential_has_its_mean() {
        let mut r = Rng::new(11);
        let n = 100_000;
        let s: f64 = (0..n).map(|_| f64::from(r.exponential(2.0))).sum();
        assert!((s / f64::from(n) - 2.0).abs() < 0.05);
    }
}
