//! Preprocessing against scipy: anti-aliasing filter design (scipy.signal.cheby1 sos), decimation
//! (scipy.signal.decimate, default IIR zero-phase) and linear detrending (scipy.signal.detrend).
//! Reference: tests/fixtures/preprocess_scipy_decimate.json from tests/ref/scipy_decimate.py
//! (scipy 1.17.1). Tolerances: sos coefficients 1e-12 relative to the section's largest;
//! decimated samples 1e-9 relative to max |y|; detrended samples 1e-12 relative to max |x|.
use ferrosid::preprocess::{preprocess, AntiAlias, Step, StepRecord};
use ferrosid::{Channel, Log};
use serde::Deserialize;

#[derive(Deserialize)]
struct Case {
    q: usize,
    sos: Vec<Vec<f64>>,
    y: Vec<f64>,
}

#[derive(Deserialize)]
struct Fixture {
    x: Vec<f64>,
    cases: Vec<Case>,
    detrend_linear: Vec<f64>,
    line_offset: f64,
    line_slope_per_sample: f64,
}

fn load() -> Fixture {
    let p = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/preprocess_scipy_decimate.json"
    );
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

fn log_of(x: &[f64], ts: f64) -> Log {
    // Input: the signal; output: its negative plus 1 (so both channels are processed).
    Log {
        path: "fixture.csv".into(),
        ts,
        inputs: vec![Channel {
            name: "u".into(),
            data: x.to_vec(),
        }],
        outputs: vec![Channel {
            name: "y".into(),
            data: x.iter().map(|v| 1.0 - v).collect(),
        }],
        warnings: vec!["carried".into()],
    }
}

#[test]
fn filter_design_matches_scipy_cheby1() {
    let fx = load();
    for c in &fx.cases {
        let ours = AntiAlias::design(c.q);
        assert_eq!(ours.sos.len(), c.sos.len());
        for (s, r) in ours.sos.iter().zip(&c.sos) {
            let scale = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for i in 0..6 {
                assert!(
                    (s[i] - r[i]).abs() <= 1e-12 * scale,
                    "q {}: {s:?} vs {r:?}",
                    c.q
                );
            }
        }
    }
}

#[test]
fn decimation_matches_scipy_decimate() {
    let fx = load();
    for c in &fx.cases {
        let (out, rec) =
            preprocess(&log_of(&fx.x, 1e-3), &[Step::Decimate { factor: c.q }]).unwrap();
        assert_eq!(out.len(), c.y.len(), "q {}", c.q);
        let top = c.y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = out
            .u()
            .iter()
            .zip(&c.y)
            .map(|(a, b)| (a - b).abs() / top)
            .fold(0.0, f64::max);
        eprintln!("q {}: max relative deviation from scipy {worst:.2e}", c.q);
        assert!(worst < 1e-9, "q {}: {worst}", c.q);
        // The output channel (1 - x) decimates to 1*g_dc - y: linearity check on the other channel.
        let g_dc = AntiAlias::design(c.q).response(0.0).norm().powi(2);
        for (a, b) in out.y().iter().zip(&c.y) {
            assert!((a - (g_dc - b)).abs() < 1e-9 * top);
        }
        assert!((out.ts - 1e-3 * c.q as f64).abs() < 1e-15);
        assert_eq!(out.warnings, vec!["carried".to_string()]);
        match &rec.steps[0] {
            StepRecord::Decimate {
                factor,
                samples_in,
                samples_out,
                fs_out_hz,
                passband_edge_hz,
                ..
            } => {
                assert_eq!(*factor, c.q);
                assert_eq!(*samples_in, fx.x.len());
                assert_eq!(*samples_out, c.y.len());
                assert!((fs_out_hz - 1000.0 / c.q as f64).abs() < 1e-9);
                assert!((passband_edge_hz - 400.0 / c.q as f64).abs() < 1e-9);
            }
            other => panic!("{other:?}"),
        }
    }
}

#[test]
fn trend_removal_matches_scipy_detrend() {
    let fx = load();
    let ts = 0.002;
    let (out, rec) = preprocess(&log_of(&fx.x, ts), &[Step::RemoveTrend]).unwrap();
    let top = fx.x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (a, b) in out.u().iter().zip(&fx.detrend_linear) {
        assert!((a - b).abs() < 1e-12 * top, "{a} vs {b}");
    }
    match &rec.steps[0] {
        StepRecord::RemoveTrend { channels } => {
            assert_eq!(channels[0].channel, "u");
            assert!((channels[0].offset - fx.line_offset).abs() < 1e-10);
            assert!((channels[0].slope_per_s - fx.line_slope_per_sample / ts).abs() < 1e-9);
            // Output channel is 1 - x: offset 1 - c, slope -m.
            assert!((channels[1].offset - (1.0 - fx.line_offset)).abs() < 1e-10);
            assert!((channels[1].slope_per_s + fx.line_slope_per_sample / ts).abs() < 1e-9);
        }
        other => panic!("{other:?}"),
    }
}
