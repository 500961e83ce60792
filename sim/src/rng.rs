//! Seeded pseudo-random numbers for the benchmark simulator, the tests, benchmarks and example
//! generators: the firmware's SplitMix64 (Steele, Lea & Flood 2014; `ferrosid_firmware::rng`,
//! the workspace's one generator) for bits and uniforms, Box–Muller for normals. Deterministic
//! across platforms and crate versions, so the same seed always gives the same logs.

pub use ferrosid_firmware::rng::SplitMix64;

/// SplitMix64 bits with uniform and normal draws.
#[derive(Debug, Clone)]
pub struct Rng {
    bits: SplitMix64,
    spare: Option<f64>,
}

impl Rng {
    /// Generator from a seed.
    pub fn new(seed: u64) -> Self {
        Self {
            bits: SplitMix64::new(seed),
            spare: None,
        }
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.bits.next_u64()
    }
    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        self.bits.next_f64()
    }
    /// Standard normal.
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }
    /// `n` samples of white Gaussian noise of standard deviation `std`.
    pub fn noise(&mut self, n: usize, std: f64) -> Vec<f64> {
        (0..n).map(|_| std * self.normal()).collect()
    }
    /// `n` random ±1 values (a white binary signal, one bit of [`Self::next_u64`] each).
    pub fn binary(&mut self, n: usize) -> Vec<f64> {
        (0..n)
            .map(|_| if self.next_u64() & 1 == 1 { 1.0 } else { -1.0 })
            .collect()
    }
}
