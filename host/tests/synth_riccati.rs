//! CARE/DARE against closed forms and published benchmark cases, and refusal of equations
//! without a stabilising solution.
use faer::{Mat, MatRef};
use ferrosid::synth::riccati::{
    care, care_g, care_residual, dare, RiccatiSolution, RICCATI_RESIDUAL_TOL,
};

fn m(rows: &[&[f64]]) -> Mat<f64> {
    Mat::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
}

/// The solution of a scalar (1×1) equation by `solve` ([`care`] or [`dare`]).
fn scalar(solve: Solver, a: f64, b: f64, q: f64, r: f64) -> RiccatiSolution {
    solve(
        m(&[&[a]]).as_ref(),
        m(&[&[b]]).as_ref(),
        m(&[&[q]]).as_ref(),
        m(&[&[r]]).as_ref(),
    )
    .unwrap()
}

/// The scalar solution `s` equals the closed form `x` within relative `tol` (case `a`).
fn assert_scalar(s: &RiccatiSolution, x: f64, tol: f64, a: f64) {
    let rel = (s.x[(0, 0)] - x).abs() / x;
    assert!(
        rel < tol,
        "a={a}: X = {} vs {x} (rel {rel:.2e})",
        s.x[(0, 0)]
    );
}

/// `solve`(A, B, Q = I, R = 1) for a single-input pair (A, B).
fn unit_weights(
    solve: Solver,
    a: &Mat<f64>,
    b: &Mat<f64>,
) -> ferrosid::error::Result<RiccatiSolution> {
    let n = a.nrows();
    solve(
        a.as_ref(),
        b.as_ref(),
        Mat::<f64>::identity(n, n).as_ref(),
        m(&[&[1.0]]).as_ref(),
    )
}

/// The signature of [`care`] and [`dare`].
type Solver = fn(
    MatRef<'_, f64>,
    MatRef<'_, f64>,
    MatRef<'_, f64>,
    MatRef<'_, f64>,
) -> ferrosid::error::Result<RiccatiSolution>;

fn max_abs_diff(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
    let mut d = 0.0f64;
    for j in 0..a.ncols() {
        for i in 0..a.nrows() {
            d = d.max((a[(i, j)] - b[(i, j)]).abs());
        }
    }
    d
}

#[test]
fn scalar_care_matches_closed_form() {
    // 2 a x − (b²/r) x² + q = 0 → x = r (a + √(a² + b² q / r)) / b².
    for &(a, b, q, r) in &[
        (1.0, 1.0, 1.0, 1.0),
        (-3.0, 0.5, 2.0, 0.1),
        (10.0, 2.0, 1e-3, 5.0),
    ] {
        let s = scalar(care, a, b, q, r);
        let x = r * (a + (a * a + b * b * q / r).sqrt()) / (b * b);
        assert_scalar(&s, x, 1e-13, a);
        assert!(s.closed_loop_abscissa < 0.0);
    }
}

#[test]
fn scalar_dare_matches_closed_form() {
    // b² x² + ((1 − a²) r − q b²) x − q r = 0, positive root.
    for &(a, b, q, r) in &[
        (1.2, 1.0, 1.0, 1.0),
        (0.5, 0.3, 2.0, 0.1),
        (-2.0, 1.5, 0.01, 3.0),
    ] {
        let s = scalar(dare, a, b, q, r);
        let p = (1.0 - a * a) * r - q * b * b;
        let x = (-p + (p * p + 4.0 * b * b * q * r).sqrt()) / (2.0 * b * b);
        assert_scalar(&s, x, 1e-12, a);
        assert!(s.closed_loop_abscissa < 1.0);
    }
}

#[test]
fn double_integrator_lqr_has_the_known_solution() {
    // A = [0 1; 0 0], B = [0; 1], Q = I, R = 1: X = [√3 1; 1 √3].
    let a = m(&[&[0.0, 1.0], &[0.0, 0.0]]);
    let b = m(&[&[0.0], &[1.0]]);
    let s = unit_weights(care, &a, &b).unwrap();
    let r3 = 3f64.sqrt();
    let x = m(&[&[r3, 1.0], &[1.0, r3]]);
    eprintln!(
        "double integrator: residual {:.2e}, error {:.2e}",
        s.residual_rel,
        max_abs_diff(&s.x, &x)
    );
    assert!(max_abs_diff(&s.x, &x) < 1e-13, "{:?}", s.x);
    assert!(s.residual_rel < 1e-14, "{:.2e}", s.residual_rel);
}

#[test]
fn carex_example_1_laub_1979() {
    // CAREX (Abels & Benner 1999) example 1: A = [0 1; 0 0], B = [0; 1], R = 1,
    // Q = diag(1, 2); exact X = [2 1; 1 2].
    let a = m(&[&[0.0, 1.0], &[0.0, 0.0]]);
    let b = m(&[&[0.0], &[1.0]]);
    let q = m(&[&[1.0, 0.0], &[0.0, 2.0]]);
    let s = care(a.as_ref(), b.as_ref(), q.as_ref(), m(&[&[1.0]]).as_ref()).unwrap();
    let x = m(&[&[2.0, 1.0], &[1.0, 2.0]]);
    eprintln!(
        "CAREX 1: residual {:.2e}, error {:.2e}",
        s.residual_rel,
        max_abs_diff(&s.x, &x)
    );
    assert!(max_abs_diff(&s.x, &x) < 1e-13, "{:?}", s.x);
}

#[test]
fn darex_example_1_jonckheere_1981() {
    // DAREX (Abels & Benner 1999) example 1: A = [4 3; −4.5 −3.5], B = [1; −1], R = 1,
    // Q = [9 6; 6 4]; exact X = (1 + √5)/2 · [9 6; 6 4].
    let a = m(&[&[4.0, 3.0], &[-4.5, -3.5]]);
    let b = m(&[&[1.0], &[-1.0]]);
    let q = m(&[&[9.0, 6.0], &[6.0, 4.0]]);
    let s = dare(a.as_ref(), b.as_ref(), q.as_ref(), m(&[&[1.0]]).as_ref()).unwrap();
    let phi = 0.5 * (1.0 + 5f64.sqrt());
    let x = Mat::from_fn(2, 2, |i, j| phi * q[(i, j)]);
    let rel = max_abs_diff(&s.x, &x) / (9.0 * phi);
    eprintln!(
        "DAREX 1: residual {:.2e}, relative error {rel:.2e}",
        s.residual_rel
    );
    assert!(rel < 1e-12, "{:?} (rel {rel:.2e})", s.x);
}

#[test]
fn scaled_lightly_damped_chain_meets_the_residual_contract() {
    // A lightly damped 4-state chain with widely scaled weights: the residual contract holds
    // and the closed loop is stable.
    let a = m(&[
        &[0.0, 1.0, 0.0, 0.0],
        &[-1e4, -0.2, 1e4, 0.0],
        &[0.0, 0.0, 0.0, 1.0],
        &[1e2, 0.0, -1e2, -0.02],
    ]);
    let b = m(&[&[0.0], &[0.0], &[0.0], &[1.0]]);
    let q = Mat::from_fn(4, 4, |i, j| {
        if i == j {
            [1e6, 1.0, 1e2, 1e-2][i]
        } else {
            0.0
        }
    });
    let r = m(&[&[1e-3]]);
    let s = care(a.as_ref(), b.as_ref(), q.as_ref(), r.as_ref()).unwrap();
    assert!(s.residual_rel <= RICCATI_RESIDUAL_TOL);
    eprintln!(
        "scaled 4-state chain: residual {:.2e}, refinement steps {}",
        s.residual_rel, s.refinement_steps
    );
    // Independent residual from the public formula.
    let g = &b * b.transpose() * faer::Scale(1e3);
    let res = care_residual(a.as_ref(), g.as_ref(), q.as_ref(), s.x.as_ref());
    let nres = res.norm_l2();
    let scale =
        q.norm_l2() + 2.0 * a.norm_l2() * s.x.norm_l2() + g.norm_l2() * s.x.norm_l2().powi(2);
    assert!(nres / scale < 1e-10, "{:.3e}", nres / scale);
}

#[test]
fn unstabilisable_pair_is_refused() {
    // An unstable mode that B cannot reach: no stabilising solution.
    let a = m(&[&[1.0, 0.0], &[0.0, -1.0]]);
    let b = m(&[&[0.0], &[1.0]]);
    let e = unit_weights(care, &a, &b).unwrap_err().to_string();
    assert!(
        e.contains("stabilising") || e.contains("imaginary axis"),
        "{e}"
    );
    let e = unit_weights(dare, &m(&[&[1.5, 0.0], &[0.0, 0.5]]), &b)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("stabilising") || e.contains("imaginary axis") || e.contains("graph"),
        "{e}"
    );
}

#[test]
fn undamped_unobservable_mode_is_refused() {
    // An undamped oscillator with Q = 0 and G = 0: Hamiltonian eigenvalues ±j on the axis.
    let a = m(&[&[0.0, 1.0], &[-1.0, 0.0]]);
    let z = Mat::<f64>::zeros(2, 2);
    let e = care_g(a.as_ref(), z.as_ref(), z.as_ref())
        .unwrap_err()
        .to_string();
    assert!(e.contains("CARE"), "{e}");
}

#[test]
fn nearly_uncontrollable_unstable_mode_fails_or_is_accurate() {
    // As the input weight on an unstable mode vanishes the solution blows up; the solver must
    // either refuse or return a solution meeting the contract, never a wrong answer.
    for eps in [1e-2, 1e-4, 1e-6, 1e-8, 1e-10] {
        let a = m(&[&[1.0, 0.0], &[0.0, -2.0]]);
        let b = m(&[&[eps], &[1.0]]);
        match unit_weights(care, &a, &b) {
            Ok(s) => {
                let g = &b * b.transpose();
                let res = care_residual(
                    a.as_ref(),
                    g.as_ref(),
                    Mat::<f64>::identity(2, 2).as_ref(),
                    s.x.as_ref(),
                );
                let nx = s.x.norm_l2();
                let rel = res.norm_l2() / (1.0 + 2.0 * a.norm_l2() * nx + g.norm_l2() * nx * nx);
                assert!(rel <= RICCATI_RESIDUAL_TOL, "eps {eps}: {rel:.3e}");
                eprintln!("eps {eps:e}: solved, residual {rel:.2e}");
                // Scalar closed form of the decoupled unstable mode as ε → 0: x₁₁ ≈ 2a/ε².
                let x11 = s.x[(0, 0)];
                assert!(x11 > 1.0 / (eps * eps), "eps {eps}: x11 = {x11:.3e}");
            }
            Err(e) => {
                eprintln!("eps {eps:e}: refused: {e}");
                assert!(e.to_string().contains("numerical failure"), "{e}")
            }
        }
    }
}

#[test]
fn bad_shapes_and_indefinite_r_are_invalid_arguments() {
    let a = m(&[&[0.0, 1.0], &[0.0, 0.0]]);
    let b = m(&[&[0.0], &[1.0]]);
    let q = Mat::<f64>::identity(2, 2);
    let e = care(a.as_ref(), b.as_ref(), q.as_ref(), m(&[&[-1.0]]).as_ref()).unwrap_err();
    assert!(e.to_string().contains("positive definite"), "{e}");
    let e = care(
        a.as_ref(),
        b.as_ref(),
        m(&[&[1.0, 2.0], &[0.0, 1.0]]).as_ref(),
        m(&[&[1.0]]).as_ref(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("symmetric"), "{e}");
    let e = care(
        a.as_ref(),
        m(&[&[1.0]]).as_ref(),
        q.as_ref(),
        m(&[&[1.0]]).as_ref(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("B must be"), "{e}");
}
