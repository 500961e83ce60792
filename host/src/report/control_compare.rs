//! The report's "Controller comparison" section for `[control] methods = [...]` with two or more
//! methods: one row per method from [`crate::pipeline::control_methods::comparison_rows`] (each
//! number is that method's receipt: the same value its own `receipts.<method>.json` holds).
//! Nothing is rendered with one method. Markup in `templates/report/control_compare.html`.
use super::append;
use crate::error::Result;
use crate::pipeline::control_methods::{comparison_rows, ComparisonRow, Structure};
use crate::pipeline::{fmt_num, PipelineRun};
use askama::Template;

fn num(v: Option<f64>) -> String {
    v.map_or("n/a".into(), |v| {
        if v.is_finite() {
            fmt_num(v)
        } else {
            "—".into()
        }
    })
}

fn structure_text(r: &ComparisonRow) -> String {
    match (r.structure, r.controller_order) {
        (Some(Structure::Pid { rolloff }), n) => format!(
            "PID{} ({} states)",
            if rolloff { " + roll-off" } else { "" },
            n.map_or("?".into(), |n| n.to_string())
        ),
        (Some(Structure::PidNotch { notches }), n) => format!(
            "PID + roll-off + {notches} notch{} ({} states)",
            if notches == 1 { "" } else { "es" },
            n.map_or("?".into(), |n| n.to_string())
        ),
        (Some(Structure::StateSpace { order }), _) => format!("state space, order {order}"),
        (
            Some(Structure::Mpc {
                horizon,
                iterations,
            }),
            _,
        ) => format!("MPC, N = {horizon}, {iterations} iterations (not LTI)"),
        (None, _) => "none".into(),
    }
}

/// One table row as the template prints it (text; the template escapes it).
struct Row {
    all_pass: bool,
    method: &'static str,
    design_failed: bool,
    receipts_file: String,
    crossover: String,
    crossover_kind: &'static str,
    sensitivity_peak: String,
    wm_t_peak: String,
    effort: String,
    limit: String,
    overshoot: String,
    step_effect: Option<String>,
    settling: String,
    structure: String,
    cost: String,
    receipts: usize,
    failed: Vec<String>,
}

impl Row {
    fn of(r: &ComparisonRow) -> Self {
        Self {
            all_pass: r.all_pass,
            method: r.method.name(),
            design_failed: r.status != "designed",
            receipts_file: r.receipts_file.clone(),
            crossover: num(r.crossover_hz),
            crossover_kind: r.crossover_kind,
            sensitivity_peak: num(r.sensitivity_peak),
            wm_t_peak: num(r.wm_t_peak),
            effort: num(r.peak_control_effort),
            limit: fmt_num(r.actuator_limit),
            overshoot: num(r.step_overshoot_pct),
            step_effect: r.step_effect.clone(),
            settling: num(r.step_settling_s),
            structure: structure_text(r),
            cost: r.target_cost.map_or("not measured".into(), |c| {
                format!(
                    "{:.0}{} ({})",
                    c.mean,
                    c.max.map_or(String::new(), |m| format!(" / max {m:.0}")),
                    c.source
                )
            }),
            receipts: r.receipts,
            failed: r.failed.clone(),
        }
    }
}

#[derive(Template)]
#[template(path = "report/control_compare.html")]
struct Compare<'a> {
    reference: String,
    output_unit: &'a str,
    input_unit: &'a str,
    rows: Vec<Row>,
}

/// Writes the section (nothing with fewer than two methods).
pub(crate) fn render(h: &mut String, run: &PipelineRun) -> Result<()> {
    let rows = comparison_rows(run);
    if rows.len() < 2 {
        return Ok(());
    }
    let sig = &run.config.signals;
    append(
        h,
        &Compare {
            reference: fmt_num(run.config.control.reference_amplitude),
            output_unit: &sig.output_unit,
            input_unit: &sig.input_unit,
            rows: rows.iter().map(Row::of).collect(),
        },
    )
}
