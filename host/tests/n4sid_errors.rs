//! Bad input to N4SID: each case is a clear error naming the problem (and the file, for a
//! Log), never a panic or a silently wrong model.
mod n4sid_support;

use ferrosid::data::{Channel, Log};
use ferrosid::n4sid::{n4sid, n4sid_slices, N4sidOptions, OrderSelection};
use ferrosid::Error;
use n4sid_support::*;
use std::path::PathBuf;

fn good(n: usize) -> (Vec<f64>, Vec<f64>) {
    let plant = third_order_plant(1e-3);
    let mut rng = Rng::new(99);
    let u = rng.binary(n);
    let y = plant.simulate_siso(&u, None).unwrap();
    (u, y)
}

fn msg(r: Result<ferrosid::n4sid::N4sidResult, Error>) -> (Error, String) {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => {
            let s = e.to_string();
            (e, s)
        }
    }
}

#[test]
fn constant_input_is_no_excitation() {
    let (_, y) = good(2000);
    let u = vec![1.5; 2000];
    let (e, s) = msg(n4sid_slices(1e-3, &[&u], &[&y], &N4sidOptions::default()));
    assert!(matches!(e, Error::Data { .. }));
    assert!(
        s.contains("constant") && s.contains("no excitation") && s.contains("u0"),
        "{s}"
    );
}

#[test]
fn constant_output_is_refused() {
    let (u, _) = good(2000);
    let y = vec![0.0; 2000];
    let (_, s) = msg(n4sid_slices(1e-3, &[&u], &[&y], &N4sidOptions::default()));
    assert!(s.contains("output `y0` is constant"), "{s}");
}

#[test]
fn too_short_data() {
    let (u, y) = good(100);
    let (e, s) = msg(n4sid_slices(1e-3, &[&u], &[&y], &N4sidOptions::default()));
    assert!(matches!(e, Error::Data { .. }));
    assert!(
        s.contains("too few samples") && s.contains("have 100"),
        "{s}"
    );
}

#[test]
fn mismatched_lengths_and_non_finite_samples() {
    let (u, y) = good(2000);
    let (_, s) = msg(n4sid_slices(
        1e-3,
        &[&u],
        &[&y[..1999]],
        &N4sidOptions::default(),
    ));
    assert!(s.contains("mismatched lengths"), "{s}");
    let mut y2 = y.clone();
    y2[123] = f64::NAN;
    let (_, s) = msg(n4sid_slices(1e-3, &[&u], &[&y2], &N4sidOptions::default()));
    assert!(s.contains("sample 123") && s.contains("not finite"), "{s}");
    let mut u2 = u.clone();
    u2[7] = f64::INFINITY;
    let (_, s) = msg(n4sid_slices(1e-3, &[&u2], &[&y], &N4sidOptions::default()));
    assert!(s.contains("input `u0` sample 7"), "{s}");
}

#[test]
fn errors_from_a_log_name_the_file_and_channel() {
    let (u, _) = good(2000);
    let log = Log {
        path: PathBuf::from("bench/run7.csv"),
        ts: 1e-3,
        inputs: vec![Channel {
            name: "torque".into(),
            data: u,
        }],
        outputs: vec![Channel {
            name: "accel".into(),
            data: vec![2.0; 2000],
        }],
        warnings: vec![],
    };
    let (_, s) = msg(n4sid(&log, &N4sidOptions::default()));
    assert!(s.contains("bench/run7.csv") && s.contains("`accel`"), "{s}");
}

#[test]
fn invalid_options() {
    let (u, y) = good(2000);
    let run = |o: N4sidOptions| msg(n4sid_slices(1e-3, &[&u], &[&y], &o));
    let (e, s) = run(N4sidOptions {
        block_rows: 1,
        ..Default::default()
    });
    assert!(
        matches!(e, Error::InvalidArgument(_)) && s.contains("block_rows"),
        "{s}"
    );
    let (_, s) = run(N4sidOptions {
        order: OrderSelection::Fixed(0),
        ..Default::default()
    });
    assert!(s.contains("order 0 invalid"), "{s}");
    let (_, s) = run(N4sidOptions {
        order: OrderSelection::Fixed(20),
        ..Default::default()
    });
    assert!(s.contains("increase block_rows"), "{s}");
    let (_, s) = run(N4sidOptions {
        order: OrderSelection::Range { min: 5, max: 3 },
        ..Default::default()
    });
    assert!(s.contains("order range 5..=3"), "{s}");
    let (_, s) = run(N4sidOptions {
        stability_margin: Some(1.5),
        ..Default::default()
    });
    assert!(s.contains("stability margin"), "{s}");
    let (_, s) = msg(n4sid_slices(0.0, &[&u], &[&y], &N4sidOptions::default()));
    assert!(s.contains("sample time"), "{s}");
    let (_, s) = msg(n4sid_slices(1e-3, &[], &[&y], &N4sidOptions::default()));
    assert!(s.contains("at least one input"), "{s}");
}

#[test]
fn non_persistently_exciting_input_is_warned() {
    // A single sinusoid excites only order 2, far below 2i = 40.
    let plant = third_order_plant(1e-3);
    let u: Vec<f64> = (0..4000).map(|k| (0.05 * k as f64).sin()).collect();
    let y = plant.simulate_siso(&u, None).unwrap();
    let mut rng = Rng::new(5);
    let y: Vec<f64> = y.iter().map(|v| v + 1e-3 * rng.normal()).collect();
    match n4sid_slices(1e-3, &[&u], &[&y], &N4sidOptions::default()) {
        Ok(r) => assert!(
            r.warnings
                .iter()
                .any(|w| w.contains("persistently exciting")),
            "{:?}",
            r.warnings
        ),
        Err(e) => {
            let s = e.to_string();
            assert!(
                s.contains("rank deficient") || s.contains("ill-conditioned"),
                "{s}"
            )
        }
    }
}
