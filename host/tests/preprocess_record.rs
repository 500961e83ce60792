//! Preprocessing records, determinism, documented filter attenuation and bad inputs.
use ferrosid::preprocess::{preprocess, AntiAlias, Step, StepRecord};
use ferrosid::{Channel, Error, Log};

fn log(n: usize) -> Log {
    let u: Vec<f64> = (0..n)
        .map(|k| (0.05 * k as f64).sin() + 2.0 + 0.01 * k as f64)
        .collect();
    let y: Vec<f64> = (0..n)
        .map(|k| (0.031 * k as f64).cos() * 3.0 - 1.0)
        .collect();
    Log {
        path: "logs/run1.csv".into(),
        ts: 0.001,
        inputs: vec![Channel {
            name: "iq".into(),
            data: u,
        }],
        outputs: vec![Channel {
            name: "omega".into(),
            data: y,
        }],
        warnings: vec![],
    }
}

#[test]
fn mean_removal_is_recorded_and_exact() {
    let l = log(1000);
    let (out, rec) = preprocess(&l, &[Step::RemoveMean]).unwrap();
    let mean_u = l.u().iter().sum::<f64>() / 1000.0;
    match &rec.steps[0] {
        StepRecord::RemoveMean { channels } => {
            assert_eq!(channels.len(), 2);
            assert_eq!(channels[0].channel, "iq");
            assert_eq!(channels[1].channel, "omega");
            assert!((channels[0].mean - mean_u).abs() < 1e-14);
        }
        other => panic!("{other:?}"),
    }
    for c in out.inputs.iter().chain(&out.outputs) {
        let m = c.data.iter().sum::<f64>() / c.data.len() as f64;
        assert!(m.abs() < 1e-13, "{}: {m}", c.name);
    }
    assert_eq!(rec.source, "logs/run1.csv");
    assert_eq!((rec.samples_in, rec.samples_out), (1000, 1000));
}

#[test]
fn same_input_same_bytes() {
    let steps = [
        Step::RemoveTrend,
        Step::Decimate { factor: 3 },
        Step::RemoveMean,
    ];
    let (a, ra) = preprocess(&log(5000), &steps).unwrap();
    let (b, rb) = preprocess(&log(5000), &steps).unwrap();
    let ja = serde_json::to_string(&ra).unwrap();
    let jb = serde_json::to_string(&rb).unwrap();
    assert_eq!(ja, jb);
    let bits = |l: &Log| -> Vec<u64> {
        l.inputs
            .iter()
            .chain(&l.outputs)
            .flat_map(|c| c.data.iter().map(|v| v.to_bits()))
            .collect()
    };
    assert_eq!(bits(&a), bits(&b));
    // The record lists the steps in order, with their parameters, as JSON.
    let v: serde_json::Value = serde_json::from_str(&ja).unwrap();
    let names: Vec<&str> = v["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["step"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["remove_trend", "decimate", "remove_mean"]);
    assert_eq!(v["steps"][1]["factor"], 3);
    assert_eq!(v["samples_out"], 1667);
    // Steps (the settings) round-trip through serde too, for PIPELINE files.
    let s = serde_json::to_string(&steps).unwrap();
    assert_eq!(
        s,
        r#"[{"step":"remove_trend"},{"step":"decimate","factor":3},{"step":"remove_mean"}]"#
    );
    let back: Vec<Step> = serde_json::from_str(&s).unwrap();
    assert_eq!(back, steps);
}

#[test]
fn documented_attenuation_holds() {
    // Module docs: two passes give >= 45.6 dB at fs_out/2, >= 83 dB from 1.2 fs_out/2 up, and
    // 0.1 dB ripple in the passband (0 .. 0.8 fs_out/2). Response in cycles/sample of the input.
    for q in [2usize, 3, 4, 5, 8, 10, 16, 50] {
        let f = AntiAlias::design(q);
        let db2 = |fr: f64| 2.0 * 20.0 * f.response(fr).norm().log10();
        let nyq_out = 0.5 / q as f64;
        assert!(db2(nyq_out) < -45.6, "q {q}: {}", db2(nyq_out));
        for i in 0..400 {
            let fr = 1.2 * nyq_out + (0.5 - 1.2 * nyq_out) * i as f64 / 399.0;
            assert!(db2(fr) < -83.0, "q {q} at {fr}: {}", db2(fr));
        }
        for i in 0..400 {
            let fr = 0.8 * nyq_out * i as f64 / 399.0;
            assert!(
                db2(fr) > -0.1 - 1e-9 && db2(fr) < 1e-9,
                "q {q} at {fr}: {}",
                db2(fr)
            );
        }
    }
    // An out-of-band tone is removed, an in-band one kept (amplitude within the ripple).
    let n = 20_000;
    let q = 4;
    let mk = |fr: f64| -> Log {
        let x: Vec<f64> = (0..n)
            .map(|k| (2.0 * std::f64::consts::PI * fr * k as f64).sin())
            .collect();
        Log {
            path: "tone".into(),
            ts: 1.0,
            inputs: vec![Channel {
                name: "u".into(),
                data: x.clone(),
            }],
            outputs: vec![Channel {
                name: "y".into(),
                data: x,
            }],
            warnings: vec![],
        }
    };
    // Amplitude of the tone at `fr_out` cycles per output sample, by projection over the
    // central 4000 output samples (an integer number of periods for the frequencies used).
    let amp = |l: &Log, fr_out: f64| {
        let x = &l.u()[500..4500];
        let (mut c, mut s) = (0.0, 0.0);
        for (k, v) in x.iter().enumerate() {
            let ph = 2.0 * std::f64::consts::PI * fr_out * (k + 500) as f64;
            c += v * ph.cos();
            s += v * ph.sin();
        }
        2.0 * (c * c + s * s).sqrt() / x.len() as f64
    };
    let (lo, _) = preprocess(&mk(0.05), &[Step::Decimate { factor: q }]).unwrap();
    let a_lo = amp(&lo, 0.05 * q as f64);
    assert!((20.0 * a_lo.log10()).abs() < 0.1 + 1e-6, "{a_lo}");
    // 0.2 cycles/sample is above fs_out/2 = 0.125 (input units): it would alias to
    // 1 - 0.8 = 0.2 cycles per output sample, where the in-band tone sits.
    let (hi, _) = preprocess(&mk(0.2), &[Step::Decimate { factor: q }]).unwrap();
    let a_hi = amp(&hi, 0.05 * q as f64);
    assert!(20.0 * a_hi.log10() < -83.0, "{a_hi}");
}

#[test]
fn bad_inputs() {
    let e = preprocess(&log(100), &[Step::Decimate { factor: 1 }]).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument(_)), "{e:?}");
    let e = preprocess(&log(27), &[Step::Decimate { factor: 2 }]).unwrap_err();
    match e {
        Error::Data { file, msg } => {
            assert!(file.ends_with("run1.csv"));
            assert!(msg.contains("27"), "{msg}");
        }
        other => panic!("{other:?}"),
    }
    // 40 samples decimated by 30 leaves 2: allowed; by 40 leaves 1: refused.
    assert!(preprocess(&log(40), &[Step::Decimate { factor: 30 }]).is_ok());
    assert!(preprocess(&log(40), &[Step::Decimate { factor: 40 }]).is_err());
    let e = preprocess(&log(1), &[Step::RemoveTrend]).unwrap_err();
    assert!(matches!(e, Error::Data { .. }));
    // No steps: identity with an empty record.
    let (same, rec) = preprocess(&log(10), &[]).unwrap();
    assert_eq!(same, log(10));
    assert!(rec.steps.is_empty());
}
