//! Welch H1 + magnitude-squared coherence on the peer-benchmark size: 100,000 samples at 1 kHz
//! (random binary input through a lightly damped second-order section, 10 % output noise),
//! Hann window, 50 % overlap, constant detrend; nperseg 1024 (the setting compared against
//! scipy in bench/peers) and 4096; plus period-synchronous averaging of 100 periods of 1000.
//! Run: `cargo bench -p ferrosid --bench welch`.
use criterion::{criterion_group, criterion_main, Criterion};
use ferrosid::spectral::{PeriodicAveraging, Welch};
use ferrosid_sim::rng::Rng;
use std::hint::black_box;

/// Input and output of the benchmark record; `periodic` repeats the first 1000 input samples.
fn data(n: usize, periodic: bool) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(42);
    let mut u: Vec<f64> = rng.binary(n);
    if periodic {
        for k in 1000..n {
            u[k] = u[k - 1000];
        }
    }
    // y[k] = 1.9 r cos(θ) y[k-1] − r² y[k-2] + u[k-1]: a resonance at 40 Hz (fs 1 kHz), r = 0.99.
    let (r, th) = (0.99_f64, 2.0 * std::f64::consts::PI * 0.04);
    let (a1, a2) = (2.0 * r * th.cos(), -r * r);
    let mut y0 = vec![0.0; n];
    for k in 2..n {
        y0[k] = a1 * y0[k - 1] + a2 * y0[k - 2] + u[k - 1];
    }
    let sd = (y0.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let y = y0.iter().map(|v| v + 0.1 * sd * rng.normal()).collect();
    (u, y)
}

fn bench(c: &mut Criterion) {
    let (u, y) = data(100_000, false);
    let mut g = c.benchmark_group("welch_h1_coherence_100k");
    for nperseg in [1024usize, 4096] {
        let w = Welch::new(nperseg);
        g.bench_function(format!("nperseg_{nperseg}"), |b| {
            b.iter(|| w.etfe(black_box(&u), black_box(&y), 1000.0).expect("welch"))
        });
    }
    let (up, yp) = data(100_000, true);
    let p = PeriodicAveraging::new(1000);
    g.bench_function("periodic_1000x100", |b| {
        b.iter(|| {
            p.frf(black_box(&up), black_box(&yp), 1000.0)
                .expect("periodic")
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
