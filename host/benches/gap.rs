//! Gap diagnosis of three 16,384-sample logs (two training runs, one validation run; the
//! labelled benchmark's two-mass actuator with Coulomb friction, all eight candidate effects
//! fitted). Target (issue 6): at most 2 s on one core in release.
//! Run: `cargo bench -p ferrosid --bench gap`.
use criterion::{criterion_group, Criterion};
use ferrosid::gap::benchmark::{cases, generate, TS};
use ferrosid::gap::{diagnose, GapOptions};

fn setup() -> (ferrosid::lti::StateSpace, Vec<ferrosid::Log>, ferrosid::Log) {
    let case = cases()
        .into_iter()
        .find(|c| c.id == "two_mass/coulomb_friction/0")
        .expect("benchmark case");
    let data = generate(&case, 16_384).expect("benchmark logs");
    let sim = data.sim.c2d_zoh(TS).expect("discretised sim");
    (sim, data.train, data.validate)
}

fn bench(c: &mut Criterion) {
    let (sim, train, val) = setup();
    let opts = GapOptions::default();
    let mut g = c.benchmark_group("gap_3x16384");
    g.sample_size(10);
    g.bench_function("diagnose_all_effects", |b| {
        b.iter(|| diagnose(&sim, &train, &val, &opts).expect("diagnosis"))
    });
    g.finish();
}

/// User + system CPU seconds of this process (Linux /proc, 10 ms ticks); `None` elsewhere.
/// Unlike criterion's wall-clock times it is not inflated when other jobs share the cores.
fn process_cpu_seconds() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name in parentheses: state is field 3, utime 14, stime 15.
    let rest = &text[text.rfind(')')? + 2..];
    let mut it = rest.split(' ').skip(11);
    let ut: f64 = it.next()?.parse().ok()?;
    let st: f64 = it.next()?.parse().ok()?;
    Some((ut + st) * 0.01)
}

fn cpu_time() {
    let (sim, train, val) = setup();
    let opts = GapOptions::default();
    let reps = 5;
    let Some(t0) = process_cpu_seconds() else {
        return;
    };
    for _ in 0..reps {
        std::hint::black_box(diagnose(&sim, &train, &val, &opts).expect("diagnosis"));
    }
    if let Some(t1) = process_cpu_seconds() {
        println!(
            "gap_3x16384/diagnose_all_effects: CPU time {:.3} s per diagnosis (mean of {reps})",
            (t1 - t0) / reps as f64
        );
    }
}

criterion_group!(benches, bench);

fn main() {
    benches();
    cpu_time();
    Criterion::default().configure_from_args().final_summary();
}
