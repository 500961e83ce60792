//! Bad input to the gap diagnosis: every case is a clear error naming the file (or variable),
//! never a panic.
use ferrosid::data::Log;
use ferrosid::error::Error;
use ferrosid::gap::simfile::{discretise_for_logs, load_sim, parse_sim};
use ferrosid::gap::{diagnose, GapOptions};
use ferrosid_sim::rng::Rng;
use std::path::{Path, PathBuf};

const TS: f64 = 1e-3;

fn log(name: &str, n: usize, ts: f64) -> Log {
    // A first-order response to a deterministic pseudo-random input.
    let mut rng = Rng::new(12345);
    let u: Vec<f64> = (0..n).map(|_| rng.uniform() - 0.5).collect();
    let mut y = vec![0.0; n];
    for k in 1..n {
        y[k] = 0.9 * y[k - 1] + 0.1 * u[k - 1];
    }
    Log::siso(name, ts, u, y)
}

fn first_order_sim() -> ferrosid::lti::StateSpace {
    // 0.1/(z − 0.9) at TS, written as a discrete state space.
    parse_sim(
        r#"{"ts": 0.001, "a": [[0.9]], "b": [[1.0]], "c": [[0.1]], "d": [[0.0]]}"#,
        Path::new("sim.json"),
    )
    .unwrap()
}

fn temp_file(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("ferrosid-gap-errors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn sim_with_two_inputs_is_refused_naming_the_file() {
    let p = temp_file(
        "two_inputs.json",
        r#"{"ts": 0, "a": [[-1]], "b": [[1, 1]], "c": [[1]], "d": [[0, 0]]}"#,
    );
    let sim = load_sim(&p).unwrap();
    let e = discretise_for_logs(&sim, TS, &p).unwrap_err();
    assert!(matches!(e, Error::Data { .. }), "{e:?}");
    let s = e.to_string();
    assert!(
        s.contains("two_inputs.json") && s.contains("2 input"),
        "{s}"
    );
}

#[test]
fn unstable_sim_is_refused_naming_the_pole() {
    let p = temp_file("unstable.json", r#"{"ts": 0, "num": [1], "den": [1, -2]}"#);
    let sim = load_sim(&p).unwrap();
    let s = discretise_for_logs(&sim, TS, &p).unwrap_err().to_string();
    assert!(
        s.contains("unstable.json")
            && s.contains("not asymptotically stable")
            && s.contains("s = 2.0"),
        "{s}"
    );
}

#[test]
fn malformed_json_names_file_and_line() {
    let p = temp_file("broken.json", "{\n  \"ts\": 0,\n  \"num\": [1,,2]\n}\n");
    let e = load_sim(&p).unwrap_err();
    assert!(matches!(e, Error::Parse { line: 3, .. }), "{e:?}");
    assert!(e.to_string().contains("broken.json:3"), "{e}");
}

#[test]
fn missing_sim_file_is_an_io_error() {
    let e = load_sim(Path::new("/nonexistent/sim.json")).unwrap_err();
    assert!(matches!(e, Error::Io { .. }) && e.to_string().contains("/nonexistent/sim.json"));
}

#[test]
fn sim_with_inconsistent_shapes_names_the_file() {
    let p = temp_file(
        "shapes.json",
        r#"{"ts": 0, "a": [[-1, 0], [0, -2]], "b": [[1]], "c": [[1, 1]], "d": [[0]]}"#,
    );
    let e = load_sim(&p).unwrap_err().to_string();
    assert!(e.contains("shapes.json") && e.contains('B'), "{e}");
}

#[test]
fn too_short_log_is_refused_naming_it() {
    let sim = first_order_sim();
    let train = vec![log("low.csv", 4000, TS), log("short.csv", 300, TS)];
    let e = diagnose(
        &sim,
        &train,
        &log("val.csv", 4000, TS),
        &GapOptions::default(),
    )
    .unwrap_err();
    let s = e.to_string();
    assert!(matches!(e, Error::Data { .. }), "{e:?}");
    assert!(
        s.contains("short.csv") && s.contains("too short") && s.contains("300"),
        "{s}"
    );
}

#[test]
fn mismatched_sample_times_are_refused() {
    let sim = first_order_sim();
    let train = vec![log("low.csv", 4000, TS), log("high.csv", 4000, 2e-3)];
    let s = diagnose(
        &sim,
        &train,
        &log("val.csv", 4000, TS),
        &GapOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(s.contains("high.csv") && s.contains("sample time"), "{s}");
}

#[test]
fn discrete_sim_at_another_sample_time_is_refused() {
    let p = Path::new("slow.json");
    let sim = parse_sim(r#"{"ts": 0.01, "num": [0.1], "den": [1, -0.9]}"#, p).unwrap();
    let s = discretise_for_logs(&sim, TS, p).unwrap_err().to_string();
    assert!(s.contains("slow.json") && s.contains("0.01"), "{s}");
}

#[test]
fn two_channel_log_is_refused() {
    let sim = first_order_sim();
    let mut two = log("mimo.csv", 4000, TS);
    two.inputs.push(two.inputs[0].clone());
    let s = diagnose(
        &sim,
        &[two],
        &log("val.csv", 4000, TS),
        &GapOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(s.contains("mimo.csv") && s.contains("SISO"), "{s}");
}

#[test]
fn no_training_log_is_an_argument_error() {
    let sim = first_order_sim();
    let e = diagnose(&sim, &[], &log("val.csv", 4000, TS), &GapOptions::default()).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument(_)), "{e:?}");
}

#[test]
fn non_finite_sample_is_refused() {
    let sim = first_order_sim();
    let mut bad = log("nan.csv", 4000, TS);
    bad.outputs[0].data[1234] = f64::NAN;
    let s = diagnose(
        &sim,
        &[bad],
        &log("val.csv", 4000, TS),
        &GapOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(s.contains("nan.csv") && s.contains("1234"), "{s}");
}

#[test]
fn zero_response_sims_are_refused_naming_the_file() {
    let p = Path::new("dead.json");
    for (text, what) in [
        (
            r#"{"ts": 0, "a": [[-2.0]], "b": [[0.0]], "c": [[3.0]], "d": [[0.0]]}"#,
            "B = 0",
        ),
        (
            r#"{"ts": 0, "a": [[-2.0]], "b": [[1.0]], "c": [[0.0]], "d": [[0.0]]}"#,
            "C = 0",
        ),
        // Controllable and observable parts disjoint: every Markov parameter is zero.
        (
            r#"{"ts": 0, "a": [[-1.0, 0.0], [0.0, -2.0]], "b": [[1.0], [0.0]], "c": [[0.0, 1.0]], "d": [[0.0]]}"#,
            "Markov",
        ),
    ] {
        let sys = parse_sim(text, p).unwrap();
        let e = discretise_for_logs(&sys, TS, p).unwrap_err();
        assert!(matches!(e, Error::Data { .. }), "{e:?}");
        let s = e.to_string();
        assert!(s.contains("dead.json") && s.contains(what), "{s}");
    }
    // A pure feedthrough (D ≠ 0, B = 0) has a response and is accepted.
    let d_only = parse_sim(
        r#"{"ts": 0, "a": [[-2.0]], "b": [[0.0]], "c": [[1.0]], "d": [[0.5]]}"#,
        p,
    )
    .unwrap();
    assert!(discretise_for_logs(&d_only, TS, p).is_ok());
}

#[test]
fn integrator_sim_is_accepted_but_other_marginal_poles_are_not() {
    let p = Path::new("axis.json");
    // Position output of a velocity-driven axis: 1/(s(0.05 s + 1)).
    let axis = parse_sim(r#"{"ts": 0, "num": [1.0], "den": [0.05, 1.0, 0.0]}"#, p).unwrap();
    let d = discretise_for_logs(&axis, TS, p).unwrap();
    assert!(d.poles().unwrap().iter().any(|z| (z - 1.0).norm() < 1e-12));
    // An undamped oscillator is not an integrator.
    let osc = parse_sim(r#"{"ts": 0, "num": [1.0], "den": [1.0, 0.0, 100.0]}"#, p).unwrap();
    let e = discretise_for_logs(&osc, TS, p).unwrap_err().to_string();
    assert!(e.contains("not asymptotically stable"), "{e}");
}

#[test]
fn constant_validation_output_is_refused_naming_the_log() {
    let sim = first_order_sim();
    let train = vec![log("low.csv", 2048, TS)];
    let mut val = log("zeros.csv", 2048, TS);
    for v in &mut val.outputs[0].data {
        *v = 0.0;
    }
    let e = diagnose(&sim, &train, &val, &GapOptions::default()).unwrap_err();
    assert!(matches!(e, Error::Data { .. }), "{e:?}");
    let s = e.to_string();
    assert!(s.contains("zeros.csv") && s.contains("constant"), "{s}");
}
