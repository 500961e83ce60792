//! The report's "Controller comparison" section for `[control] methods = [...]` with two or more
//! methods: one row per method from [`crate::pipeline::control_methods::comparison_rows`] (each
//! number is that method's receipt: the same value its own `receipts.<method>.json` holds).
//! Nothing is rendered with one method.
use super::esc;
use crate::pipeline::control_methods::{comparison_rows, ComparisonRow, Structure};
use crate::pipeline::{fmt_num, PipelineRun};
use std::fmt::Write as _;

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

/// Writes the section (nothing with fewer than two methods).
pub(crate) fn render(h: &mut String, run: &PipelineRun) {
    let rows = comparison_rows(run);
    if rows.len() < 2 {
        return;
    }
    let sig = &run.config.signals;
    h.push_str("<section id=\"control-comparison\">\n<h2>Controller comparison</h2>\n");
    let _ = writeln!(
        h,
        "<p class=\"note\">Every method designed on the same G0 and W_m (<code>[control] \
         methods</code>); the first is the primary (its receipts are the report's and \
         <code>receipts.json</code>'s). Each number is that method's receipt; n/a: the receipt \
         does not apply (MPC: no LTI output-feedback K) or the design failed. Effort is \
         ‖KS‖∞·{} {} against the actuator limit; the step is the saturated {} {} step.</p>",
        esc(&fmt_num(run.config.control.reference_amplitude)),
        esc(&sig.output_unit),
        esc(&fmt_num(run.config.control.reference_amplitude)),
        esc(&sig.output_unit),
    );
    h.push_str(
        "<table>\n<tr><th>method</th><th>crossover (Hz)</th><th>M_s</th><th>‖W_m T‖∞</th>\
         <th>peak effort / limit</th><th>overshoot (%)</th><th>settling (s)</th>\
         <th>controller</th><th>instructions / step on target</th><th>receipts</th></tr>\n",
    );
    for r in &rows {
        let cost = r.target_cost.map_or("not measured".into(), |c| {
            format!(
                "{:.0}{} ({})",
                c.mean,
                c.max.map_or(String::new(), |m| format!(" / max {m:.0}")),
                c.source
            )
        });
        let verdict = if r.all_pass {
            format!("<span class=\"badge pass\">all {} pass</span>", r.receipts)
        } else {
            format!(
                "<span class=\"badge fail\">{} of {} fail</span> {}",
                r.failed.len(),
                r.receipts,
                esc(&r.failed.join(", "))
            )
        };
        let _ = writeln!(
            h,
            "<tr{}><td>{}{}<br><span class=\"note\">{}</span></td><td class=\"num\">{}<br>\
             <span class=\"note\">{}</span></td><td class=\"num\">{}</td><td class=\"num\">{}\
             </td><td class=\"num\">{} / {} {}</td><td class=\"num\">{}</td><td class=\"num\">{}\
             </td><td>{}</td><td>{}</td><td>{}</td></tr>",
            if r.all_pass { "" } else { " class=\"fail\"" },
            esc(r.method.name()),
            if r.status == "designed" {
                ""
            } else {
                " (design failed)"
            },
            esc(&r.receipts_file),
            num(r.crossover_hz),
            esc(r.crossover_kind),
            num(r.sensitivity_peak),
            num(r.wm_t_peak),
            num(r.peak_control_effort),
            esc(&fmt_num(r.actuator_limit)),
            esc(&sig.input_unit),
            num(r.step_overshoot_pct)
                + &r.step_effect.as_ref().map_or(String::new(), |e| {
                    format!("<br><span class=\"note\">with {}</span>", esc(e))
                }),
            num(r.step_settling_s),
            esc(&structure_text(r)),
            esc(&cost),
            verdict
        );
    }
    h.push_str("</table>\n</section>\n");
}
