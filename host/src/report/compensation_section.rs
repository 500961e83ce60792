//! The report's "Compensation" section: what [`crate::pipeline::remedy`] did after the gap
//! diagnosis — the choice and its reason, the compensation's parameters, the
//! describing-function picture (the loop's linear part L(e^{jωT}) against −1/N(A), figure
//! `describing_function`), the simulated loop without and with the compensation (figure
//! `limit_cycle`) and the receipts before and after the choice. Both figures show the first
//! analysed effect; the tables list every effect. The section's HTML is `compensation.html`.
use super::captions::{Caption, SimOutcome};
use super::{append, filters, Figure, View, FIG_WIDTH};
use crate::error::Result;
use crate::pipeline::compensation_stage::EffectCycles;
use crate::pipeline::remedy::{CompensationOutcome, Decision};
use crate::pipeline::PipelineRun;
use crate::plot::{self, colors, Kind, LegendAt, Panel, Series};
use crate::robust::receipts::Receipt;
use askama::Template;

/// The section's figures (none unless an effect was analysed).
pub(crate) fn figures(run: &PipelineRun) -> Result<Vec<Figure>> {
    let Some(d) = run.compensation.decision() else {
        return Ok(Vec::new());
    };
    let Some(e) = d.stage.effects.first() else {
        return Ok(Vec::new());
    };
    Ok(vec![fig_describing(e)?, fig_cycle(e, run.model().ts)?])
}

fn fig_describing(e: &EffectCycles) -> Result<Figure> {
    let mut p = Panel::new("", "Re", "Im", false, false);
    let l: Vec<(f64, f64)> = e.locus.linear_part.iter().map(|q| (q.1, q.2)).collect();
    let n: Vec<(f64, f64)> = e.locus.neg_inv_n.iter().map(|q| (q.1, q.2)).collect();
    p.series.push(Series::new(
        "L(e^jωT) seen from the nonlinearity",
        l,
        colors::BLUE,
        Kind::Line(2),
    ));
    p.series
        .push(Series::new("−1/N(A)", n, colors::RED, Kind::Line(2)));
    let pts: Vec<(f64, f64)> = e
        .before
        .predicted
        .iter()
        .map(|c| (c.loop_value.0, c.loop_value.1))
        .collect();
    if !pts.is_empty() {
        p.series.push(Series::new(
            "predicted limit cycle",
            pts,
            colors::ORANGE,
            Kind::Points(5),
        ));
    }
    // Frame the intersections (or the origin region) rather than the whole locus.
    let scale = e
        .before
        .predicted
        .iter()
        .map(|c| (c.loop_value.0.abs()).max(c.loop_value.1.abs()))
        .fold(0.0, f64::max);
    let r = if scale > 0.0 {
        4.0 * scale
    } else {
        e.locus
            .linear_part
            .iter()
            .map(|q| q.1.abs().max(q.2.abs()))
            .fold(0.0, f64::max)
            .max(1e-12)
    };
    p.x_range = Some((-r, r));
    p.y_range = Some((-r, r));
    p.legend = LegendAt::LowerLeft;
    let caption = Caption::DescribingFunction {
        label: &e.label,
        cycle: e.before.predicted.first(),
    }
    .text()?;
    Ok(Figure {
        name: "describing_function",
        caption,
        svg: plot::render("describing_function", FIG_WIDTH, &[(p, 420)])?,
    })
}

fn fig_cycle(e: &EffectCycles, ts: f64) -> Result<Figure> {
    let mut p = Panel::new(
        "",
        "time (s, end of the simulation)",
        "plant output",
        false,
        false,
    );
    let trace = |y: &[f64]| -> Vec<(f64, f64)> {
        let n = y.len() as f64;
        y.iter()
            .enumerate()
            .map(|(i, &v)| ((i as f64 - n) * ts, v))
            .collect()
    };
    p.series.push(Series::new(
        "without compensation",
        trace(&e.before.output_trace),
        colors::RED,
        Kind::Line(2),
    ));
    if let Some(a) = &e.after {
        p.series.push(Series::new(
            "with compensation",
            trace(&a.output_trace),
            colors::BLUE,
            Kind::Line(2),
        ));
    }
    p.legend = LegendAt::LowerLeft;
    let caption = Caption::LimitCycle {
        label: &e.label,
        before: SimOutcome::of(&e.before),
        after: e.after.as_ref().map(SimOutcome::of),
    }
    .text()?;
    Ok(Figure {
        name: "limit_cycle",
        caption,
        svg: plot::render("limit_cycle", FIG_WIDTH, &[(p, 320)])?,
    })
}

#[derive(Template)]
#[template(path = "report/compensation.html")]
struct Section<'a>(View<'a>);

view_deref!(Section);

impl Section<'_> {
    /// The choice as receipts.json spells it.
    fn choice(&self, d: &Decision) -> String {
        serde_json::to_value(d.choice)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default()
    }
    /// The compensation block as compensation.json holds it.
    fn block_json(&self, d: &Decision) -> String {
        serde_json::to_string_pretty(&d.stage.compensation).unwrap_or_default()
    }
    /// The receipt tables: before (first design) and after the choice.
    fn receipt_tables<'d>(&self, d: &'d Decision) -> [(&'static str, &'d [Receipt]); 2] {
        [
            (
                "Receipts before (first design, no compensation)",
                &d.receipts_before,
            ),
            ("Receipts after the choice", &d.receipts_after),
        ]
    }
}

/// Appends the section to `h`.
pub(crate) fn render(h: &mut String, v: View<'_>) -> Result<()> {
    append(h, &Section(v))
}
