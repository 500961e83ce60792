//! N4SID on the reference case of issue 3: a 100,000-sample SISO log of a third-order lightly
//! damped plant (1/(s+2π·5) × resonance at 40 Hz, ζ = 0.02, ZOH at 1 kHz) driven by a random
//! binary signal with 10 % output noise, i = 20 block rows, automatic order.
//! Run: `cargo bench -p ferrosid --bench n4sid`.
use criterion::{criterion_group, criterion_main, Criterion};
use ferrosid::lti::{poly_mul, TransferFunction};
use ferrosid::n4sid::{n4sid_slices, N4sidOptions, OrderSelection};
use std::f64::consts::PI;

/// SplitMix64 + Box–Muller, seeded.
struct Rng(u64);
impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        z ^ (z >> 31)
    }
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        (-2.0 * u1.ln()).sqrt() * (2.0 * PI * self.uniform()).cos()
    }
}

fn data(n: usize) -> (Vec<f64>, Vec<f64>) {
    let a = 2.0 * PI * 5.0;
    let wn = 2.0 * PI * 40.0;
    let plant = TransferFunction::new(
        vec![a * wn * wn],
        poly_mul(&[1.0, a], &[1.0, 2.0 * 0.02 * wn, wn * wn]),
        0.0,
    )
    .and_then(|tf| tf.to_state_space())
    .and_then(|g| g.c2d_zoh(1e-3))
    .expect("reference plant");
    let mut rng = Rng(42);
    let u: Vec<f64> = (0..n)
        .map(|_| if rng.next_u64() & 1 == 1 { 1.0 } else { -1.0 })
        .collect();
    let y0 = plant.simulate_siso(&u, None).expect("simulation");
    let mean = y0.iter().sum::<f64>() / n as f64;
    let sd = (y0.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    let y = y0.iter().map(|v| v + 0.1 * sd * rng.normal()).collect();
    (u, y)
}

fn bench(c: &mut Criterion) {
    let (u, y) = data(100_000);
    let mut g = c.benchmark_group("n4sid_100k_siso_i20");
    g.sample_size(20);
    g.bench_function("auto_order", |b| {
        b.iter(|| n4sid_slices(1e-3, &[&u], &[&y], &N4sidOptions::default()).expect("n4sid"))
    });
    let fixed = N4sidOptions {
        order: OrderSelection::Fixed(3),
        ..Default::default()
    };
    g.bench_function("order3", |b| {
        b.iter(|| n4sid_slices(1e-3, &[&u], &[&y], &fixed).expect("n4sid"))
    });
    let lean = N4sidOptions {
        order: OrderSelection::Fixed(3),
        estimate_kalman_gain: false,
        ..Default::default()
    };
    g.bench_function("order3_no_kalman", |b| {
        b.iter(|| n4sid_slices(1e-3, &[&u], &[&y], &lean).expect("n4sid"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
