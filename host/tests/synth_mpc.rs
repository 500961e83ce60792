//! Condensed MPC: the ADMM solution against the closed-form unconstrained optimum and a KKT
//! certificate, and a constrained step on the two-mass model that respects the rails.
use faer::Mat;
use ferrosid::lti::{StateSpace, StateSpaceData};
use ferrosid::synth::mpc::{MpcDesign, MpcSpec};

fn two_mass_1khz() -> StateSpace {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/two_mass_sim.json");
    let data: StateSpaceData =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    StateSpace::try_from(&data).unwrap().c2d_zoh(1e-3).unwrap()
}

fn spec(horizon: usize) -> MpcSpec {
    MpcSpec {
        horizon,
        q: 1.0,
        r_rate: 1e-2,
        u_min: -0.3,
        u_max: 0.3,
        du_max: 0.05,
        rho: 1.0,
        iterations: 60,
    }
}

#[test]
fn unconstrained_admm_matches_the_closed_form_optimum() {
    let g = two_mass_1khz();
    let mut s = spec(10);
    (s.u_min, s.u_max, s.du_max) = (-1e9, 1e9, 1e9);
    let d = MpcDesign::new(&g, s).unwrap();
    let x0 = [0.001, 2.0, 1.0];
    let (f, lo, hi) = d.qp_data(&x0, 5.0, 0.1);
    let mut st = d.initial_state();
    d.solve(&mut st, &f, &lo, &hi, 3000);
    let fm = Mat::from_fn(10, 1, |i, _| -f[i]);
    let exact = d.h.as_ref().partial_piv_lu();
    let exact = faer::linalg::solvers::Solve::solve(&exact, fm.as_ref());
    let err = (0..10)
        .map(|i| (st.u[i] - exact[(i, 0)]).abs())
        .fold(0.0, f64::max);
    let scale = (0..10).map(|i| exact[(i, 0)].abs()).fold(0.0, f64::max);
    assert!(
        err <= 1e-6 * scale.max(1.0),
        "err {err:.3e} (scale {scale:.3e})"
    );
}

#[test]
fn constrained_solution_satisfies_the_kkt_conditions() {
    let g = two_mass_1khz();
    // ρ of the order of the Hessian's diagonal (≈ 265 here) for fast ADMM convergence.
    let d = MpcDesign::new(
        &g,
        MpcSpec {
            rho: 300.0,
            ..spec(20)
        },
    )
    .unwrap();
    let (f, lo, hi) = d.qp_data(&[0.0, 0.0, 0.0], 5.0, 0.0);
    let mut st = d.initial_state();
    d.solve(&mut st, &f, &lo, &hi, 20_000);
    let n = 20;
    let tol = 1e-6;
    let mut active = 0;
    for i in 0..2 * n {
        let mu: f64 = (0..n).map(|j| d.m[(i, j)] * st.u[j]).sum();
        assert!(
            mu >= lo[i] - tol && mu <= hi[i] + tol,
            "row {i}: {mu} outside [{}, {}]",
            lo[i],
            hi[i]
        );
        let l = st.lambda[i];
        if l > tol {
            assert!(
                (mu - hi[i]).abs() < 1e-5,
                "row {i}: λ {l:.3e} > 0 off the upper bound: {mu} vs {}",
                hi[i]
            );
            active += 1;
        } else if l < -tol {
            assert!(
                (mu - lo[i]).abs() < 1e-5,
                "row {i}: λ {l:.3e} < 0 off the lower bound: {mu} vs {}",
                lo[i]
            );
            active += 1;
        }
    }
    let grad_scale = f.iter().map(|v| v.abs()).fold(0.0, f64::max);
    for (j, fj) in f.iter().enumerate() {
        let r: f64 = (0..n).map(|k| d.h[(j, k)] * st.u[k]).sum::<f64>()
            + fj
            + (0..2 * n).map(|i| d.m[(i, j)] * st.lambda[i]).sum::<f64>();
        assert!(r.abs() < 1e-6 * grad_scale, "stationarity row {j}: {r:.3e}");
    }
    assert!(active > 0, "the step must hit a constraint");
}

#[test]
fn constrained_step_respects_the_rails_and_tracks() {
    let g = two_mass_1khz();
    for horizon in [10, 20] {
        let d = MpcDesign::new(&g, spec(horizon)).unwrap();
        let mut st = d.initial_state();
        let mut x = Mat::<f64>::zeros(3, 1);
        let mut u_prev = 0.0;
        let mut y = 0.0;
        let mut peak = 0.0f64;
        for _ in 0..1500 {
            let x0 = [x[(0, 0)], x[(1, 0)], x[(2, 0)]];
            let u = d.step(&mut st, &x0, 5.0, u_prev);
            assert!((-0.3..=0.3).contains(&u), "u = {u}");
            assert!((u - u_prev).abs() <= 0.05 + 1e-12, "Δu = {}", u - u_prev);
            x = &g.a * &x + &g.b * faer::Scale(u);
            y = (&g.c * &x)[(0, 0)];
            peak = peak.max(y);
            u_prev = u;
        }
        eprintln!("N = {horizon}: y(1.5 s) = {y:.4} rad/s, peak {peak:.4}, u = {u_prev:.4} N·m");
        assert!((y - 5.0).abs() < 0.05, "N = {horizon}: y = {y}");
    }
}

#[test]
fn firmware_terms_reproduce_the_linear_term() {
    let g = two_mass_1khz();
    let d = MpcDesign::new(&g, spec(20)).unwrap();
    let (gx, gr) = d.firmware_terms();
    let (x0, r, u_prev) = ([0.002, 1.5, 0.7], 5.0, 0.12);
    let (f, _, _) = d.qp_data(&x0, r, u_prev);
    for (i, fi) in f.iter().enumerate() {
        let mut v = (0..3).map(|j| gx[(i, j)] * x0[j]).sum::<f64>() - gr[i] * r;
        if i == 0 {
            v -= 2.0 * d.spec.r_rate * u_prev;
        }
        assert!(
            (v - fi).abs() <= 1e-12 * fi.abs().max(1.0),
            "f[{i}]: {v} vs {fi}"
        );
    }
}
