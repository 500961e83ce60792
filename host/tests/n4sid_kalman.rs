//! Steady-state Kalman filter (doubling DARE solver) against closed forms and a brute-force
//! Riccati iteration, and the innovation model identified by N4SID against the truth.
mod n4sid_support;

use faer::Mat;
use ferrosid::lti::StateSpace;
use ferrosid::n4sid::{kalman_filter_gain, n4sid_slices, N4sidOptions};
use n4sid_support::*;

#[test]
fn scalar_filter_riccati_closed_form() {
    // P = a²P + q − a²c²P²/(c²P + r)  ⇔  c²P² + (r(1 − a²) − qc²)P − qr = 0.
    let (a, c, q, r): (f64, f64, f64, f64) = (0.9, 2.0, 0.5, 3.0);
    let bq = r * (1.0 - a * a) - q * c * c;
    let p = (-bq + (bq * bq + 4.0 * c * c * q * r).sqrt()) / (2.0 * c * c);
    let kf = kalman_filter_gain(
        mat(&[&[a]]).as_ref(),
        mat(&[&[c]]).as_ref(),
        mat(&[&[q]]).as_ref(),
        mat(&[&[0.0]]).as_ref(),
        mat(&[&[r]]).as_ref(),
    )
    .unwrap();
    assert!((kf.p[(0, 0)] - p).abs() < 1e-12 * p);
    let k = a * p * c / (c * c * p + r);
    assert!((kf.gain[(0, 0)] - k).abs() < 1e-12 * k);
    assert!((kf.innovation_cov[(0, 0)] - (c * c * p + r)).abs() < 1e-12 * (c * c * p + r));
}

#[test]
fn mimo_filter_matches_riccati_iteration_with_cross_covariance() {
    let a = mat(&[&[0.9, 0.3, 0.0], &[-0.3, 0.9, 0.1], &[0.0, 0.0, 0.5]]);
    let c = mat(&[&[1.0, 0.0, 1.0], &[0.0, 1.0, 0.0]]);
    let q = mat(&[&[1.0, 0.2, 0.0], &[0.2, 0.5, 0.0], &[0.0, 0.0, 0.3]]);
    let s = mat(&[&[0.1, 0.0], &[0.0, 0.05], &[0.0, 0.0]]);
    let r = mat(&[&[0.4, 0.1], &[0.1, 0.6]]);
    let kf =
        kalman_filter_gain(a.as_ref(), c.as_ref(), q.as_ref(), s.as_ref(), r.as_ref()).unwrap();
    // Reference: iterate the Riccati difference equation to convergence, in plain arrays.
    let mm = |x: &Vec<Vec<f64>>, y: &Vec<Vec<f64>>| -> Vec<Vec<f64>> {
        (0..x.len())
            .map(|i| {
                (0..y[0].len())
                    .map(|j| (0..y.len()).map(|k| x[i][k] * y[k][j]).sum())
                    .collect()
            })
            .collect()
    };
    let tr = |x: &Vec<Vec<f64>>| -> Vec<Vec<f64>> {
        (0..x[0].len())
            .map(|j| (0..x.len()).map(|i| x[i][j]).collect())
            .collect()
    };
    let rows = |m: &Mat<f64>| -> Vec<Vec<f64>> {
        (0..m.nrows())
            .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
            .collect()
    };
    let (av, cv, qv, sv, rv) = (rows(&a), rows(&c), rows(&q), rows(&s), rows(&r));
    let mut p = vec![vec![0.0; 3]; 3];
    for _ in 0..5000 {
        let cp = mm(&cv, &p);
        let re0 = mm(&cp, &tr(&cv));
        let re: Vec<Vec<f64>> = (0..2)
            .map(|i| (0..2).map(|j| re0[i][j] + rv[i][j]).collect())
            .collect();
        let ap = mm(&av, &p);
        let g0 = mm(&ap, &tr(&cv));
        let g: Vec<Vec<f64>> = (0..3)
            .map(|i| (0..2).map(|j| g0[i][j] + sv[i][j]).collect())
            .collect();
        let det = re[0][0] * re[1][1] - re[0][1] * re[1][0];
        let inv = vec![
            vec![re[1][1] / det, -re[0][1] / det],
            vec![-re[1][0] / det, re[0][0] / det],
        ];
        let apa = mm(&ap, &tr(&av));
        let gig = mm(&mm(&g, &inv), &tr(&g));
        // Symmetrised each step: the plain recursion amplifies round-off skew parts.
        let pn: Vec<Vec<f64>> = (0..3)
            .map(|i| (0..3).map(|j| apa[i][j] + qv[i][j] - gig[i][j]).collect())
            .collect();
        p = (0..3)
            .map(|i| (0..3).map(|j| 0.5 * (pn[i][j] + pn[j][i])).collect())
            .collect();
    }
    let p = Mat::from_fn(3, 3, |i, j| p[i][j]);
    for i in 0..3 {
        for j in 0..3 {
            assert!(
                (kf.p[(i, j)] - p[(i, j)]).abs() < 1e-10,
                "P[{i},{j}] {:?} vs {:?}",
                kf.p,
                p
            );
        }
    }
    let closed = &a - &kf.gain * &c;
    let ev = closed.eigenvalues().unwrap();
    assert!(ev.iter().all(|z| z.norm() < 1.0));
}

#[test]
fn riccati_refuses_indefinite_measurement_noise() {
    let r = kalman_filter_gain(
        mat(&[&[0.5]]).as_ref(),
        mat(&[&[1.0]]).as_ref(),
        mat(&[&[1.0]]).as_ref(),
        mat(&[&[0.0]]).as_ref(),
        mat(&[&[-1.0]]).as_ref(),
    );
    assert!(r.is_err());
    let r = kalman_filter_gain(
        mat(&[&[0.5]]).as_ref(),
        mat(&[&[1.0, 0.0]]).as_ref(),
        mat(&[&[1.0]]).as_ref(),
        mat(&[&[0.0]]).as_ref(),
        mat(&[&[1.0]]).as_ref(),
    );
    assert!(r.is_err(), "shape mismatch must be refused");
}

#[test]
fn identified_innovation_model_matches_the_true_noise_model() {
    // x⁺ = Ax + Bu + Ke, y = Cx + e, var(e) = 0.04: the one-step predictor's noise model
    // H(z) = I + C(zI − A)⁻¹K is basis independent and compared with the truth.
    let a = mat(&[&[1.5, -0.7], &[1.0, 0.0]]);
    let b = mat(&[&[1.0], &[0.0]]);
    let c = mat(&[&[1.0, 0.5]]);
    let k = mat(&[&[0.6], &[0.2]]);
    let truth_h = StateSpace::new(a.clone(), k.clone(), c.clone(), mat(&[&[1.0]]), 1.0).unwrap();
    let n = 50_000;
    let mut rng = Rng::new(17);
    let u = rng.binary(n);
    let e = rng.noise(n, 0.2);
    let mut x = [0.0, 0.0];
    let mut y = vec![0.0; n];
    for t in 0..n {
        y[t] = c[(0, 0)] * x[0] + c[(0, 1)] * x[1] + e[t];
        let x0 = a[(0, 0)] * x[0] + a[(0, 1)] * x[1] + b[(0, 0)] * u[t] + k[(0, 0)] * e[t];
        let x1 = a[(1, 0)] * x[0] + a[(1, 1)] * x[1] + b[(1, 0)] * u[t] + k[(1, 0)] * e[t];
        x = [x0, x1];
    }
    let r = n4sid_slices(1.0, &[&u], &[&y], &N4sidOptions::default()).unwrap();
    assert_eq!(r.order, 2, "{}", r.order_reason);
    let kg = r.kalman_gain.clone().expect("Kalman gain estimated");
    let re = r.innovation_cov.clone().unwrap();
    assert!(
        (re[(0, 0)] - 0.04).abs() < 0.1 * 0.04,
        "innovation variance {}",
        re[(0, 0)]
    );
    let h = StateSpace::new(
        r.model.a.clone(),
        kg,
        r.model.c.clone(),
        mat(&[&[1.0]]),
        1.0,
    )
    .unwrap();
    let f = logspace(0.001, 0.49, 60);
    let worst = max_rel_error(&h, &truth_h, &f);
    assert!(worst < 0.1, "noise model error {worst:.3e}");
}
