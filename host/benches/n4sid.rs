//! N4SID on the reference case of issue 3: a 100,000-sample SISO log of a third-order lightly
//! damped plant (1/(s+2π·5) × resonance at 40 Hz, ζ = 0.02, ZOH at 1 kHz) driven by a random
//! binary signal with 10 % output noise, i = 20 block rows, automatic order.
//! Run: `cargo bench -p ferrosid --bench n4sid`.
use criterion::{criterion_group, Criterion};
use ferrosid::lti::{poly_mul, TransferFunction};
use ferrosid::n4sid::{n4sid_slices, N4sidOptions, OrderSelection};
use ferrosid_sim::rng::Rng;
use std::f64::consts::PI;

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
    let mut rng = Rng::new(42);
    let u: Vec<f64> = rng.binary(n);
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

/// Process CPU time (user + system) in seconds from /proc/self/stat (Linux; clock ticks of
/// 1/100 s), or None elsewhere. Wall-clock medians from criterion are inflated when other
/// processes share the cores; CPU time per call is not.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let after = stat.rsplit(')').next()?;
    let f: Vec<&str> = after.split_whitespace().collect();
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

fn cpu_time_per_call() {
    let (u, y) = data(100_000);
    let calls = 40;
    for (name, opts) in [
        ("auto_order", N4sidOptions::default()),
        (
            "order3_no_kalman",
            N4sidOptions {
                order: OrderSelection::Fixed(3),
                estimate_kalman_gain: false,
                ..Default::default()
            },
        ),
    ] {
        let Some(t0) = cpu_seconds() else {
            return;
        };
        for _ in 0..calls {
            std::hint::black_box(n4sid_slices(1e-3, &[&u], &[&y], &opts).expect("n4sid"));
        }
        if let Some(t1) = cpu_seconds() {
            println!(
                "n4sid_100k_siso_i20/{name}: CPU time {:.1} ms per call (user+sys over {calls} calls)",
                1e3 * (t1 - t0) / calls as f64
            );
        }
    }
}

criterion_group!(benches, bench);

fn main() {
    benches();
    cpu_time_per_call();
    Criterion::default().configure_from_args().final_summary();
}
