//! The `limit_cycle` receipts of the chosen controller's own loop (issue 14) on the bundled
//! two-mass example with its gap diagnosis (Coulomb friction at the motor): `pid-notch` and
//! `hinf` analyse the diagnosed effect in their own loop, the MPC says the analysis does not
//! apply, and the loop the analysis uses is the chosen controller's (checked against an
//! independent evaluation and simulation of G0 with that controller).
use crate::bundled_example::{example_path, with_control, without_physical};
use ferrosid::gap::fit::VelocitySource;
use ferrosid::limit_cycle::{simulate, DescribingFunction, LureLoop, Nonlinearity, SimSpec, Site};
use ferrosid::lti::StateSpace;
use ferrosid::pipeline::control_methods::MethodRun;
use ferrosid::pipeline::control_stage::{chosen_law, ControlMethod};
use ferrosid::pipeline::{run_pipeline, LoadedConfig, PipelineRun};
use ferrosid::robust::receipts::{Receipt, ReceiptKind};
use ferrosid::synth::sim::SsFilter;
use num_complex::Complex64;

/// The example with its gap and compensation stages (without the physical stage), every
/// method in one run.
fn run_all() -> PipelineRun {
    let t = without_physical();
    assert!(
        t.contains("[gap]\nrun = \"always\""),
        "the example runs the gap stage"
    );
    let t = with_control(
        &t,
        "methods = [\"pid\", \"pid-notch\", \"hinf\", \"mpc\"]\n",
    );
    let cfg = LoadedConfig::from_text(&example_path(), &t).unwrap();
    run_pipeline(&cfg, &|_| {}).unwrap()
}

fn cycles(rs: &[Receipt]) -> Vec<&Receipt> {
    rs.iter()
        .filter(|r| r.kind() == Some(ReceiptKind::LimitCycle))
        .collect()
}

fn method<'a>(run: &'a PipelineRun, m: ControlMethod) -> &'a MethodRun {
    run.comparison.iter().find(|r| r.method == m).unwrap()
}

#[test]
fn each_method_has_the_limit_cycle_receipts_of_its_own_loop() {
    let run = run_all();
    let dec = run
        .compensation
        .decision()
        .expect("the compensation stage decided");
    let effects = dec.stage.effects.len();
    assert!(effects >= 1, "the example's friction is analysed");
    // The PID (primary) keeps the compensation stage's receipts.
    let pid = cycles(&run.receipts.receipts);
    assert_eq!(pid.len(), effects);
    let stage: Vec<&Receipt> = cycles(&dec.receipts_after);
    assert_eq!(pid, stage);
    for m in [ControlMethod::Loopshape, ControlMethod::Hinf] {
        let mr = method(&run, m);
        let c = mr.control.as_ref().unwrap();
        assert_eq!(c.status, "designed");
        let own = cycles(&mr.receipts.receipts);
        assert_eq!(own.len(), effects, "{}", m.name());
        let tag = format!("({} loop)", m.name());
        for (r, e) in own.iter().zip(&dec.stage.effects) {
            eprintln!(
                "{}: {} = {} — {}",
                m.name(),
                r.description,
                r.value,
                r.detail
            );
            assert!(r.description.contains(&e.label) && r.description.contains(&tag));
            assert!(r
                .detail
                .contains(&format!("the {} controller (order", m.name())));
            assert!(r.value.is_finite(), "the analysis ran: {}", r.detail);
            // Merged as computed, and in the method's own receipt set.
            assert!(c.receipts.receipts.contains(r));
        }
        // The PID's moved to replaced_pid_receipts; none of them is left in the list.
        assert_eq!(cycles(&c.replaced_pid_receipts), pid);
        assert!(mr.receipts.receipts.iter().all(|r| !pid.contains(&r)));
        assert!(c.not_applicable.iter().all(|n| n.name != "limit_cycle"));
    }
    // The MPC: no limit_cycle receipt, the reason, and the PID's among the replaced.
    let mpc = method(&run, ControlMethod::Mpc);
    let c = mpc.control.as_ref().unwrap();
    assert!(cycles(&mpc.receipts.receipts).is_empty());
    let na = c
        .not_applicable
        .iter()
        .find(|n| n.name == "limit_cycle")
        .expect("limit_cycle not applicable to the MPC");
    assert!(na.reason.contains("LTI controller"), "{}", na.reason);
    assert_eq!(cycles(&c.replaced_pid_receipts), pid);
    // The comparison table marks the MPC's step as simulated with the friction, no other.
    let rows = ferrosid::pipeline::control_methods::comparison_rows(&run);
    for r in &rows {
        match r.method {
            ControlMethod::Mpc => assert_eq!(
                r.step_effect.as_deref(),
                Some("coulomb_friction at motor"),
                "{:?}",
                c.step_effect
            ),
            _ => assert!(r.step_effect.is_none(), "{}", r.method.name()),
        }
    }
    // The receipts file of the MPC says the same.
    let docs = ferrosid::pipeline::control_methods::method_documents(&run).unwrap();
    let (_, json) = docs.iter().find(|(f, _)| f == "receipts.mpc.json").unwrap();
    let v: serde_json::Value = serde_json::from_str(json).unwrap();
    assert!(v["receipts"]
        .as_array()
        .unwrap()
        .iter()
        .all(|r| r["name"] != "limit_cycle"));
    assert!(v["control"]["not_applicable"]
        .as_array()
        .unwrap()
        .iter()
        .any(|n| n["name"] == "limit_cycle"));
}

/// The loop the chosen controller's analysis uses: its linear part is G0·K of that controller
/// (not the PID), evaluated independently from the two models, and its simulation steps that
/// controller: with a drive saturation far above any command the loop is linear, and a kick at
/// the plant input gives the output of G0/(1 + G0·K) computed here sample by sample.
#[test]
fn the_analysed_loop_is_the_chosen_controllers() {
    let run = run_all();
    let model = run.model().clone();
    let pid = run.tuned().unwrap().discrete.clone().unwrap();
    for m in [ControlMethod::Loopshape, ControlMethod::Hinf] {
        let c = method(&run, m).control.as_ref().unwrap();
        let k: &StateSpace = c.controller_ss.as_ref().unwrap();
        let law = chosen_law(c, model.ts).unwrap().unwrap();
        let lp = LureLoop::new(&model, &pid, VelocitySource::Output)
            .unwrap()
            .with_controller(k, law)
            .unwrap();
        let mut worst = 0.0f64;
        for f in [0.5, 3.0, 8.0, 25.0, 50.0, 200.0] {
            let w = 2.0 * std::f64::consts::PI * f;
            let g = model.freq_response_siso(f).unwrap();
            let kk = k.freq_response_siso(f).unwrap();
            let l = lp.linear_part(Site::Drive, w).unwrap();
            let v = lp.linear_part(Site::Velocity, w).unwrap();
            let one = Complex64::new(1.0, 0.0);
            worst = worst.max((l - kk * g).norm() / (kk * g).norm());
            // Friction path with the discrete G0 as its own continuous equivalent's ZOH: the
            // loop part 1/(1 + K·G) is the chosen controller's.
            let gc = lp
                .plant_continuous
                .as_ref()
                .unwrap()
                .freq_response(w)
                .unwrap()[(0, 0)];
            let expect = gc / (one + kk * g);
            worst = worst.max((v - expect).norm() / expect.norm());
            // And not the PID's (the two controllers differ at these frequencies).
            let kp = LureLoop::new(&model, &pid, VelocitySource::Output)
                .unwrap()
                .controller_response(w)
                .unwrap();
            assert!(
                (kp - kk).norm() > 1e-3 * kk.norm(),
                "{} at {f} Hz",
                m.name()
            );
        }
        assert!(worst < 1e-9, "{}: linear part off by {worst:e}", m.name());

        // Simulation: linear loop (saturation never reached), kick 0.05 N·m for 5 samples.
        let nl = Nonlinearity {
            df: DescribingFunction::Saturation { limit: 1e9 },
            site: Site::Drive,
        };
        let spec = SimSpec::new(0.5, 0.05);
        let sim = simulate(&lp, &nl, None, &spec).unwrap();
        let mut kf = SsFilter::new(k).unwrap();
        let n = model.n_states();
        let mut x = vec![0.0; n];
        let mut w_prev = 0.0;
        let mut err = 0.0f64;
        let mut peak = 0.0f64;
        for (i, &ys) in sim.y.iter().enumerate() {
            let y = (0..n).map(|j| model.c[(0, j)] * x[j]).sum::<f64>() + model.d[(0, 0)] * w_prev;
            let u = kf.step(-y);
            let w = u + if i < spec.kick_samples {
                spec.kick
            } else {
                0.0
            };
            let xn: Vec<f64> = (0..n)
                .map(|r| (0..n).map(|j| model.a[(r, j)] * x[j]).sum::<f64>() + model.b[(r, 0)] * w)
                .collect();
            x = xn;
            w_prev = w;
            err = err.max((ys - y).abs());
            peak = peak.max(y.abs());
        }
        eprintln!(
            "{}: simulated vs reference max |Δy| {err:e} (peak {peak})",
            m.name()
        );
        assert!(peak > 1e-3, "the kick moves the output");
        assert!(err <= 1e-9 * peak, "{}: {err:e} of {peak}", m.name());
    }
}
