//! The pipeline's `[physical]` stage on the bundled example (examples/pipeline.toml asks for
//! the two-mass structure with Kt = 1, the input being a torque): parameters in physical units
//! with intervals in the run, receipts.json, the report and the printed summary; bad sections
//! are refused naming the key and its line.
//!
//! Truth (sim/examples/make_example_data.rs): Jm = 2e-4 kg·m², Jl = 6e-4 kg·m², k = 15 N·m/rad,
//! shaft damping c = 4.7e-3 N·m·s/rad, viscous friction 2e-3 at the motor and 3e-3 at the
//! load, Coulomb friction 0.008 N·m at the motor. The structure has viscous friction at the
//! motor only, so `b` absorbs the load-side friction (and part of the Coulomb friction) and
//! `c` comes out low: only Jm, Jl and k are compared with the truth.
use ferrosid::greybox::ParameterStatus;
use ferrosid::pipeline::physical_stage::PhysicalOutcome;
use ferrosid::pipeline::{run_pipeline, LoadedConfig};
use std::path::{Path, PathBuf};

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/pipeline.toml")
}

#[test]
fn the_bundled_example_gets_physical_parameters_near_the_truth() {
    let cfg = LoadedConfig::load(&example()).expect("config");
    let run = run_pipeline(&cfg, &|_| {}).expect("run");
    let st = match &run.physical {
        PhysicalOutcome::Fitted(st) => st,
        other => panic!("expected a fit, got {other:?}"),
    };
    assert_eq!(st.run, "high");
    assert!(st.fit.converged);
    // (name, truth, relative tolerance): the mismatch (load-side friction left out) biases
    // the estimates by ~1 %; 3 % leaves room without hiding a wrong structure.
    for (name, truth, tol) in [("Jm", 2e-4, 0.03), ("Jl", 6e-4, 0.03), ("k", 15.0, 0.03)] {
        let p = st.fit.parameter(name).expect(name);
        assert_eq!(p.status, ParameterStatus::Estimated, "{name}");
        let rel = (p.value - truth).abs() / truth;
        assert!(rel < tol, "{name} = {} against {truth} ({rel:.4})", p.value);
        let [lo, hi] = p.interval.expect("interval");
        assert!(lo < p.value && p.value < hi, "{name} interval {lo}..{hi}");
    }
    let kt = st.fit.parameter("Kt").expect("Kt");
    assert_eq!(kt.status, ParameterStatus::Known);
    assert_eq!(kt.value, 1.0);
    // receipts.json and the report carry it; the printed line names every parameter.
    let doc = ferrosid::pipeline::document::ReceiptsDocument::from_run(&run);
    let v: serde_json::Value = serde_json::from_str(&doc.to_json().unwrap()).unwrap();
    assert_eq!(v["physical"]["status"], "fitted");
    assert_eq!(v["physical"]["fit"]["parameters"][0]["name"], "Jm");
    assert_eq!(v["physical"]["fit"]["parameters"][5]["status"], "known");
    let line = run.physical.summary_line();
    for name in ["Jm", "Jl", "k ", "c ", "b ", "Kt"] {
        assert!(line.contains(name), "{line}");
    }
    let html = ferrosid::report::render_html(&run, &[]).expect("report");
    assert!(
        html.contains("<h2>Physical parameters</h2>"),
        "report section"
    );
    assert!(html.contains("known (given)"));
}

#[test]
fn bad_physical_sections_name_the_key_and_line() {
    let base = std::fs::read_to_string(example()).unwrap();
    let head = base.split("[physical]").next().unwrap().to_string();
    let cases = [
        // Torque -> speed alone fixes the parameters only up to a common scale.
        (
            "structure = \"two-mass\"\n",
            "physical.structure",
            "common scale",
        ),
        (
            "structure = \"three-mass\"\n",
            "physical.structure",
            "unknown structure",
        ),
        (
            "structure = \"two-mass\"\nknown = { Kq = 1.0 }\n",
            "physical.structure",
            "Kq",
        ),
        (
            "structure = \"two-mass\"\nknown = { Kt = 1.0 }\nrun = \"medium\"\n",
            "physical.run",
            "not a [[runs]] name",
        ),
        (
            "structure = \"two-mass\"\nknown = { Kt = 1.0 }\nconfidence = 1.5\n",
            "physical.structure",
            "confidence",
        ),
        (
            "structure = \"two-mass\"\nwhatever = 1\n",
            "whatever",
            "unknown field",
        ),
    ];
    for (body, key, what) in cases {
        let text = format!("{head}[physical]\n{body}");
        let err = LoadedConfig::from_text(&example(), &text)
            .err()
            .unwrap_or_else(|| panic!("accepted: {body}"))
            .to_string();
        assert!(err.contains("pipeline.toml"), "{err}");
        assert!(err.contains(key) && err.contains(what), "{body}: {err}");
    }
    // Without the section the stage is skipped and the summary line is empty.
    let cfg = LoadedConfig::from_text(&example(), &head).expect("no [physical]");
    assert!(cfg.config.physical.is_none());
}
