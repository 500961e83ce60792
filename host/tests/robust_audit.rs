//! Nonlinearity audit on synthetic FRFs with known shifts.
use ferrosid::robust::audit::{audit_nonlinearity, AuditOptions, FrfRun, Verdict};
use ferrosid::robust::norms::logspace;
use num_complex::Complex64;
use std::f64::consts::PI;

fn base(f: &[f64]) -> Vec<Complex64> {
    // A lightly damped second-order plant with a resonance at 30 Hz.
    f.iter()
        .map(|&f| {
            let s = Complex64::new(0.0, 2.0 * PI * f);
            let wn = 2.0 * PI * 30.0;
            wn * wn / (s * s + 2.0 * 0.1 * wn * s + wn * wn)
        })
        .collect()
}

fn run(label: &str, amp: f64, f: &[f64], h: Vec<Complex64>, coh: Vec<f64>) -> FrfRun {
    FrfRun {
        label: label.into(),
        amplitude: amp,
        freq_hz: f.to_vec(),
        h,
        coherence: coh,
    }
}

/// Multiplies h by 10^(db/20)·e^{j deg} at bins with lo <= f <= hi.
fn perturb(f: &[f64], h: &[Complex64], lo: f64, hi: f64, db: f64, deg: f64) -> Vec<Complex64> {
    f.iter()
        .zip(h)
        .map(|(&fi, &hi_)| {
            if fi >= lo && fi <= hi {
                hi_ * Complex64::from_polar(10f64.powf(db / 20.0), deg.to_radians())
            } else {
                hi_
            }
        })
        .collect()
}

#[test]
fn identical_runs_pass() {
    let f = logspace(0.5, 500.0, 301);
    let h = base(&f);
    let a = run("low", 0.1, &f, h.clone(), vec![0.99; f.len()]);
    let b = run("high", 1.0, &f, h, vec![0.97; f.len()]);
    let r = audit_nonlinearity(&[a, b], &AuditOptions::new(10.0)).unwrap();
    assert_eq!(r.verdict, Verdict::LinearEnough);
    assert!(r.reasons.is_empty() && r.shift_bands.is_empty() && r.coherence_drops.is_empty());
    assert_eq!(r.worst_gain_shift_db.value, 0.0);
    assert_eq!(r.worst_phase_shift_deg.value, 0.0);
    let n_in = f.iter().filter(|&&x| (1.0..=100.0).contains(&x)).count();
    assert_eq!(r.bins_examined, n_in);
}

#[test]
fn known_gain_and_phase_shifts_are_located() {
    let f = logspace(0.5, 500.0, 301);
    let h = base(&f);
    // +4 dB in 8–12 Hz, −20° in 50–60 Hz, +10 dB at 200–300 Hz (outside the decade band).
    let hb = perturb(&f, &h, 8.0, 12.0, 4.0, 0.0);
    let hb = perturb(&f, &hb, 50.0, 60.0, 0.0, -20.0);
    let hb = perturb(&f, &hb, 200.0, 300.0, 10.0, 0.0);
    let a = run("0.1 A", 0.1, &f, h, vec![0.99; f.len()]);
    let b = run("1 A", 1.0, &f, hb, vec![0.99; f.len()]);
    let r = audit_nonlinearity(&[a, b], &AuditOptions::new(10.0)).unwrap();
    assert_eq!(r.verdict, Verdict::NotLinear);
    assert_eq!(r.shift_bands.len(), 2, "{:?}", r.shift_bands);
    let g = &r.shift_bands[0];
    let in_g: Vec<f64> = f
        .iter()
        .copied()
        .filter(|&x| (8.0..=12.0).contains(&x))
        .collect();
    assert_eq!(g.bins, in_g.len());
    assert_eq!(g.f_lo_hz, in_g[0]);
    assert_eq!(g.f_hi_hz, *in_g.last().unwrap());
    assert!((g.worst_gain_shift_db.value - 4.0).abs() < 1e-9);
    assert_eq!(
        (
            g.worst_gain_shift_db.run_a.as_str(),
            g.worst_gain_shift_db.run_b.as_str()
        ),
        ("0.1 A", "1 A")
    );
    let p = &r.shift_bands[1];
    assert!(p.f_lo_hz >= 50.0 && p.f_hi_hz <= 60.0);
    assert!((p.worst_phase_shift_deg.value + 20.0).abs() < 1e-9);
    assert!((r.worst_phase_shift_deg.value + 20.0).abs() < 1e-9);
    // The 10 dB shift at 200–300 Hz lies outside 1–100 Hz and is not reported.
    assert!((r.worst_gain_shift_db.value - 4.0).abs() < 1e-9);
    assert_eq!(r.reasons.len(), 2);
}

#[test]
fn shifts_below_threshold_pass_and_thresholds_are_configurable() {
    let f = logspace(0.5, 500.0, 301);
    let h = base(&f);
    let hb = perturb(&f, &h, 5.0, 20.0, 2.0, 10.0);
    let a = run("a", 0.1, &f, h.clone(), vec![0.9; f.len()]);
    let b = run("b", 1.0, &f, hb, vec![0.9; f.len()]);
    let r = audit_nonlinearity(&[a.clone(), b.clone()], &AuditOptions::new(10.0)).unwrap();
    assert_eq!(r.verdict, Verdict::LinearEnough);
    assert!((r.worst_gain_shift_db.value - 2.0).abs() < 1e-9);
    assert!((r.worst_phase_shift_deg.value - 10.0).abs() < 1e-9);
    let mut o = AuditOptions::new(10.0);
    o.max_gain_shift_db = 1.5;
    let r = audit_nonlinearity(&[a.clone(), b.clone()], &o).unwrap();
    assert_eq!(r.verdict, Verdict::NotLinear);
    let mut o = AuditOptions::new(10.0);
    o.max_phase_shift_deg = 8.0;
    assert_eq!(
        audit_nonlinearity(&[a, b], &o).unwrap().verdict,
        Verdict::NotLinear
    );
}

#[test]
fn worst_pair_among_three_runs() {
    let f = logspace(1.0, 100.0, 101);
    let h = base(&f);
    let runs = vec![
        run("a", 0.1, &f, h.clone(), vec![0.95; f.len()]),
        run(
            "b",
            0.5,
            &f,
            perturb(&f, &h, 9.0, 11.0, 2.0, 0.0),
            vec![0.95; f.len()],
        ),
        run(
            "c",
            1.0,
            &f,
            perturb(&f, &h, 9.0, 11.0, -2.5, 0.0),
            vec![0.95; f.len()],
        ),
    ];
    let r = audit_nonlinearity(&runs, &AuditOptions::new(10.0)).unwrap();
    // b vs c differ by 4.5 dB: the worst pair.
    assert_eq!(r.verdict, Verdict::NotLinear);
    let w = &r.worst_gain_shift_db;
    assert!((w.value.abs() - 4.5).abs() < 1e-9, "{w:?}");
    assert_eq!((w.run_a.as_str(), w.run_b.as_str()), ("b", "c"));
}

#[test]
fn coherence_drop_near_crossover_is_reported() {
    let f = logspace(0.5, 500.0, 301);
    let h = base(&f);
    let mut coh = vec![0.95; f.len()];
    let mut coh_far = coh.clone();
    for (i, &fi) in f.iter().enumerate() {
        if (11.0..=13.0).contains(&fi) {
            coh[i] = 0.4;
        }
        if (50.0..=60.0).contains(&fi) {
            coh_far[i] = 0.3; // outside the 3.33–30 Hz coherence window
        }
    }
    let a = run("a", 0.1, &f, h.clone(), coh);
    let b = run("b", 1.0, &f, h.clone(), vec![0.95; f.len()]);
    let r = audit_nonlinearity(&[a, b], &AuditOptions::new(10.0)).unwrap();
    assert_eq!(r.verdict, Verdict::NotLinear);
    assert_eq!(r.coherence_drops.len(), 1);
    let d = &r.coherence_drops[0];
    assert_eq!(d.min_coherence, 0.4);
    assert_eq!(d.run, "a");
    assert!(d.f_lo_hz >= 11.0 && d.f_hi_hz <= 13.0);
    let a = run("a", 0.1, &f, h.clone(), coh_far);
    let b = run("b", 1.0, &f, h, vec![0.95; f.len()]);
    assert_eq!(
        audit_nonlinearity(&[a, b], &AuditOptions::new(10.0))
            .unwrap()
            .verdict,
        Verdict::LinearEnough
    );
}

#[test]
fn bad_inputs_are_clear_errors() {
    let f = logspace(1.0, 100.0, 50);
    let h = base(&f);
    let good = run("a", 0.1, &f, h.clone(), vec![0.9; 50]);
    let o = AuditOptions::new(10.0);
    let err =
        |runs: &[FrfRun], o: &AuditOptions| audit_nonlinearity(runs, o).unwrap_err().to_string();
    assert!(err(std::slice::from_ref(&good), &o).contains("at least 2 runs"));
    let f2 = logspace(1.0, 120.0, 50);
    assert!(err(
        &[good.clone(), run("b", 1.0, &f2, h.clone(), vec![0.9; 50])],
        &o
    )
    .contains("different frequency grid"));
    // A NaN response (no input power at that bin) is skipped and counted, not compared.
    let mut nan = h.clone();
    nan[3] = Complex64::new(f64::NAN, 0.0);
    let r = audit_nonlinearity(&[good.clone(), run("b", 1.0, &f, nan, vec![0.9; 50])], &o).unwrap();
    assert_eq!(r.bins_skipped, 1);
    let in_band = f.iter().filter(|&&x| (1.0..=100.0).contains(&x)).count();
    assert_eq!(r.bins_examined, in_band - 1);
    assert_eq!(r.verdict, Verdict::LinearEnough);
    let all_nan = vec![Complex64::new(f64::NAN, 0.0); 50];
    assert!(err(
        &[good.clone(), run("b", 1.0, &f, all_nan, vec![0.9; 50])],
        &o
    )
    .contains("no usable"));
    let mut badf = f.clone();
    badf[4] = f64::NAN;
    assert!(err(
        &[
            run("a", 0.1, &badf, h.clone(), vec![0.9; 50]),
            run("b", 1.0, &badf, h.clone(), vec![0.9; 50])
        ],
        &o
    )
    .contains("frequency bin 4"));
    let mut c = vec![0.9; 50];
    c[7] = 1.5;
    assert!(
        err(&[good.clone(), run("b", 1.0, &f, h.clone(), c)], &o).contains("coherence at bin 7")
    );
    assert!(err(
        &[good.clone(), run("b", 1.0, &f, h.clone(), vec![0.9; 49])],
        &o
    )
    .contains("must agree"));
    assert!(err(&[good.clone(), good.clone()], &AuditOptions::new(1e5)).contains("no usable"));
    let mut z = h.clone();
    z[20] = Complex64::new(0.0, 0.0);
    assert!(err(&[good.clone(), run("b", 1.0, &f, z, vec![0.9; 50])], &o).contains("exactly zero"));
    let mut bo = o;
    bo.band_factor = 1.0;
    assert!(err(&[good.clone(), good.clone()], &bo).contains("band_factor"));
    bo = o;
    bo.min_coherence = 2.0;
    assert!(err(&[good.clone(), good], &bo).contains("min_coherence"));
}
