//! Condensed MPC: the ADMM solution against the closed-form unconstrained optimum and a KKT
//! certificate, and a constrained step on the two-mass model that respects the rails.
use faer::Mat;
use ferrosid::lti::StateSpace;
use ferrosid::synth::mpc::{MpcDesign, MpcSpec};

fn two_mass_1khz() -> StateSpace {
    crate::test_models::two_mass().c2d_zoh(1e-3).unwrap()
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

// ---- The pipeline's `[control] method = "mpc"` on the bundled example ---------------------

mod pipeline {
    use crate::bundled_example::{assert_bad_control_keys, codegen_axis1, report_html, run};
    use ferrosid::pipeline::ReceiptsDocument;
    use ferrosid::synth::mpc::{MpcDesign, MpcSpec};

    #[test]
    fn mpc_designs_with_its_receipts_report_and_codegen() {
        let run = run("method = \"mpc\"\nmpc_horizon = 10\n");
        let c = run.control.as_ref().expect("control block");
        assert_eq!(c.status, "designed", "{:?}", c.error);
        let model = run.model();
        // The receipts that apply, merged into the top-level list; the frequency-domain loop
        // receipts are absent there and listed with a reason.
        let names = [
            "controller_design",
            "closed_loop_stable",
            "step_actuator_demand",
            "step_overshoot",
            "step_settling_time",
        ];
        for n in names {
            let r = c.receipts.get(n).unwrap_or_else(|| panic!("{n}"));
            assert_eq!(run.receipts.get(n), Some(r), "{n} merged");
            eprintln!(
                "mpc: {n} = {} ({} {}) {}",
                r.value_text,
                r.comparison.symbol(),
                r.limit,
                r.pass
            );
        }
        for n in [
            "gain_margin",
            "phase_margin",
            "sensitivity_peak",
            "complementary_sensitivity_peak",
            "robust_stability",
            "peak_control_effort",
        ] {
            assert!(run.receipts.get(n).is_none(), "{n} must not be claimed");
            assert!(c.not_applicable.iter().any(|x| x.name == n), "{n} listed");
            assert!(
                c.replaced_pid_receipts.iter().any(|x| x.name == n),
                "{n} kept"
            );
        }
        // Independent re-simulation of the constrained step from the written settings: rails
        // and rate limit hold, and it tracks.
        let k = &run.config.control;
        let spec = MpcSpec {
            horizon: 10,
            q: 1.0,
            r_rate: 1e-2,
            u_min: -k.actuator_limit,
            u_max: k.actuator_limit,
            du_max: k.actuator_limit / 6.0,
            rho: 1.0,
            iterations: 60,
        };
        let d = MpcDesign::new(model, spec).unwrap();
        let step = c.step.as_ref().expect("step");
        let mut st = d.initial_state();
        let n = model.n_states();
        let mut x = vec![0.0; n];
        let mut u_prev = 0.0;
        for kk in 0..step.t.len() {
            let y: f64 = (0..n).map(|j| model.c[(0, j)] * x[j]).sum();
            let u = d.step(&mut st, &x, k.reference_amplitude, u_prev);
            assert!(u.abs() <= k.actuator_limit, "rail crossed: u = {u}");
            assert!((u - u_prev).abs() <= spec.du_max * (1.0 + 1e-12) + 1e-15);
            assert!(
                (y - step.y[kk]).abs() <= 1e-9 * k.reference_amplitude,
                "y[{kk}]"
            );
            assert!((u - step.u[kk]).abs() <= 1e-12, "u[{kk}]");
            x = (0..n)
                .map(|i| (0..n).map(|j| model.a[(i, j)] * x[j]).sum::<f64>() + model.b[(i, 0)] * u)
                .collect();
            u_prev = u;
        }
        assert!(step.samples_at_rail > 0, "a 5 rad/s step must use the rail");
        assert!(
            step.final_error.abs() < 0.02 * k.reference_amplitude,
            "final error {}",
            step.final_error
        );
        // The unconstrained law's closed loop (independent construction here): stable and
        // unit DC gain from r to y on the model (the weights penalise y − r only).
        let law = d.unconstrained_law().unwrap();
        let cl = d.unconstrained_closed_loop(model).unwrap();
        let dc = cl.freq_response_siso(1e-6).unwrap().norm();
        assert!((dc - 1.0).abs() < 1e-3, "DC gain {dc}");
        assert_eq!(law.kx.len(), n);
        // JSON, report and codegen.
        let doc: serde_json::Value =
            serde_json::from_str(&ReceiptsDocument::from_run(&run).to_json().unwrap()).unwrap();
        assert_eq!(doc["control"]["method"], "mpc");
        assert_eq!(doc["control"]["design"]["kind"], "mpc");
        assert!(doc["control"]["not_applicable"].as_array().unwrap().len() >= 6);
        let html = report_html(&run);
        assert!(html.contains("Chosen controller: mpc"));
        assert!(html.contains("id=\"fig-control_step\""));
        assert!(html.contains("do not apply"));
        let input = codegen_axis1(&run);
        let sk = input.state_controller.as_ref().expect("mpc block");
        let m = sk.mpc.as_ref().expect("mpc data");
        assert_eq!(m.horizon, 10);
        assert_eq!(m.k[3][7], d.k[(3, 7)]);
        let files = ferrosid_codegen::generate(&input).unwrap();
        assert!(files.c_header.contains("#define AXIS1_HAS_MPC 1"));
        assert!(!files.c_header.contains("AXIS1_HAS_STATE_CONTROLLER"));
        assert!(files.rust_module.contains("pub const MPC_N: usize = 10;"));
    }

    #[test]
    fn bad_mpc_keys_name_file_line_and_key() {
        assert_bad_control_keys(&[
            (
                "mpc_horizon = 10",
                "control.mpc_horizon",
                "only used with method = \"mpc\"",
            ),
            (
                "method = \"mpc\"\nmpc_horizon = 0",
                "control.mpc_horizon",
                "must lie in [1, 64]",
            ),
            (
                "method = \"mpc\"\nmpc_horizon = 65",
                "control.mpc_horizon",
                "must lie in [1, 64]",
            ),
            (
                "method = \"mpc\"\nmpc_horizon = -3",
                "control.mpc_horizon",
                "",
            ),
            (
                "method = \"mpc\"\nmpc_output_weight = 0",
                "control.mpc_output_weight",
                "> 0",
            ),
            (
                "method = \"mpc\"\nmpc_output_weight = nan",
                "control.mpc_output_weight",
                "finite",
            ),
            (
                "method = \"mpc\"\nmpc_rate_weight = -1",
                "control.mpc_rate_weight",
                ">= 0",
            ),
            (
                "method = \"mpc\"\nmpc_rate_limit = 0",
                "control.mpc_rate_limit",
                "> 0",
            ),
            (
                "method = \"mpc\"\nmpc_rate_limit = 0.7",
                "control.mpc_rate_limit",
                "rail-to-rail",
            ),
            (
                "method = \"mpc\"\nmpc_rho = inf",
                "control.mpc_rho",
                "finite",
            ),
            (
                "method = \"mpc\"\nmpc_iterations = 0",
                "control.mpc_iterations",
                "[1, 10000]",
            ),
            (
                "method = \"hinf\"\nmpc_iterations = 5",
                "control.mpc_iterations",
                "only used with",
            ),
            (
                "method = \"mpc\"\nmpc_horizn = 5",
                "control.mpc_horizn",
                "unknown field",
            ),
        ]);
    }
}
