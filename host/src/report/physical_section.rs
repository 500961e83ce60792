//! The report's "Physical parameters" section: the grey-box fit of the `[physical]` structure
//! ([`crate::pipeline::physical_stage`]) — each parameter with its unit, value, interval and
//! status (estimated from the data, known because given, or undetermined by the data).
use super::esc;
use crate::greybox::ParameterStatus;
use crate::pipeline::fmt_num;
use crate::pipeline::physical_stage::PhysicalOutcome;
use std::fmt::Write as _;

/// Writes the section (a note when the pipeline file has no `[physical]` section).
pub(crate) fn render(h: &mut String, physical: &PhysicalOutcome) {
    h.push_str("<section id=\"physical\">\n<h2>Physical parameters</h2>\n");
    match physical {
        PhysicalOutcome::Skipped => h.push_str(
            "<p class=\"note\">Not run: add a <code>[physical]</code> section naming a \
             structure (docs/pipeline-schema.md).</p>\n",
        ),
        PhysicalOutcome::Failed { error } => {
            let _ = writeln!(h, "<p>The grey-box fit failed: {}</p>", esc(error));
        }
        PhysicalOutcome::Fitted(stage) => {
            let f = &stage.fit;
            let _ = writeln!(
                h,
                "<p>Structure <code>{}</code> fitted on run <code>{}</code> by output error: \
                 simulation NRMSE {} (black box of the same order {}), {} iterations{}; \
                 {} % intervals ({}).</p>",
                esc(f.structure.name()),
                esc(&stage.run),
                fmt_num(f.nrmse),
                fmt_num(f.black_box_nrmse),
                f.iterations,
                if f.converged {
                    ""
                } else {
                    ", <b>not converged</b>"
                },
                fmt_num(100.0 * f.confidence),
                esc(&f.interval_method),
            );
            h.push_str(
                "<table>\n<tr><th>parameter</th><th>meaning</th><th>value</th>\
                 <th>interval</th><th>unit</th><th>status</th></tr>\n",
            );
            for p in &f.parameters {
                let interval = p.interval.map_or_else(
                    || "—".to_string(),
                    |[lo, hi]| format!("[{}, {}]", fmt_num(lo), fmt_num(hi)),
                );
                let status = match p.status {
                    ParameterStatus::Estimated => "estimated",
                    ParameterStatus::Known => "known (given)",
                    ParameterStatus::Undetermined => "undetermined by the data",
                };
                let _ = writeln!(
                    h,
                    "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                    esc(&p.name),
                    esc(&p.description),
                    fmt_num(p.value),
                    interval,
                    esc(&p.unit),
                    status,
                );
            }
            h.push_str("</table>\n");
        }
    }
    h.push_str("</section>\n");
}
