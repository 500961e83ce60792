//! The report's "Gap diagnosis" section: what [`crate::pipeline::gap_stage`] found — the
//! verdict with its effects and shares, how far the gap shrinks against the noise floor, and the
//! full diagnosis as `ferrosid gap` prints it.
use super::esc;
use crate::pipeline::fmt_num;
use crate::pipeline::gap_stage::GapStage;
use std::fmt::Write as _;

/// Appends the section for `stage` to `h`.
pub(crate) fn render(h: &mut String, stage: &GapStage) {
    h.push_str("<section id=\"gap\">\n<h2>Sim-to-real gap diagnosis</h2>\n");
    match stage {
        GapStage::Skipped { reason } => {
            let _ = writeln!(h, "<p class=\"note\">Not run: {}.</p>", esc(reason));
        }
        GapStage::Failed {
            triggered_by,
            error,
        } => {
            let _ = writeln!(
                h,
                "<p>Triggered by {}, but the diagnosis failed: {}</p>",
                esc(&triggered_by.join(", ")),
                esc(error)
            );
        }
        GapStage::Diagnosed {
            triggered_by,
            report,
        } => {
            let _ = writeln!(
                h,
                "<p>Triggered by <code>{}</code>. G0 was diagnosed as the nominal sim against \
                 the runs (training) and the validation log.</p>",
                esc(&triggered_by.join(", "))
            );
            let _ = writeln!(h, "<p><b>Verdict: {}</b></p>", esc(&report.verdict));
            if !report.verdict_effects.is_empty() {
                h.push_str(
                    "<table>\n<tr><th>effect</th><th>place</th><th>parameters</th>\
                     <th>share of the shrink</th></tr>\n",
                );
                for e in &report.verdict_effects {
                    let params: Vec<String> = e
                        .params
                        .iter()
                        .map(|(k, v)| format!("{k} = {}", fmt_num(*v)))
                        .collect();
                    let _ = writeln!(
                        h,
                        "<tr><td>{}</td><td>{}</td><td>{}</td><td>{} %</td></tr>",
                        esc(&e.effect),
                        esc(&e.place),
                        esc(&params.join(", ")),
                        fmt_num(100.0 * e.share)
                    );
                }
                h.push_str("</table>\n");
            }
            let _ = writeln!(
                h,
                "<p>Free-run NRMSE on the validation log: nominal G0 {}, linear re-fit {}, with \
                 the verdict's effects {}; noise floor {} ({}).</p>",
                fmt_num(report.gap_before),
                fmt_num(report.gap_linear),
                fmt_num(report.gap_after),
                fmt_num(report.noise_floor.nrmse),
                esc(&report.noise_floor.method)
            );
            let _ = writeln!(
                h,
                "<details><summary>Full diagnosis (as <code>ferrosid gap</code> prints \
                 it)</summary>\n<pre>{}</pre>\n</details>",
                esc(&report.to_text())
            );
        }
    }
    h.push_str("</section>\n");
}
