//! The `[control] method` switch on the bundled two-mass example (examples/pipeline.toml):
//! `pid` stays what it was, `loopshape` and `hinf` replace the loop receipts with their own,
//! computed on their sampled loop, and every new key refuses bad input with file, line and key.
use crate::bundled_example::{
    assert_bad_control_keys, codegen_axis1, example_path, report_html, run, with_control,
    without_physical,
};
use ferrosid::pipeline::{run_pipeline, LoadedConfig, PipelineRun, ReceiptsDocument};
use ferrosid::robust::loops::FeedbackLoop;
use ferrosid::robust::norms::hinf_norm;

fn json(run: &PipelineRun) -> String {
    ReceiptsDocument::from_run(run).to_json().unwrap()
}

#[test]
fn pid_is_the_default_and_writes_no_control_block() {
    let a = run("");
    let b = run("method = \"pid\"\n");
    assert!(a.control.is_none() && b.control.is_none());
    let (ja, jb) = (json(&a), json(&b));
    // Only the pipeline file's own digest and size differ (its text differs).
    let strip = |s: &str| -> String {
        s.lines()
            .filter(|l| !l.contains("\"sha256\"") && !l.contains("\"bytes\""))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(strip(&ja), strip(&jb));
    let doc: serde_json::Value = serde_json::from_str(&ja).unwrap();
    assert!(doc.get("control").is_none(), "no control block for pid");
    let html = ferrosid::report::render_html(&a, &[]).unwrap();
    assert!(!html.contains("chosen-controller"));
    assert!(doc["provenance"]["settings"]["control"]
        .get("method")
        .is_none());
    assert!(doc["provenance"]["settings"]["control"]["crossover_hz"].is_number());
}

/// Every loop receipt of the chosen controller, checked against an independent recomputation
/// of M_s and the stability of the loop from G0 and the written controller.
fn check_chosen(run: &PipelineRun, method: &str) -> (f64, f64) {
    let c = run.control.as_ref().expect("control block");
    assert_eq!(c.status, "designed", "{:?}", c.error);
    let doc: serde_json::Value = serde_json::from_str(&json(run)).unwrap();
    assert_eq!(doc["control"]["method"], method);
    let names: Vec<&str> = doc["receipts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["name"].as_str().unwrap())
        .collect();
    for r in &c.receipts.receipts {
        let top = run.receipts.get(&r.name).expect("merged");
        assert_eq!(top, r, "{} merged as is", r.name);
        eprintln!(
            "{method}: {} = {} (limit {} {}) {}",
            r.name,
            r.value_text,
            r.limit,
            r.unit,
            if r.pass { "pass" } else { "FAIL" }
        );
    }
    for n in [
        "controller_design",
        "closed_loop_stable",
        "gain_margin",
        "phase_margin",
        "sensitivity_peak",
        "robust_stability",
        "peak_control_effort",
        "step_overshoot",
    ] {
        assert_eq!(names.iter().filter(|x| **x == n).count(), 1, "{n} once");
    }
    // Independent: the loop of G0 and the controller as written (discrete, ts = model ts).
    let k = c.controller_ss.as_ref().unwrap();
    assert!((k.ts - run.model().ts).abs() < 1e-15);
    let lp = FeedbackLoop::new(run.model(), k).unwrap();
    assert!(lp.is_stable().unwrap());
    let ms = hinf_norm(&lp.s).unwrap().gamma;
    let rec = run.receipts.get("sensitivity_peak").unwrap().value;
    assert!((ms - rec).abs() <= 1e-6 * ms, "M_s {ms} vs receipt {rec}");
    // The report: the section with its three figures and the comparison against the PID.
    let html = report_html(run);
    assert!(html.contains("<section id=\"chosen-controller\">"));
    assert!(html.contains(&format!("Chosen controller: {method}")));
    for f in ["control_loop", "control_sensitivity", "control_step"] {
        assert!(html.contains(&format!("id=\"fig-{f}\"")), "{f}");
    }
    assert!(html.contains("PID baseline"));
    // Codegen: the chosen controller is in the header and the module; the header compiles
    // with the strict flags and its matrices are the written controller's.
    let input = codegen_axis1(run);
    let sk = input
        .state_controller
        .as_ref()
        .expect("state controller block");
    assert_eq!(sk.method, method);
    assert_eq!(sk.matrices.a.len(), k.n_states());
    assert_eq!(sk.matrices.c[0][0], k.c[(0, 0)]);
    let files = ferrosid_codegen::generate(&input).unwrap();
    assert!(files
        .c_header
        .contains("#define AXIS1_HAS_STATE_CONTROLLER 1"));
    assert!(files.rust_module.contains("pub fn k_step("));
    let dir = std::env::temp_dir().join(format!("ferrosid-pctl-{}-{method}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(&files.c_file_name), &files.c_header).unwrap();
    let main = dir.join("main.c");
    std::fs::write(
        &main,
        format!(
            "#include \"{}\"\nint main(void) {{ float xi[AXIS1_K_N_STATES] = {{0}}; return \
             AXIS1_k_step(xi, 1.0f) > 1e30f; }}\n",
            files.c_file_name
        ),
    )
    .unwrap();
    let st = std::process::Command::new("gcc")
        .args([
            "-std=c99",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-pedantic",
            "-c",
            "-o",
        ])
        .arg(dir.join("main.o"))
        .arg("-I")
        .arg(&dir)
        .arg(&main)
        .status()
        .expect("gcc");
    assert!(st.success(), "gcc -Werror on the generated header");
    let fc = c.gain_crossover_hz.unwrap();
    let base = c.baseline_pid_crossover_hz.unwrap();
    eprintln!(
        "{method}: crossover {fc:.3} Hz vs PID {base:.3} Hz; all pass {}",
        run.receipts.all_pass
    );
    (fc, base)
}

#[test]
fn loopshape_reaches_a_higher_crossover_than_pid_with_its_own_receipts() {
    let r = run("method = \"pid-notch\"\n");
    let (fc, base) = check_chosen(&r, "loopshape");
    assert!(fc > base * 1.2, "PID + notch {fc} Hz vs PID {base} Hz");
    for name in ["robust_stability", "sensitivity_peak", "closed_loop_stable"] {
        assert!(r.receipts.get(name).unwrap().pass, "{name}");
    }
}

#[test]
fn hinf_designs_and_issues_its_receipts() {
    let r = run("method = \"hinf\"\n");
    let (fc, base) = check_chosen(&r, "hinf");
    assert!(fc > base, "H∞ {fc} Hz vs PID {base} Hz");
    for name in ["robust_stability", "sensitivity_peak", "closed_loop_stable"] {
        assert!(r.receipts.get(name).unwrap().pass, "{name}");
    }
}

#[test]
fn reduced_hinf_controller_keeps_its_receipts_within_the_truncation_bound() {
    use ferrosid::pipeline::control_stage::DesignSummary;
    let r = run("method = \"hinf\"\nhinf_order = 4\n");
    let (fc, base) = check_chosen(&r, "hinf");
    let c = r.control.as_ref().unwrap();
    let Some(DesignSummary::Hinf {
        reduction: Some(red),
        order,
        ..
    }) = &c.design
    else {
        panic!("no reduction: {:?}", c.design);
    };
    assert_eq!(red.order, 4);
    assert_eq!(red.full_order, *order);
    assert_eq!(c.controller_ss.as_ref().unwrap().n_states(), 4);
    // Glover's bounds: σ_(r+1) ≤ ‖K − K_r‖∞ ≤ 2·Σ discarded σ.
    let hsv = &red.hankel_singular_values;
    eprintln!(
        "reduction {} → 4: ‖K − K_r‖∞ {:.4e}, bound {:.4e}, σ {:?}; crossover {fc:.3} Hz (PID \
         {base:.3})",
        red.full_order, red.measured_error, red.error_bound, hsv
    );
    assert!(red.measured_error <= red.error_bound * (1.0 + 1e-6));
    assert!(red.measured_error >= hsv[4] * (1.0 - 1e-6));
    let before = red.receipts_before.as_ref().expect("full-order receipts");
    for rc in &c.receipts.receipts {
        let Some(b) = before.get(&rc.name) else {
            assert_eq!(
                rc.name, "controller_design",
                "only the design receipt is per design"
            );
            continue;
        };
        eprintln!(
            "  {}: full {} → reduced {} ({})",
            rc.name,
            b.value_text,
            rc.value_text,
            if rc.pass { "pass" } else { "FAIL" }
        );
    }
    for name in ["closed_loop_stable", "robust_stability", "sensitivity_peak"] {
        assert!(r.receipts.get(name).unwrap().pass, "{name} after reduction");
    }
}

#[test]
fn bad_control_keys_name_file_line_and_key() {
    assert_bad_control_keys(&[
        ("method = \"mpcc\"", "control.method", "unknown variant"),
        ("method = 3", "control.method", ""),
        (
            "notch_max_damping = 0.3",
            "control.notch_max_damping",
            "only used with method = \"loopshape\"",
        ),
        (
            "method = \"loopshape\"\nnotch_max_damping = 1.5",
            "control.notch_max_damping",
            "must lie in (0, 1)",
        ),
        (
            "method = \"loopshape\"\nhinf_backoff = 0.1",
            "control.hinf_backoff",
            "only used with method = \"hinf\"",
        ),
        (
            "method = \"hinf\"\nhinf_backoff = -0.1",
            "control.hinf_backoff",
            "must lie in [0, 1]",
        ),
        (
            "method = \"hinf\"\nhinf_ws_floor = 0",
            "control.hinf_ws_floor",
            "must lie in (0, 0.5)",
        ),
        (
            "method = \"hinf\"\nhinf_ws_floor = nan",
            "control.hinf_ws_floor",
            "must lie in",
        ),
        (
            "method = \"hinf\"\nnotch_max_damping = 0.2",
            "control.notch_max_damping",
            "only used with",
        ),
        (
            "method = \"hinf\"\nhinf_gamma = 2",
            "control.hinf_gamma",
            "unknown field",
        ),
        (
            "method = \"hinf\"\nhinf_order = 0",
            "control.hinf_order",
            "must be >= 1",
        ),
        (
            "method = \"hinf\"\nhinf_order = -2",
            "control.hinf_order",
            "",
        ),
        (
            "method = \"loopshape\"\nhinf_order = 4",
            "control.hinf_order",
            "only used with",
        ),
    ]);
}

/// `method = "mpc"` on the example as it ships (`[gap] run = "always"` diagnoses Coulomb
/// friction at the motor): the top-level step receipts simulate the friction between the MPC
/// and G0, equal a direct `closed_loop_step_with`, keep the linear step in
/// `control.linear_step_receipts`, and move the way friction moves a loop without integral
/// action: less overshoot and a final error equal to the steady-state offset of the
/// unconstrained law against a constant −level at the plant input (computed here by hand).
#[test]
fn mpc_step_receipts_simulate_the_diagnosed_friction() {
    use ferrosid::gap::effect::Effect;
    let t = with_control(&without_physical(), "method = \"mpc\"\n");
    let cfg = LoadedConfig::from_text(&example_path(), &t).unwrap();
    let run = run_pipeline(&cfg, &|_| {}).unwrap();
    let report = run.gap.report().expect("the example diagnoses every run");
    assert_eq!(report.verdict, "coulomb_friction");
    let level = report.verdict_effects[0].params["level"];
    let c = run.control.as_ref().unwrap();
    let se = c.step_effect.as_ref().unwrap();
    assert!(se.simulated, "{}", se.note);
    assert_eq!(se.place.as_deref(), Some("motor"));
    let (d, g0) = c.mpc.as_ref().unwrap();
    let r = 5.0;
    let n = c.step.as_ref().unwrap().y.len();
    let with = d
        .closed_loop_step_with(g0, Some(&Effect::CoulombFriction { level }), r, n, 0.02)
        .unwrap();
    let lin = d.closed_loop_step(g0, r, n, 0.02).unwrap();
    assert_eq!(c.step.as_ref().unwrap().y, with.step.y);
    let value = |rs: &[ferrosid::robust::receipts::Receipt], name: &str| {
        let x: Vec<_> = rs.iter().filter(|x| x.name == name).collect();
        assert_eq!(x.len(), 1, "{name}");
        x[0].value
    };
    let top = &run.receipts.receipts;
    assert_eq!(value(top, "step_overshoot"), with.step.overshoot_pct);
    assert_eq!(
        value(top, "step_settling_time"),
        with.step.settling_time_s.unwrap()
    );
    assert!(top
        .iter()
        .any(|x| x.name == "step_overshoot" && x.detail.contains("coulomb_friction")));
    let linear = &c.linear_step_receipts;
    assert_eq!(value(linear, "step_overshoot"), lin.step.overshoot_pct);
    assert_eq!(
        value(linear, "step_settling_time"),
        lin.step.settling_time_s.unwrap()
    );
    assert!(with.step.overshoot_pct < lin.step.overshoot_pct);
    assert!(lin.step.final_error.abs() < 1e-6 * r);
    // Steady state of u = −k_x·x + k_r·r + k_u·u, x = A x + B (u − level): with
    // m = (I − A)⁻¹B, u (1 − k_u + k_x·m) = k_x·m·level + k_r·r, y = C m (u − level).
    let law = d.unconstrained_law().unwrap();
    let ns = g0.n_states();
    let mut aug: Vec<Vec<f64>> = (0..ns)
        .map(|i| {
            let mut row: Vec<f64> = (0..ns)
                .map(|j| f64::from(u8::from(i == j)) - g0.a[(i, j)])
                .collect();
            row.push(g0.b[(i, 0)]);
            row
        })
        .collect();
    for p in 0..ns {
        let piv = (p..ns)
            .max_by(|&a, &b| aug[a][p].abs().total_cmp(&aug[b][p].abs()))
            .unwrap();
        aug.swap(p, piv);
        for i in 0..ns {
            if i != p {
                let f = aug[i][p] / aug[p][p];
                for j in p..=ns {
                    aug[i][j] -= f * aug[p][j];
                }
            }
        }
    }
    let m: Vec<f64> = (0..ns).map(|i| aug[i][ns] / aug[i][i]).collect();
    let kxm: f64 = law.kx.iter().zip(&m).map(|(a, b)| a * b).sum();
    let cm: f64 = (0..ns).map(|j| g0.c[(0, j)] * m[j]).sum();
    let u = (kxm * level + law.kr * r) / (1.0 - law.ku + kxm);
    let offset = r - cm * (u - level);
    assert!(offset > 0.0);
    assert!(
        (with.step.final_error - offset).abs() <= 1e-3 * offset,
        "final error {} vs steady-state offset {offset}",
        with.step.final_error
    );
    let doc: serde_json::Value = serde_json::from_str(&json(&run)).unwrap();
    assert_eq!(doc["control"]["step_effect"]["simulated"], true);
    assert_eq!(
        doc["control"]["linear_step_receipts"]
            .as_array()
            .unwrap()
            .len(),
        3
    );
    // The report's step figure says the step has the friction in the loop.
    let figs = ferrosid::report::figures(&run).unwrap();
    let step = figs.iter().find(|f| f.name == "control_step").unwrap();
    assert!(
        step.caption
            .contains("With the diagnosed coulomb_friction (level "),
        "{}",
        step.caption
    );
}

/// Without a diagnosis the MPC writes neither `step_effect` nor `linear_step_receipts`.
#[test]
fn mpc_without_a_diagnosis_writes_no_effect_keys() {
    let run = run("method = \"mpc\"\n");
    assert!(run.gap.report().is_none());
    let doc: serde_json::Value = serde_json::from_str(&json(&run)).unwrap();
    assert!(doc["control"].get("step_effect").is_none());
    assert!(doc["control"].get("linear_step_receipts").is_none());
}
