//! Speed of the gap diagnosis (issue 9: three 16,384-sample logs with pairs considered in at
//! most 2 s on one core, cost at most linear in the log length, the F-16 case in at most 8 s).
//!
//! * `gap_3x16384/pair_case`: two training runs and one validation run of the labelled
//!   benchmark's two-mass actuator (host/src/gap/benchmark.rs scales, 15 % nominal mismatch,
//!   1 % noise) with Coulomb friction at the motor *and* a saturating drive, so the best single
//!   leaves enough of the gap for the pair stage to run; every candidate is fitted.
//! * `gap_3x16384/same_law_coulomb`: the labelled benchmark's `two_mass/coulomb_friction/0`
//!   (a single effect; the pair stage is skipped), kept for comparison with earlier figures.
//! * `gap_scaling/<n>`: the pair case at 4,096, 8,192, 16,384 and 32,768 samples per log.
//! * `gap_f16/acceleration3_cli`: `ferrosid gap` on the F-16 ground-vibration data as in
//!   docs/gap-benchmark.md (order-8 N4SID of Level 1 as the nominal, Levels 1 and 7 train, Level 4
//!   validates, output Acceleration3), run as the CLI binary; skipped with a notice when
//!   ../shared/data/f16-gvt is absent.
//!
//! After the criterion groups, each case is also timed in CPU seconds (user + system of this
//! process, or of the CLI child), which a loaded machine inflates less than wall time.
//! Run: `cargo bench -p ferrosid --bench gap` (one thread: the diagnosis is sequential);
//! `-- --cpu-only` skips criterion; `-- --pair-once` runs one diagnosis of the pair case only
//! (for `perf stat`, valgrind or `GAP_PROFILE=1`).
use criterion::{criterion_group, BenchmarkId, Criterion};
use ferrosid::data::Log;
use ferrosid::gap::effect::saturation;
use ferrosid::gap::{diagnose, Effect, GapOptions};
use ferrosid_sim::benchmark::{cases, filtered_noise, generate, multisine, TS};
use ferrosid_sim::plant::{simulate, Plant, SimSettings};
use ferrosid_sim::rng::Rng;
use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

type Case = (ferrosid::lti::StateSpace, Vec<Log>, Log);

fn log_of(name: &str, u: Vec<f64>, y: Vec<f64>) -> Log {
    Log::siso(name, TS, u, y)
}

/// The two-mass pair case with `n` samples per log (module docs): Coulomb friction of 0.3 a
/// at the motor behind a drive saturating at 1.5 a (a: the low run's input RMS).
fn pair_case(n: usize) -> Case {
    let plant = Plant::two_mass();
    let a = 0.05;
    let f_c = 120.0;
    let mut rng = Rng::new(20_260_901);
    let nominal = plant.perturbed(0.15, &mut rng);
    let u_low = filtered_noise(n, TS, f_c, a, &mut rng);
    let u_high = filtered_noise(n, TS, f_c, 3.0 * a, &mut rng);
    let u_val = multisine(n, TS, 0.2, f_c, 2.0 * a, &mut rng);
    let clean = SimSettings {
        ts: TS,
        substeps: 8,
        noise_std: 0.0,
        seed: 0,
    };
    let y_rms = {
        let y = simulate(&plant, None, &u_low, &clean).expect("clean run");
        (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt()
    };
    let friction = Effect::CoulombFriction { level: 0.3 * a };
    let run = |u: &[f64], seed: u64| {
        let w: Vec<f64> = u.iter().map(|&v| saturation(v, 1.5 * a)).collect();
        let s = SimSettings {
            noise_std: 0.01 * y_rms,
            seed,
            ..clean
        };
        simulate(&plant, Some(&friction), &w, &s).expect("pair-case run")
    };
    let (y_low, y_high, y_val) = (run(&u_low, 1), run(&u_high, 2), run(&u_val, 3));
    let sim = nominal
        .physical()
        .expect("nominal plant")
        .sys
        .c2d_zoh(TS)
        .expect("discretised sim");
    (
        sim,
        vec![log_of("low", u_low, y_low), log_of("high", u_high, y_high)],
        log_of("validate", u_val, y_val),
    )
}

fn same_law_case(n: usize) -> Case {
    let case = cases()
        .into_iter()
        .find(|c| c.id == "two_mass/coulomb_friction/0")
        .expect("benchmark case");
    let data = generate(&case, n).expect("benchmark logs");
    let sim = data.sim.c2d_zoh(TS).expect("discretised sim");
    (sim, data.train, data.validate)
}

fn run_case(c: &Case) -> ferrosid::gap::Diagnosis {
    diagnose(&c.0, &c.1, &c.2, &GapOptions::default()).expect("diagnosis")
}

/// `shared/data/f16-gvt` in the nearest ancestor of the crate directory that has it.
fn f16_dir() -> Option<PathBuf> {
    let here = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    here.ancestors()
        .map(|d| d.join("shared/data/f16-gvt"))
        .find(|p| p.join("F16Data_FullMSine_Level1.csv").exists())
}

/// The F-16 Acceleration3 `gap` command line (docs/gap-benchmark.md), after writing its nominal model with
/// `identify`; `None` (with a notice) when the data or the identification is missing.
fn f16_command() -> Option<Command> {
    let Some(dir) = f16_dir() else {
        println!("notice: shared/data/f16-gvt not found; skipping the F-16 gap benchmark");
        return None;
    };
    let exe = env!("CARGO_BIN_EXE_ferrosid");
    let f = |name: &str| dir.join(name);
    let sim = std::env::temp_dir().join(format!("ferrosid-bench-f16-{}.json", std::process::id()));
    let status = Command::new(exe)
        .arg("identify")
        .arg(f("F16Data_FullMSine_Level1.csv"))
        .args([
            "--fs",
            "400",
            "--input",
            "Force",
            "--output",
            "Acceleration3",
            "--order",
            "8",
            "--out",
        ])
        .arg(&sim)
        .output()
        .ok()?;
    if !sim.exists() {
        println!(
            "notice: identify of the F-16 nominal failed ({}); skipping the F-16 gap benchmark",
            String::from_utf8_lossy(&status.stderr)
        );
        return None;
    }
    let mut cmd = Command::new(exe);
    cmd.arg("gap")
        .arg("--sim")
        .arg(&sim)
        .arg("--real")
        .arg(f("F16Data_FullMSine_Level1.csv"))
        .arg("--real")
        .arg(f("F16Data_FullMSine_Level7.csv"))
        .arg("--validate")
        .arg(f("F16Data_FullMSine_Level4_Validation.csv"))
        .args([
            "--fs",
            "400",
            "--input",
            "Force",
            "--output",
            "Acceleration3",
            "--json",
        ]);
    Some(cmd)
}

fn run_cli(cmd: &mut Command) {
    let out = cmd.output().expect("ferrosid gap runs");
    assert!(
        out.status.success(),
        "ferrosid gap failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Prints the pair case's verdict and whether its pair stage ran (it runs when a single is
/// selected that leaves more than a tenth of the linear gap and more than twice the floor).
fn describe_pair_case(pair: &Case) {
    let d = run_case(pair);
    let selected_single = !d
        .report
        .notes
        .iter()
        .any(|n| n.starts_with("best single") && n.contains("< margin"));
    let skipped = d
        .report
        .notes
        .iter()
        .any(|n| n.starts_with("no pair tried"));
    println!(
        "pair case: verdict {}, pair stage {}",
        d.report.verdict,
        if selected_single && !skipped {
            "ran"
        } else {
            "skipped"
        }
    );
}

fn bench(c: &mut Criterion) {
    let pair = pair_case(16_384);
    describe_pair_case(&pair);
    let same = same_law_case(16_384);
    let mut g = c.benchmark_group("gap_3x16384");
    g.sample_size(10);
    g.bench_function("pair_case", |b| b.iter(|| run_case(&pair)));
    g.bench_function("same_law_coulomb", |b| b.iter(|| run_case(&same)));
    g.finish();

    let mut g = c.benchmark_group("gap_scaling");
    g.sample_size(10);
    for n in [4_096usize, 8_192, 16_384, 32_768] {
        let case = pair_case(n);
        g.bench_with_input(BenchmarkId::from_parameter(n), &case, |b, case| {
            b.iter(|| run_case(case))
        });
    }
    g.finish();

    if let Some(mut cmd) = f16_command() {
        let mut g = c.benchmark_group("gap_f16");
        g.sample_size(10);
        g.measurement_time(Duration::from_secs(60));
        g.bench_function("acceleration3_cli", |b| b.iter(|| run_cli(&mut cmd)));
        g.finish();
    }
}

/// User + system CPU seconds of this process and of its waited-for children (Linux /proc,
/// 10 ms ticks); `None` elsewhere.
fn cpu_seconds() -> Option<(f64, f64)> {
    let text = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name in parentheses: state is field 3, utime 14, stime 15,
    // cutime 16, cstime 17.
    let rest = &text[text.rfind(')')? + 2..];
    let v: Vec<f64> = rest
        .split(' ')
        .skip(11)
        .take(4)
        .map(|s| s.parse().ok())
        .collect::<Option<_>>()?;
    Some(((v[0] + v[1]) * 0.01, (v[2] + v[3]) * 0.01))
}

/// Mean CPU seconds of `reps` runs of `f` (own and children's time).
fn cpu_of(reps: usize, mut f: impl FnMut()) -> Option<f64> {
    let (s0, c0) = cpu_seconds()?;
    for _ in 0..reps {
        f();
    }
    let (s1, c1) = cpu_seconds()?;
    Some(((s1 - s0) + (c1 - c0)) / reps as f64)
}

fn cpu_time() {
    let report = |name: &str, t: Option<f64>, reps: usize| {
        if let Some(t) = t {
            println!("{name}: CPU time {t:.3} s per diagnosis (mean of {reps})");
        }
    };
    let reps = 3;
    let pair = pair_case(16_384);
    describe_pair_case(&pair);
    report(
        "gap_3x16384/pair_case",
        cpu_of(reps, || drop(std::hint::black_box(run_case(&pair)))),
        reps,
    );
    let same = same_law_case(16_384);
    report(
        "gap_3x16384/same_law_coulomb",
        cpu_of(reps, || drop(std::hint::black_box(run_case(&same)))),
        reps,
    );
    for n in [4_096usize, 8_192, 16_384, 32_768] {
        let case = pair_case(n);
        report(
            &format!("gap_scaling/{n}"),
            cpu_of(reps, || drop(std::hint::black_box(run_case(&case)))),
            reps,
        );
    }
    if let Some(mut cmd) = f16_command() {
        report(
            "gap_f16/acceleration3_cli",
            cpu_of(reps, || run_cli(&mut cmd)),
            reps,
        );
    }
}

criterion_group!(benches, bench);

fn main() {
    if std::env::args().any(|a| a == "--pair-once") {
        // One diagnosis of the pair case and nothing else (for perf, valgrind, GAP_PROFILE).
        let pair = pair_case(16_384);
        let t = cpu_of(1, || drop(std::hint::black_box(run_case(&pair))));
        println!("pair case once: CPU {:.3} s", t.unwrap_or(f64::NAN));
        return;
    }
    let quick = std::env::args().any(|a| a == "--cpu-only");
    if !quick {
        benches();
    }
    cpu_time();
    if !quick {
        Criterion::default().configure_from_args().final_summary();
    }
}
