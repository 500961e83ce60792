//! All integration tests of the `ferrosid` crate, in ONE test binary.
//!
//! Each `tests/<name>.rs` file is a module here (run one with
//! `cargo test -p ferrosid --test integration <name>::`). One binary instead of ~65: every test
//! binary links faer and the whole library statically (≈30 MB each in the dev profile), and 65
//! of them filled a CI disk (the linker died of SIGBUS, then "No space left on device"); one
//! binary also links once instead of 65 times. The support modules (`cli_support`, …) are
//! declared inside the files that use them, as before: a file loaded with `#[path]` resolves its
//! own `mod x;` next to itself, so each file still reads as it did when it was its own crate.
#[path = "bundled_example.rs"]
mod bundled_example;
#[path = "cli_codegen.rs"]
mod cli_codegen;
#[path = "cli_errors.rs"]
mod cli_errors;
#[path = "cli_frf.rs"]
mod cli_frf;
#[path = "cli_hardening.rs"]
mod cli_hardening;
#[path = "cli_hostile.rs"]
mod cli_hostile;
#[path = "cli_identify.rs"]
mod cli_identify;
#[path = "cli_real_data.rs"]
mod cli_real_data;
#[path = "closed_loop_identification.rs"]
mod closed_loop_identification;
#[path = "compensation_design.rs"]
mod compensation_design;
#[path = "compensation_stage.rs"]
mod compensation_stage;
#[path = "fleet_shard.rs"]
mod fleet_shard;
#[path = "fleet_summary.rs"]
mod fleet_summary;
#[path = "gap_benchmark.rs"]
mod gap_benchmark;
#[path = "gap_cli.rs"]
mod gap_cli;
#[path = "gap_errors.rs"]
mod gap_errors;
#[path = "gap_f16.rs"]
mod gap_f16;
#[path = "gap_honest.rs"]
mod gap_honest;
#[path = "gap_motor_bench.rs"]
mod gap_motor_bench;
#[path = "gap_nested.rs"]
mod gap_nested;
#[path = "gap_where.rs"]
mod gap_where;
#[path = "greybox_coverage.rs"]
mod greybox_coverage;
#[path = "greybox_motor_bench.rs"]
mod greybox_motor_bench;
#[path = "io_csv.rs"]
mod io_csv;
#[path = "io_mat.rs"]
mod io_mat;
#[path = "io_text.rs"]
mod io_text;
#[path = "layers.rs"]
mod layers;
#[path = "limit_cycle_coulomb_lag.rs"]
mod limit_cycle_coulomb_lag;
#[path = "limit_cycle_loops.rs"]
mod limit_cycle_loops;
#[path = "limit_cycle_misleads.rs"]
mod limit_cycle_misleads;
#[path = "limit_cycle_slowest_mode.rs"]
mod limit_cycle_slowest_mode;
#[path = "lti_models.rs"]
mod lti_models;
#[path = "n4sid_daisy.rs"]
mod n4sid_daisy;
#[path = "n4sid_errors.rs"]
mod n4sid_errors;
#[path = "n4sid_kalman.rs"]
mod n4sid_kalman;
#[path = "n4sid_known_plants.rs"]
mod n4sid_known_plants;
#[path = "n4sid_reference_case.rs"]
mod n4sid_reference_case;
#[path = "pipeline_codegen.rs"]
mod pipeline_codegen;
#[path = "pipeline_compensation.rs"]
mod pipeline_compensation;
#[path = "pipeline_control.rs"]
mod pipeline_control;
#[path = "pipeline_control_cycles.rs"]
mod pipeline_control_cycles;
#[path = "pipeline_end_to_end.rs"]
mod pipeline_end_to_end;
#[path = "pipeline_gap.rs"]
mod pipeline_gap;
#[path = "pipeline_methods.rs"]
mod pipeline_methods;
#[path = "pipeline_physical.rs"]
mod pipeline_physical;
#[path = "preprocess_record.rs"]
mod preprocess_record;
#[path = "preprocess_scipy.rs"]
mod preprocess_scipy;
#[path = "properties_hardening.rs"]
mod properties_hardening;
#[path = "rational_fit.rs"]
mod rational_fit;
#[path = "report_render.rs"]
mod report_render;
#[path = "robust_audit.rs"]
mod robust_audit;
#[path = "robust_margins.rs"]
mod robust_margins;
#[path = "robust_norms.rs"]
mod robust_norms;
#[path = "robust_pid.rs"]
mod robust_pid;
#[path = "robust_receipts.rs"]
mod robust_receipts;
#[path = "robust_step.rs"]
mod robust_step;
#[path = "robust_uncertainty.rs"]
mod robust_uncertainty;
#[path = "robust_wm_fit.rs"]
mod robust_wm_fit;
#[path = "scipy_spectra.rs"]
mod scipy_spectra;
#[path = "shared_data.rs"]
mod shared_data;
#[path = "spectral_periodic.rs"]
mod spectral_periodic;
#[path = "spectral_plants.rs"]
mod spectral_plants;
#[path = "spectral_real_data.rs"]
mod spectral_real_data;
#[path = "spectral_scipy.rs"]
mod spectral_scipy;
#[path = "synth_hinf.rs"]
mod synth_hinf;
#[path = "synth_loopshape.rs"]
mod synth_loopshape;
#[path = "synth_mpc.rs"]
mod synth_mpc;
#[path = "synth_riccati.rs"]
mod synth_riccati;
#[path = "synth_sim.rs"]
mod synth_sim;
#[path = "target_frame.rs"]
mod target_frame;
#[path = "test_models.rs"]
mod test_models;
#[path = "validate_model.rs"]
mod validate_model;

/// Every `tests/*.rs` file must be a module above: with `autotests = false` a file left out
/// would silently never run.
#[test]
fn every_test_file_is_a_module_of_this_binary() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    let this = include_str!("integration.rs");
    let mut missing = Vec::new();
    for entry in std::fs::read_dir(&dir).expect("read host/tests") {
        let path = entry.expect("dir entry").path();
        let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else {
            continue;
        };
        if path.extension().and_then(|e| e.to_str()) != Some("rs") || stem == "integration" {
            continue;
        }
        if !this.contains(&format!("#[path = \"{stem}.rs\"]\nmod {stem};")) {
            missing.push(stem.to_string());
        }
    }
    assert!(
        missing.is_empty(),
        "host/tests files not in tests/integration.rs: {missing:?}"
    );
}
