//! LTI model algebra against closed forms: first- and second-order responses, ZOH
//! discretisation, matrix exponential/logarithm identities, companion-form poles,
//! interconnections checked pointwise against complex matrix algebra written here.
use faer::linalg::solvers::Solve;
use faer::Mat;
use ferrosid::lti::{
    expm, logm, poly_from_roots, poly_mul, StateSpace, StateSpaceData, TransferFunction,
};
use ferrosid::Error;
use ferrosid_sim::rng::Rng;
use num_complex::Complex64;
use std::f64::consts::PI;

/// Matrix of uniform entries in [−1, 1) from the workspace's seeded generator.
fn random_mat(rng: &mut Rng, r: usize, c: usize) -> Mat<f64> {
    Mat::from_fn(r, c, |_, _| 2.0 * rng.uniform() - 1.0)
}

fn c(re: f64, im: f64) -> Complex64 {
    Complex64::new(re, im)
}

fn mat(rows: &[&[f64]]) -> Mat<f64> {
    Mat::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
}

/// ω_n²/(s² + 2ζω_n s + ω_n²) in physical form, x = [position; velocity].
fn mode(wn: f64, zeta: f64) -> StateSpace {
    StateSpace::new(
        mat(&[&[0.0, 1.0], &[-wn * wn, -2.0 * zeta * wn]]),
        mat(&[&[0.0], &[wn * wn]]),
        mat(&[&[1.0, 0.0]]),
        mat(&[&[0.0]]),
        0.0,
    )
    .unwrap()
}

fn max_abs_diff(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
    assert_eq!((a.nrows(), a.ncols()), (b.nrows(), b.ncols()));
    let mut m = 0.0f64;
    for i in 0..a.nrows() {
        for j in 0..a.ncols() {
            m = m.max((a[(i, j)] - b[(i, j)]).abs());
        }
    }
    m
}

/// A random stable continuous model: A = −(I·shift) + small random part.
fn random_stable_continuous(rng: &mut Rng, n: usize, m: usize, p: usize) -> StateSpace {
    let mut a = random_mat(rng, n, n);
    for i in 0..n {
        a[(i, i)] -= 2.5;
    }
    StateSpace::new(
        a,
        random_mat(rng, n, m),
        random_mat(rng, p, n),
        random_mat(rng, p, m),
        0.0,
    )
    .unwrap()
}

#[test]
fn first_order_lag_frequency_response_matches_closed_form() {
    let (k, tau) = (2.5, 0.04);
    let tf = TransferFunction::new(vec![k], vec![tau, 1.0], 0.0).unwrap();
    let ss = tf.to_state_space().unwrap();
    for &f in &[0.0, 0.1, 1.0, 3.97, 10.0, 100.0, 1e4] {
        let w = 2.0 * PI * f;
        let exact = c(k, 0.0) / c(1.0, w * tau);
        let g_ss = ss.freq_response_siso(f).unwrap();
        let g_tf = tf.freq_response_hz(f).unwrap();
        assert!(
            (g_ss - exact).norm() <= 1e-12 * exact.norm(),
            "f={f}: {g_ss} vs {exact}"
        );
        assert!((g_tf - exact).norm() <= 1e-12 * exact.norm());
    }
}

#[test]
fn second_order_mode_response_matches_closed_form() {
    let (wn, zeta) = (2.0 * PI * 50.0, 0.02);
    let ss = mode(wn, zeta);
    for &f in &[1.0, 25.0, 49.0, 50.0, 51.0, 200.0] {
        let w = 2.0 * PI * f;
        let exact = c(wn * wn, 0.0) / c(wn * wn - w * w, 2.0 * zeta * wn * w);
        let g = ss.freq_response(w).unwrap()[(0, 0)];
        assert!(
            (g - exact).norm() <= 1e-11 * exact.norm(),
            "f={f}: {g} vs {exact}"
        );
    }
    // Peak gain at wn is 1/(2ζ) = 25.
    let peak = ss.freq_response(wn).unwrap()[(0, 0)].norm();
    assert!((peak - 1.0 / (2.0 * zeta)).abs() < 1e-10);
    // Poles −ζωn ± jωn√(1−ζ²).
    let p = ss.poles().unwrap();
    let wd = wn * (1.0 - zeta * zeta).sqrt();
    assert!((p[0] - c(-zeta * wn, wd)).norm() < 1e-9 * wn);
    assert!((p[1] - c(-zeta * wn, -wd)).norm() < 1e-9 * wn);
}

#[test]
fn discrete_first_order_response_on_unit_circle() {
    let (a, b, ts) = (0.9, 0.3, 1e-3);
    let ss = StateSpace::new(
        mat(&[&[a]]),
        mat(&[&[b]]),
        mat(&[&[1.0]]),
        mat(&[&[0.0]]),
        ts,
    )
    .unwrap();
    for &f in &[0.0, 10.0, 123.4, 499.0] {
        let z = Complex64::from_polar(1.0, 2.0 * PI * f * ts);
        let exact = c(b, 0.0) / (z - a);
        let g = ss.freq_response_siso(f).unwrap();
        assert!((g - exact).norm() <= 1e-13 * exact.norm());
    }
}

#[test]
fn hessenberg_evaluator_matches_direct_complex_solve() {
    // Independent reference: dense complex LU of (jωI − A) on a random 7-state 2x3 model.
    let mut rng = Rng::new(7);
    let sys = random_stable_continuous(&mut rng, 7, 3, 2);
    for &w in &[0.0, 0.37, 1.0, 2.9, 40.0] {
        let g = sys.freq_response(w).unwrap();
        let n = 7;
        let m_c = Mat::from_fn(n, n, |i, j| {
            let d = if i == j { c(0.0, w) } else { c(0.0, 0.0) };
            d - c(sys.a[(i, j)], 0.0)
        });
        let b_c = Mat::from_fn(n, 3, |i, j| c(sys.b[(i, j)], 0.0));
        let x = m_c.partial_piv_lu().solve(&b_c);
        for i in 0..2 {
            for j in 0..3 {
                let mut r = c(sys.d[(i, j)], 0.0);
                for k in 0..n {
                    r += sys.c[(i, k)] * x[(k, j)];
                }
                assert!((g[(i, j)] - r).norm() <= 1e-12 * (1.0 + r.norm()));
            }
        }
    }
}

#[test]
fn evaluating_at_a_pole_is_an_error() {
    let integ = TransferFunction::new(vec![1.0], vec![1.0, 0.0], 0.0).unwrap();
    let ss = integ.to_state_space().unwrap();
    assert!(matches!(ss.freq_response(0.0), Err(Error::Numerical(_))));
    assert!(matches!(ss.dc_gain(), Err(Error::Numerical(_))));
    assert!(matches!(integ.dc_gain(), Err(Error::Numerical(_))));
}

#[test]
fn c2d_first_order_is_exact() {
    let (k, tau, ts) = (3.0, 0.02, 1e-3);
    let ss = StateSpace::new(
        mat(&[&[-1.0 / tau]]),
        mat(&[&[k / tau]]),
        mat(&[&[1.0]]),
        mat(&[&[0.0]]),
        0.0,
    )
    .unwrap();
    let d = ss.c2d_zoh(ts).unwrap();
    let a = (-ts / tau).exp();
    assert!((d.a[(0, 0)] - a).abs() <= 1e-15);
    assert!((d.b[(0, 0)] - (1.0 - a) * k).abs() <= 1e-14 * k);
    assert_eq!(d.ts, ts);
}

#[test]
fn c2d_step_response_equals_continuous_step_at_samples() {
    // ZOH invariance: the discrete step response equals the continuous one at t = kTs.
    let (wn, zeta, ts) = (2.0 * PI * 20.0, 0.1, 1e-3);
    let ss = mode(wn, zeta);
    let d = ss.c2d_zoh(ts).unwrap();
    let y = d.simulate_siso(&vec![1.0; 400], None).unwrap();
    let wd = wn * (1.0 - zeta * zeta).sqrt();
    for (k, yk) in y.iter().enumerate() {
        let t = k as f64 * ts;
        let exact = 1.0
            - (-zeta * wn * t).exp()
                * ((wd * t).cos() + zeta / (1.0 - zeta * zeta).sqrt() * (wd * t).sin());
        assert!((yk - exact).abs() < 1e-11, "k={k}: {yk} vs {exact}");
    }
}

#[test]
fn d2c_inverts_c2d() {
    let mut rng = Rng::new(11);
    for (n, m, p, ts) in [(4, 2, 3, 0.05), (1, 1, 1, 1e-6), (6, 1, 1, 0.2)] {
        let g = random_stable_continuous(&mut rng, n, m, p);
        let back = g.c2d_zoh(ts).unwrap().d2c_zoh().unwrap();
        let scale = 1.0 + ferrosid_norm(&g.a);
        assert!(max_abs_diff(&back.a, &g.a) <= 1e-10 * scale, "A n={n}");
        assert!(max_abs_diff(&back.b, &g.b) <= 1e-10 * scale, "B n={n}");
        assert_eq!(back.ts, 0.0);
    }
    // A lightly damped third-order plant at a fast sample rate.
    let wn = 2.0 * PI * 40.0;
    let tf = TransferFunction::new(
        vec![wn * wn * 30.0],
        poly_mul(&[1.0, 30.0], &[1.0, 2.0 * 0.02 * wn, wn * wn]),
        0.0,
    )
    .unwrap();
    let g = tf.to_state_space().unwrap();
    let back = g.c2d_zoh(1e-3).unwrap().d2c_zoh().unwrap();
    assert!(max_abs_diff(&back.a, &g.a) <= 1e-10 * ferrosid_norm(&g.a));
    assert!(max_abs_diff(&back.b, &g.b) <= 1e-10);
}

fn ferrosid_norm(a: &Mat<f64>) -> f64 {
    let mut m = 0.0f64;
    for i in 0..a.nrows() {
        for j in 0..a.ncols() {
            m = m.max(a[(i, j)].abs());
        }
    }
    m
}

#[test]
fn d2c_refuses_poles_without_real_continuous_equivalent() {
    let neg = StateSpace::new(
        mat(&[&[-0.5]]),
        mat(&[&[1.0]]),
        mat(&[&[1.0]]),
        mat(&[&[0.0]]),
        0.01,
    )
    .unwrap();
    match neg.d2c_zoh() {
        Err(Error::Numerical(msg)) => assert!(msg.contains("negative real axis"), "{msg}"),
        other => panic!("expected an error, got {other:?}"),
    }
    let zero = StateSpace::new(
        mat(&[&[0.5, 0.0], &[0.0, 0.0]]),
        mat(&[&[1.0], &[1.0]]),
        mat(&[&[1.0, 1.0]]),
        mat(&[&[0.0]]),
        0.01,
    )
    .unwrap();
    match zero.d2c_zoh() {
        Err(Error::Numerical(msg)) => assert!(msg.contains("0"), "{msg}"),
        other => panic!("expected an error, got {other:?}"),
    }
    let cont = zero.d2c_zoh();
    assert!(cont.is_err());
    // A continuous model cannot be converted again, nor discretised twice.
    let g = neg.c2d_zoh(0.1);
    assert!(matches!(g, Err(Error::InvalidArgument(_))));
}

#[test]
fn expm_known_cases() {
    // Rotation generator.
    for &th in &[0.01, 0.5, 2.0, 7.0, 40.0] {
        let e = expm(mat(&[&[0.0, th], &[-th, 0.0]]).as_ref()).unwrap();
        let exact = mat(&[&[th.cos(), th.sin()], &[-th.sin(), th.cos()]]);
        assert!(max_abs_diff(&e, &exact) <= 1e-13 * (1.0 + th), "θ={th}");
    }
    // Nilpotent: exp(N) = I + N + N²/2 + N³/6 exactly.
    let n = mat(&[
        &[0.0, 2.0, -1.0, 4.0],
        &[0.0, 0.0, 3.0, 0.5],
        &[0.0, 0.0, 0.0, -2.0],
        &[0.0, 0.0, 0.0, 0.0],
    ]);
    let n2 = &n * &n;
    let n3 = &n2 * &n;
    let exact =
        Mat::<f64>::identity(4, 4) + &n + &n2 * faer::Scale(0.5) + &n3 * faer::Scale(1.0 / 6.0);
    let e = expm(n.as_ref()).unwrap();
    assert!(max_abs_diff(&e, &exact) <= 1e-13 * ferrosid_norm(&exact));
    // Diagonalisable with known eigenvectors, across all Padé degrees (norms 1e-3 .. 60).
    let v = mat(&[&[1.0, 2.0, 0.0], &[0.0, 1.0, 1.0], &[1.0, 0.0, 1.0]]);
    let vinv = v.partial_piv_lu().solve(Mat::<f64>::identity(3, 3));
    for &s in &[1e-3, 0.05, 0.3, 1.0, 4.0, 20.0] {
        let lam: [f64; 3] = [-s, 0.5 * s, -3.0 * s];
        let dm = Mat::from_fn(3, 3, |i, j| if i == j { lam[i] } else { 0.0 });
        let de = Mat::from_fn(3, 3, |i, j| if i == j { lam[i].exp() } else { 0.0 });
        let a = &(&v * &dm) * &vinv;
        let exact = &(&v * &de) * &vinv;
        let e = expm(a.as_ref()).unwrap();
        assert!(
            max_abs_diff(&e, &exact) <= 1e-12 * ferrosid_norm(&exact),
            "scale {s}: {}",
            max_abs_diff(&e, &exact)
        );
    }
    assert!(expm(Mat::<f64>::zeros(2, 3).as_ref()).is_err());
    assert!(expm(mat(&[&[f64::NAN]]).as_ref()).is_err());
}

#[test]
fn logm_inverts_expm_and_refuses_negative_eigenvalues() {
    let mut rng = Rng::new(3);
    for n in [1, 2, 5, 8] {
        let mut a = random_mat(&mut rng, n, n);
        for i in 0..n {
            a[(i, i)] -= 1.0;
        }
        let l = logm(expm(a.as_ref()).unwrap().as_ref()).unwrap();
        assert!(
            max_abs_diff(&l, &a) <= 1e-11,
            "n={n}: {}",
            max_abs_diff(&l, &a)
        );
    }
    // Rotation by θ < π: log is the generator.
    let th: f64 = 2.5;
    let r = mat(&[&[th.cos(), th.sin()], &[-th.sin(), th.cos()]]);
    let l = logm(r.as_ref()).unwrap();
    assert!(max_abs_diff(&l, &mat(&[&[0.0, th], &[-th, 0.0]])) <= 1e-12);
    // Jordan block at 1: log([[1,1],[0,1]]) = [[0,1],[0,0]].
    let l = logm(mat(&[&[1.0, 1.0], &[0.0, 1.0]]).as_ref()).unwrap();
    assert!(max_abs_diff(&l, &mat(&[&[0.0, 1.0], &[0.0, 0.0]])) <= 1e-13);
    assert!(matches!(
        logm(mat(&[&[-2.0, 0.0], &[0.0, 1.0]]).as_ref()),
        Err(Error::Numerical(_))
    ));
}

#[test]
fn companion_form_poles_and_zeros() {
    // (s+1)(s+2)(s²+2s+5): poles −1, −2, −1±2j; numerator (s+3).
    let den = poly_mul(&poly_mul(&[1.0, 1.0], &[1.0, 2.0]), &[1.0, 2.0, 5.0]);
    assert_eq!(den, vec![1.0, 5.0, 13.0, 19.0, 10.0]);
    let tf = TransferFunction::new(vec![2.0, 6.0], den.clone(), 0.0).unwrap();
    let ss = tf.to_state_space().unwrap();
    let p = ss.poles().unwrap();
    let expected = [c(-1.0, 2.0), c(-1.0, -2.0), c(-1.0, 0.0), c(-2.0, 0.0)];
    assert_eq!(p.len(), 4);
    for (got, want) in p.iter().zip(&expected) {
        assert!((got - want).norm() < 1e-12, "{p:?}");
    }
    let z = tf.zeros().unwrap();
    assert_eq!(z.len(), 1);
    assert!((z[0] - c(-3.0, 0.0)).norm() < 1e-14);
    // DC gain 6/10; TF -> SS -> TF round trip.
    assert!((tf.dc_gain().unwrap() - 0.6).abs() < 1e-15);
    assert!((ss.dc_gain().unwrap()[(0, 0)] - 0.6).abs() < 1e-14);
    let back = ss.to_transfer_function().unwrap();
    assert_eq!(back.den.len(), 5);
    for (x, y) in back.den.iter().zip(&den) {
        assert!((x - y).abs() < 1e-12 * 19.0);
    }
    let num_back = &back.num[back.num.len() - 2..];
    assert!((num_back[0] - 2.0).abs() < 1e-12 && (num_back[1] - 6.0).abs() < 1e-12);
    assert!(back.num[..back.num.len() - 2]
        .iter()
        .all(|x| x.abs() < 1e-12));
    // poly_from_roots inverts.
    let pr = poly_from_roots(&p).unwrap();
    for (x, y) in pr.iter().zip(&den) {
        assert!((x - y).abs() < 1e-12 * 19.0);
    }
}

#[test]
fn biproper_transfer_function_realisation() {
    // (2s + 3)/(s + 1): D = 2, residue 1.
    let tf = TransferFunction::new(vec![2.0, 3.0], vec![1.0, 1.0], 0.0).unwrap();
    let ss = tf.to_state_space().unwrap();
    assert_eq!(ss.d[(0, 0)], 2.0);
    for &w in &[0.0, 1.0, 10.0] {
        let exact = c(3.0, 2.0 * w) / c(1.0, w);
        assert!((ss.freq_response(w).unwrap()[(0, 0)] - exact).norm() < 1e-14);
    }
}

#[test]
fn stability_checks_with_margin() {
    let cont = TransferFunction::new(vec![1.0], vec![1.0, 0.5], 0.0)
        .unwrap()
        .to_state_space()
        .unwrap();
    assert!(cont.is_stable(0.0).unwrap());
    assert!(cont.is_stable(0.4).unwrap());
    assert!(!cont.is_stable(0.6).unwrap());
    let disc = StateSpace::new(
        mat(&[&[0.0, 1.0], &[-0.9025, 0.0]]), // poles ±0.95j
        mat(&[&[0.0], &[1.0]]),
        mat(&[&[1.0, 0.0]]),
        mat(&[&[0.0]]),
        0.1,
    )
    .unwrap();
    assert!(disc.is_stable(0.0).unwrap());
    assert!(disc.is_stable(0.04).unwrap());
    assert!(!disc.is_stable(0.06).unwrap());
}

#[test]
fn transfer_function_bad_inputs() {
    assert!(matches!(
        TransferFunction::new(vec![1.0, 0.0, 0.0], vec![1.0, 1.0], 0.0)
            .unwrap()
            .to_state_space(),
        Err(Error::InvalidArgument(_))
    ));
    assert!(TransferFunction::new(vec![1.0], vec![0.0, 0.0], 0.0).is_err());
    assert!(TransferFunction::new(vec![], vec![1.0], 0.0).is_err());
    assert!(TransferFunction::new(vec![f64::NAN], vec![1.0], 0.0).is_err());
    assert!(TransferFunction::new(vec![1.0], vec![1.0], -1.0).is_err());
}

#[test]
fn state_space_shape_and_value_errors() {
    let ok = || {
        (
            mat(&[&[0.5]]),
            mat(&[&[1.0]]),
            mat(&[&[1.0]]),
            mat(&[&[0.0]]),
        )
    };
    let (a, b, c_, d) = ok();
    assert!(StateSpace::new(a, b, c_, d, 0.1).is_ok());
    let (_, b, c_, d) = ok();
    assert!(StateSpace::new(Mat::zeros(1, 2), b, c_, d, 0.1).is_err());
    let (a, _, c_, d) = ok();
    assert!(StateSpace::new(a, Mat::zeros(2, 1), c_, d, 0.1).is_err());
    let (a, b, _, d) = ok();
    assert!(StateSpace::new(a, b, Mat::zeros(1, 3), d, 0.1).is_err());
    let (a, b, c_, _) = ok();
    assert!(StateSpace::new(a, b, c_, Mat::zeros(1, 2), 0.1).is_err());
    let (a, b, c_, d) = ok();
    assert!(StateSpace::new(a, b, c_, d, f64::NAN).is_err());
    let (_, b, c_, d) = ok();
    assert!(StateSpace::new(mat(&[&[f64::INFINITY]]), b, c_, d, 0.1).is_err());
}

#[test]
fn simulate_matches_impulse_closed_form_and_rejects_bad_input() {
    let (a, b) = (0.8, 0.5);
    let ss = StateSpace::new(
        mat(&[&[a]]),
        mat(&[&[b]]),
        mat(&[&[2.0]]),
        mat(&[&[0.1]]),
        1.0,
    )
    .unwrap();
    let mut u = vec![0.0; 20];
    u[0] = 1.0;
    let y = ss.simulate_siso(&u, Some(&[1.0])).unwrap();
    // y[0] = 2·x0 + 0.1; y[k] = 2·(a^k·x0 + a^(k−1)·b) for k >= 1.
    assert!((y[0] - 2.1).abs() < 1e-15);
    for (k, yk) in y.iter().enumerate().skip(1) {
        let exact = 2.0 * (a.powi(k as i32) + a.powi(k as i32 - 1) * b);
        assert!((yk - exact).abs() < 1e-14);
    }
    assert!(ss.simulate_siso(&[1.0, f64::NAN], None).is_err());
    assert!(ss.simulate(&[vec![1.0], vec![2.0]], None).is_err());
    assert!(ss.simulate_siso(&[1.0], Some(&[1.0, 2.0])).is_err());
    let cont = StateSpace::new(
        mat(&[&[-1.0]]),
        mat(&[&[1.0]]),
        mat(&[&[1.0]]),
        mat(&[&[0.0]]),
        0.0,
    )
    .unwrap();
    assert!(matches!(
        cont.simulate_siso(&[1.0], None),
        Err(Error::InvalidArgument(_))
    ));
}

/// Complex p×m matrices for the reference algebra.
fn cmat_mul(a: &Mat<Complex64>, b: &Mat<Complex64>) -> Mat<Complex64> {
    Mat::from_fn(a.nrows(), b.ncols(), |i, j| {
        (0..a.ncols()).map(|k| a[(i, k)] * b[(k, j)]).sum()
    })
}

#[test]
fn interconnections_match_pointwise_matrix_algebra() {
    let mut rng = Rng::new(21);
    let g = random_stable_continuous(&mut rng, 3, 2, 2);
    let k = random_stable_continuous(&mut rng, 2, 2, 2);
    let h = random_stable_continuous(&mut rng, 4, 2, 2);
    let ser = g.series(&k).unwrap();
    let par = g.parallel(&h).unwrap();
    let fb = g.feedback(&k).unwrap();
    for &w in &[0.0, 0.5, 3.0, 17.0] {
        let (gw, kw, hw) = (
            g.freq_response(w).unwrap(),
            k.freq_response(w).unwrap(),
            h.freq_response(w).unwrap(),
        );
        // series: K·G
        let want = cmat_mul(&kw, &gw);
        let got = ser.freq_response(w).unwrap();
        for i in 0..2 {
            for j in 0..2 {
                assert!((got[(i, j)] - want[(i, j)]).norm() < 1e-11);
                let pw = gw[(i, j)] + hw[(i, j)];
                assert!((par.freq_response(w).unwrap()[(i, j)] - pw).norm() < 1e-11);
            }
        }
        // feedback: (I + G K)^-1 G, via a complex LU in the test.
        let gk = cmat_mul(&gw, &kw);
        let lhs = Mat::from_fn(2, 2, |i, j| {
            gk[(i, j)] + if i == j { c(1.0, 0.0) } else { c(0.0, 0.0) }
        });
        let want = lhs.partial_piv_lu().solve(&gw);
        let got = fb.freq_response(w).unwrap();
        for i in 0..2 {
            for j in 0..2 {
                assert!((got[(i, j)] - want[(i, j)]).norm() < 1e-11, "w={w}");
            }
        }
    }
    assert!(g
        .series(&random_stable_continuous(&mut rng, 1, 3, 1))
        .is_err());
    let gd = g.c2d_zoh(0.1).unwrap();
    assert!(gd.series(&k).is_err(), "mixing sample times must fail");
}

#[test]
fn loop_functions_sensitivity_and_complementary_sensitivity() {
    // L = K·G with G = 1/(s(s+1)) and K = 2 (static): S + T = 1 at every frequency.
    let g = TransferFunction::new(vec![1.0], vec![1.0, 1.0, 0.0], 0.0).unwrap();
    let gs = g.to_state_space().unwrap();
    let kgain = StateSpace::gain(mat(&[&[2.0]]), 0.0).unwrap();
    let l = gs.series(&kgain).unwrap();
    let one = StateSpace::identity(1, 0.0).unwrap();
    let s = one.feedback(&l).unwrap();
    let t = l.feedback(&one).unwrap();
    let t_tf = TransferFunction::new(vec![2.0], vec![1.0], 0.0)
        .unwrap()
        .series(&g)
        .unwrap()
        .feedback(&TransferFunction::new(vec![1.0], vec![1.0], 0.0).unwrap())
        .unwrap();
    for &w in &[0.01, 0.3, 1.0, 1.41, 10.0] {
        let sw = s.freq_response(w).unwrap()[(0, 0)];
        let tw = t.freq_response(w).unwrap()[(0, 0)];
        assert!((sw + tw - c(1.0, 0.0)).norm() < 1e-12);
        // Closed form: T = 2/(s² + s + 2).
        let jw = c(0.0, w);
        let exact = c(2.0, 0.0) / (jw * jw + jw + 2.0);
        assert!((tw - exact).norm() < 1e-12);
        assert!((t_tf.freq_response(w).unwrap() - exact).norm() < 1e-12);
    }
    // Algebraic loop with D_G·D_K = −1 is ill-posed.
    let neg = StateSpace::gain(mat(&[&[-1.0]]), 0.0).unwrap();
    assert!(one.feedback(&neg).is_err());
}

#[test]
fn state_space_data_round_trips_through_json() {
    let mut rng = Rng::new(5);
    let g = random_stable_continuous(&mut rng, 3, 2, 1)
        .c2d_zoh(0.01)
        .unwrap();
    let json = serde_json::to_string(&StateSpaceData::from(&g)).unwrap();
    let back: StateSpaceData = serde_json::from_str(&json).unwrap();
    let g2 = StateSpace::try_from(&back).unwrap();
    // serde_json without its `float_roundtrip` feature may be off by one ulp.
    assert!(max_abs_diff(&g.a, &g2.a) <= 4.0 * f64::EPSILON);
    assert!(max_abs_diff(&g.d, &g2.d) <= 4.0 * f64::EPSILON);
    assert_eq!(g2.ts, 0.01);
    let mut bad = back.clone();
    bad.a[1].pop();
    assert!(StateSpace::try_from(&bad).is_err());
}
