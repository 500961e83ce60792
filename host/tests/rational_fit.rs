//! Sanathanan–Koerner discrete rational fit against closed-form transfer functions.
//!
//! References are written here as explicit polynomials in q = z⁻¹ and evaluated directly,
//! independently of the fit code; tolerances are stated per test.
use ferrosid::rational_fit::{
    fit_discrete_rational, fit_discrete_rational_delay_search, RationalFitOptions,
};
use ferrosid::Error;
use ferrosid_sim::rng::Rng;
use num_complex::Complex64;
use std::f64::consts::PI;

const TS: f64 = 1e-3;

/// H(q) = q^nk (b0 + b1 q + ...) / (1 + a1 q + ...), q = e^{-j2πf·TS}.
fn tf(a: &[f64], b: &[f64], nk: usize, f: f64) -> Complex64 {
    let q = Complex64::from_polar(1.0, -2.0 * PI * f * TS);
    let mut num = Complex64::new(0.0, 0.0);
    let mut qi = q.powu(nk as u32);
    for &bi in b {
        num += bi * qi;
        qi *= q;
    }
    let mut den = Complex64::new(1.0, 0.0);
    let mut qa = q;
    for &ai in &a[1..] {
        den += ai * qa;
        qa *= q;
    }
    num / den
}

/// A lightly damped resonance at 25 Hz (ζ = 0.1) sampled at 1 kHz: poles r·e^{±jθ}.
fn resonance() -> (Vec<f64>, Vec<f64>) {
    let w = 2.0 * PI * 25.0;
    let r = (-0.1 * w * TS).exp();
    let th = w * TS * (1.0f64 - 0.01).sqrt();
    (vec![1.0, -2.0 * r * th.cos(), r * r], vec![0.0122, 0.0118])
}

fn grid(n: usize, f_hi: f64) -> Vec<f64> {
    (1..=n).map(|k| k as f64 * f_hi / n as f64).collect()
}

#[test]
fn exact_data_recovers_the_coefficients() {
    let (a, b) = resonance();
    let f = grid(120, 240.0);
    let h: Vec<Complex64> = f.iter().map(|&x| tf(&a, &b, 1, x)).collect();
    let fit = fit_discrete_rational(&f, &h, None, TS, &RationalFitOptions::new(2, 1, 1)).unwrap();
    // Noise-free data of the same structure: coefficients to 1e-9 (conditioning of the
    // monomial basis with poles near z = 1 costs a few digits).
    for (x, y) in fit.a.iter().zip(&a) {
        assert!((x - y).abs() < 1e-9, "a: {:?} vs {:?}", fit.a, a);
    }
    for (x, y) in fit.b.iter().zip(&b) {
        assert!((x - y).abs() < 1e-9, "b: {:?} vs {:?}", fit.b, b);
    }
    assert!(fit.converged && fit.max_rel_error < 1e-8);
    // The state-space form has the same response.
    let ss = fit.state_space().unwrap();
    for &x in &[3.0, 25.0, 100.0] {
        let g = ss.freq_response_siso(x).unwrap();
        assert!((g - tf(&a, &b, 1, x)).norm() < 1e-8 * g.norm());
    }
}

#[test]
fn delay_search_finds_the_transport_delay() {
    let (a, b) = resonance();
    let f = grid(100, 200.0);
    // Plant with 3 extra samples of delay: numerator starts at q^4.
    let h: Vec<Complex64> = f.iter().map(|&x| tf(&a, &b, 4, x)).collect();
    let fit = fit_discrete_rational_delay_search(
        &f,
        &h,
        None,
        TS,
        &RationalFitOptions::new(2, 1, 1),
        0..=8,
    )
    .unwrap();
    assert_eq!(fit.options.nk, 4);
    assert!(fit.max_rel_error < 1e-8);
}

#[test]
fn noisy_data_gives_a_close_model() {
    let (a, b) = resonance();
    let f = grid(128, 250.0);
    let mut rng = Rng::new(0x9E37_79B9_7F4A_7C15);
    // 1 % relative complex noise (uniform, RMS 0.58 % per component).
    let h: Vec<Complex64> = f
        .iter()
        .map(|&x| {
            tf(&a, &b, 1, x)
                * Complex64::new(
                    1.0 + 0.02 * (rng.uniform() - 0.5),
                    0.02 * (rng.uniform() - 0.5),
                )
        })
        .collect();
    let fit = fit_discrete_rational(&f, &h, None, TS, &RationalFitOptions::new(2, 1, 1)).unwrap();
    // The model (not the data) must be within 0.5 % of the truth everywhere on the grid:
    // 128 points average the 1 % noise down.
    let worst = f
        .iter()
        .map(|&x| (fit.response_hz(x) - tf(&a, &b, 1, x)).norm() / tf(&a, &b, 1, x).norm())
        .fold(0.0f64, f64::max);
    assert!(worst < 5e-3, "worst model error {worst}");
    // The residual reflects the noise level (RMS of |noise| ~ 0.8 %).
    assert!(
        fit.rms_rel_error > 3e-3 && fit.rms_rel_error < 1.5e-2,
        "{}",
        fit.rms_rel_error
    );
}

#[test]
fn unstable_fit_is_an_error_not_a_model() {
    // Data of an unstable plant (poles at |z| = 1.02): the fit finds them and must refuse.
    let a = [1.0, -2.0 * 1.02 * 0.1f64.cos(), 1.02 * 1.02];
    let b = [0.01, 0.01];
    let f = grid(60, 200.0);
    let h: Vec<Complex64> = f.iter().map(|&x| tf(&a, &b, 1, x)).collect();
    match fit_discrete_rational(&f, &h, None, TS, &RationalFitOptions::new(2, 1, 1)) {
        Err(Error::Numerical(m)) => assert!(m.contains("unstable"), "{m}"),
        other => panic!("expected an unstable-fit error, got {other:?}"),
    }
}

#[test]
fn rank_deficient_regression_is_an_error() {
    // Every point at the same frequency: one complex equation cannot fix 4 coefficients.
    let (a, b) = resonance();
    let f = vec![20.0; 5];
    let h: Vec<Complex64> = f.iter().map(|&x| tf(&a, &b, 1, x)).collect();
    match fit_discrete_rational(&f, &h, None, TS, &RationalFitOptions::new(2, 1, 1)) {
        Err(Error::Numerical(m)) => assert!(m.contains("rank deficient"), "{m}"),
        other => panic!("expected rank deficiency, got {other:?}"),
    }
}

#[test]
fn bad_input_is_named() {
    let (a, b) = resonance();
    let f = grid(20, 200.0);
    let h: Vec<Complex64> = f.iter().map(|&x| tf(&a, &b, 1, x)).collect();
    let o = RationalFitOptions::new(2, 1, 1);
    let err = |f: &[f64], h: &[Complex64], w: Option<&[f64]>, ts: f64, o: &RationalFitOptions| {
        match fit_discrete_rational(f, h, w, ts, o) {
            Err(Error::InvalidArgument(m)) => m,
            other => panic!("expected InvalidArgument, got {other:?}"),
        }
    };
    assert!(err(&f[..19], &h, None, TS, &o).contains("19 frequencies but 20"));
    let mut hn = h.clone();
    hn[3] = Complex64::new(f64::NAN, 0.0);
    assert!(err(&f, &hn, None, TS, &o).contains("response 3"));
    hn[3] = Complex64::new(0.0, 0.0);
    assert!(err(&f, &hn, None, TS, &o).contains("non-zero"));
    let mut fb = f.clone();
    fb[7] = 500.0;
    assert!(err(&fb, &h, None, TS, &o).contains("frequency 7"));
    assert!(err(&f, &h, None, 0.0, &o).contains("sample time"));
    assert!(err(&f, &h, None, TS, &RationalFitOptions::new(0, 1, 1)).contains("na"));
    assert!(err(&f[..2], &h[..2], None, TS, &o).contains("cannot determine"));
    let w = vec![1.0; 20];
    let mut wb = w.clone();
    wb[2] = -1.0;
    assert!(err(&f, &h, Some(&wb), TS, &o).contains("weight 2"));
    assert!(err(&f, &h, Some(&w[..3]), TS, &o).contains("3 weights"));
}
