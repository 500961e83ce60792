//! Property tests of issue 10: scale invariance of the spectra and of N4SID, permutation of
//! equal channels, and idempotent re-reads of logs. Inputs are random (proptest, seeded by its
//! own runner; failures are shrunk and reported with the case).
use ferrosid::cli::frf::{estimate, DetrendArg, EtfeArgs, WindowArg};
use ferrosid::io::{read_csv, CsvOptions};
use ferrosid::n4sid::{n4sid, N4sidOptions, OrderSelection};
use ferrosid::spectral::Welch;
use ferrosid::{Channel, Log};
use ferrosid_sim::rng::Rng;
use proptest::prelude::*;
use std::fmt::Write as _;

/// White-noise input through y[k] = a·y[k−1] + u[k−1], plus a little output noise, from a
/// stream of the workspace's seeded generator (`ferrosid_sim::rng`) seeded with `seed`.
fn signals(seed: u64, n: usize, a: f64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let mut next = move || rng.uniform() - 0.5;
    let u: Vec<f64> = (0..n).map(|_| next()).collect();
    let mut y = vec![0.0; n];
    for k in 1..n {
        y[k] = a * y[k - 1] + u[k - 1];
    }
    for v in &mut y {
        *v += 0.01 * next();
    }
    (u, y)
}

fn log_of(u: Vec<f64>, outputs: Vec<(String, Vec<f64>)>, ts: f64) -> Log {
    Log {
        path: "prop.csv".into(),
        ts,
        inputs: vec![Channel {
            name: "u".into(),
            data: u,
        }],
        outputs: outputs
            .into_iter()
            .map(|(name, data)| Channel { name, data })
            .collect(),
        warnings: Vec::new(),
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Scaling the input by 10^eu and the output by 10^ey (up to 1e±300) leaves the coherence
    /// unchanged and scales H by 10^(ey − eu).
    #[test]
    fn welch_is_scale_invariant(seed in any::<u64>(), eu in -300i32..300, ey in -300i32..300) {
        let (u, y) = signals(seed, 2048, 0.8);
        // H itself must be representable: |H| ~ 1..5 times 10^(ey − eu).
        prop_assume!((ey - eu).abs() <= 300);
        let base = Welch::new(128).etfe(&u, &y, 1000.0).unwrap();
        let (gu, gy) = (10f64.powi(eu), 10f64.powi(ey));
        let us: Vec<f64> = u.iter().map(|v| v * gu).collect();
        let ys: Vec<f64> = y.iter().map(|v| v * gy).collect();
        let e = Welch::new(128).etfe(&us, &ys, 1000.0).unwrap();
        for k in 1..base.h.len() {
            prop_assert!((e.coherence[k] - base.coherence[k]).abs() < 1e-9,
                "bin {k}: {} vs {}", e.coherence[k], base.coherence[k]);
            let expect = base.h[k] * (gy / gu);
            prop_assert!((e.h[k] - expect).norm() <= 1e-9 * expect.norm(),
                "bin {k}: {} vs {}", e.h[k], expect);
            prop_assert_eq!(e.gate(0.85)[k], base.gate(0.85)[k]);
        }
    }

    /// N4SID finds the same pole whatever the signals' scale.
    #[test]
    fn n4sid_pole_is_scale_invariant(seed in any::<u64>(), eu in -300i32..300, ey in -300i32..300) {
        // The model's gain (D, C·B) must be representable: 10^(ey − eu) within f64.
        prop_assume!((ey - eu).abs() <= 300);
        let (u, y) = signals(seed, 1500, 0.9);
        let opts = N4sidOptions { block_rows: 8, order: OrderSelection::Fixed(1), ..N4sidOptions::default() };
        let p0 = n4sid(&log_of(u.clone(), vec![("y".into(), y.clone())], 1e-3), &opts)
            .unwrap().model.poles().unwrap()[0].re;
        let (gu, gy) = (10f64.powi(eu), 10f64.powi(ey));
        let us: Vec<f64> = u.iter().map(|v| v * gu).collect();
        let ys: Vec<f64> = y.iter().map(|v| v * gy).collect();
        let p = n4sid(&log_of(us, vec![("y".into(), ys)], 1e-3), &opts)
            .unwrap().model.poles().unwrap()[0].re;
        prop_assert!((p - p0).abs() < 1e-6, "pole {p} vs {p0}");
    }

    /// Permuting output channels permutes the estimates and changes nothing else; two equal
    /// channels give bit-identical estimates.
    #[test]
    fn permuted_equal_channels_give_equal_estimates(seed in any::<u64>()) {
        let (u, y) = signals(seed, 1024, 0.5);
        let y2: Vec<f64> = y.iter().map(|v| 3.0 * v).collect();
        let etfe = EtfeArgs {
            nperseg: "auto".into(),
            overlap: None,
            window: WindowArg::Hann,
            detrend: DetrendArg::Constant,
            period: None,
            skip_periods: 0,
            gate: 0.85,
        };
        let a = estimate(&[log_of(u.clone(), vec![("y".into(), y.clone()), ("y2".into(), y2.clone()), ("copy".into(), y.clone())], 1e-3)], &etfe).unwrap();
        let b = estimate(&[log_of(u, vec![("copy".into(), y.clone()), ("y2".into(), y2), ("y".into(), y)], 1e-3)], &etfe).unwrap();
        for ea in &a.estimates {
            let eb = b.estimates.iter().find(|e| e.output == ea.output).unwrap();
            prop_assert_eq!(&ea.re, &eb.re);
            prop_assert_eq!(&ea.im, &eb.im);
            prop_assert_eq!(&ea.coherence, &eb.coherence);
        }
        let (y_est, copy) = (&a.estimates[0], &a.estimates[2]);
        prop_assert_eq!(&y_est.re, &copy.re);
        prop_assert_eq!(&y_est.coherence, &copy.coherence);
    }

    /// Writing a log as CSV with full precision and reading it back is the identity, and a
    /// second write/read cycle gives the same bytes and the same log.
    #[test]
    fn csv_re_reads_are_idempotent(seed in any::<u64>(), n in 2usize..200, e in -300i32..300) {
        let (u, y) = signals(seed, n, 0.7);
        let g = 10f64.powi(e);
        let write = |u: &[f64], y: &[f64], ts: f64| {
            let mut t = String::from("t,u,y\n");
            for k in 0..u.len() {
                let _ = writeln!(t, "{:e},{:e},{:e}", k as f64 * ts, u[k], y[k]);
            }
            t
        };
        let dir = std::env::temp_dir().join(format!("ferrosid-prop-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(format!("re-read-{seed}-{n}.csv"));
        let us: Vec<f64> = u.iter().map(|v| v * g).collect();
        let ys: Vec<f64> = y.iter().map(|v| v * g).collect();
        let text = write(&us, &ys, 1e-3);
        std::fs::write(&p, &text).unwrap();
        let a = read_csv(&p, &CsvOptions::default()).unwrap();
        prop_assert_eq!(&a.inputs[0].data, &us);
        prop_assert_eq!(&a.outputs[0].data, &ys);
        let text2 = write(&a.inputs[0].data, &a.outputs[0].data, 1e-3);
        prop_assert_eq!(&text, &text2);
        std::fs::write(&p, &text2).unwrap();
        let b = read_csv(&p, &CsvOptions::default()).unwrap();
        prop_assert_eq!(&a, &b);
        let _ = std::fs::remove_file(&p);
    }
}
