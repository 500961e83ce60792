//! The report's "Chosen controller" section for `[control] method = "loopshape" | "hinf" |
//! "mpc"`
//! ([`crate::pipeline::control_stage`]): the design (notches or H∞ levels and weights), a
//! comparison table of the chosen loop against the PID baseline on the same plant, the Bode
//! plot of L (figure `control_loop`), |S| and |T| against 1/|W_m| (`control_sensitivity`) and
//! the saturated step (`control_step`). Nothing is rendered for `pid`. The section's HTML is
//! `control.html`.
use super::captions::Caption;
use super::charts::{db, thin};
use super::{append, filters, Figure, View, FIG_WIDTH};
use crate::error::Result;
use crate::pipeline::control_stage::{ControlOutcome, DesignSummary};
use crate::pipeline::PipelineRun;
use crate::plot::{self, colors, Kind, LegendAt, Panel, RefLine, Series};
use crate::robust::receipts::Receipt;
use askama::Template;

/// The section's figures (none for `pid` or a failed design).
pub(crate) fn figures(run: &PipelineRun) -> Result<Vec<Figure>> {
    let Some(c) = run.control.as_ref() else {
        return Ok(Vec::new());
    };
    let mut out = Vec::new();
    if let Some(cur) = &c.curves {
        let m = c.method.name();
        let f: &[f64] = &cur.freq_hz;
        let mut pm = Panel::new("", "", "|L| (dB)", true, false);
        let mag = f
            .iter()
            .zip(&cur.l_mag)
            .map(|(&f, &l)| (f, db(l)))
            .collect();
        pm.series
            .push(Series::new("|L|", mag, colors::BLUE, Kind::Line(2)));
        pm.hlines.push(RefLine {
            at: 0.0,
            color: colors::GREY,
            label: None,
        });
        let mut pp = Panel::new("", "frequency (Hz)", "∠L (deg)", true, false);
        let ph = f
            .iter()
            .zip(&cur.l_phase_deg)
            .map(|(&f, &p)| (f, p))
            .collect();
        pp.series
            .push(Series::new("∠L", ph, colors::BLUE, Kind::Line(2)));
        pp.hlines.push(RefLine {
            at: -180.0,
            color: colors::RED,
            label: Some("−180°".into()),
        });
        out.push(Figure {
            name: "control_loop",
            caption: Caption::ControlLoop {
                method: m,
                crossover_hz: c.gain_crossover_hz,
            }
            .text()?,
            svg: plot::render("control_loop", FIG_WIDTH, &[(pm, 260), (pp, 220)])?,
        });
        let mut ps = Panel::new("", "frequency (Hz)", "magnitude (dB)", true, false);
        for (label, v, col) in [
            ("|S|", &cur.s_mag, colors::BLUE),
            ("|T|", &cur.t_mag, colors::ORANGE),
        ] {
            let pts = f.iter().zip(v).map(|(&f, &s)| (f, db(s))).collect();
            ps.series.push(Series::new(label, pts, col, Kind::Line(2)));
        }
        if let Some(w) = &cur.inv_wm_mag {
            let pts = f.iter().zip(w).map(|(&f, &s)| (f, db(s))).collect();
            ps.series.push(Series::new(
                "1/|W_m| (|T| must stay below)",
                pts,
                colors::RED,
                Kind::Dashed(2),
            ));
        }
        ps.y_range = Some((-60.0, 20.0));
        ps.legend = LegendAt::LowerRight;
        out.push(Figure {
            name: "control_sensitivity",
            caption: Caption::ControlSensitivity { method: m }.text()?,
            svg: plot::render("control_sensitivity", FIG_WIDTH, &[(ps, 340)])?,
        });
    }
    if let Some(s) = &c.step {
        let t_end = s.t.last().copied().unwrap_or(1.0);
        let fc = c.gain_crossover_hz.unwrap_or(run.receipts_crossover_hz);
        let t_show = s
            .settling_time_s
            .map_or(t_end, |ts| (3.0 * ts).max(6.0 / fc).min(t_end));
        let k = s.t.iter().take_while(|&&t| t <= t_show).count().max(2);
        let k = k.min(s.t.len());
        let sig = &run.config.signals;
        let ylab = format!("output ({})", sig.output_unit);
        let mut py = Panel::new("", "", &ylab, false, false);
        py.series.push(Series::new(
            "y",
            thin(&s.t[..k], &s.y[..k], 3000),
            colors::BLUE,
            Kind::Line(2),
        ));
        let ulab = format!("actuator ({})", sig.input_unit);
        let mut pu = Panel::new("", "time (s)", &ulab, false, false);
        pu.series.push(Series::new(
            "u applied",
            thin(&s.t[..k], &s.u[..k], 3000),
            colors::ORANGE,
            Kind::Line(2),
        ));
        pu.series.push(Series::new(
            "u demanded",
            thin(&s.t[..k], &s.u_demand[..k], 3000),
            colors::PURPLE,
            Kind::Dashed(1),
        ));
        for at in [s.actuator_limit, -s.actuator_limit] {
            pu.hlines.push(RefLine {
                at,
                color: colors::RED,
                label: None,
            });
        }
        for p in [&mut py, &mut pu] {
            p.x_range = Some((0.0, t_show));
        }
        out.push(Figure {
            name: "control_step",
            caption: Caption::ControlStep {
                method: c.method.name(),
                s,
                output_unit: &sig.output_unit,
                input_unit: &sig.input_unit,
                effect: c.step_effect.as_ref(),
            }
            .text()?,
            svg: plot::render("control_step", FIG_WIDTH, &[(py, 260), (pu, 220)])?,
        });
    }
    Ok(out)
}

#[derive(Template)]
#[template(path = "report/control.html")]
struct Section<'a> {
    v: View<'a>,
    c: &'a ControlOutcome,
}

impl<'a> Section<'a> {
    fn fig(&self, name: &str) -> Option<&'a Figure> {
        self.v.fig(name)
    }
    fn is_mpc(&self) -> bool {
        matches!(self.c.design, Some(DesignSummary::Mpc { .. }))
    }
    /// The PID baseline's receipt of the same name as `r`, if any.
    fn baseline(&self, r: &Receipt) -> Option<&'a Receipt> {
        self.c
            .replaced_pid_receipts
            .iter()
            .find(|b| b.name == r.name)
    }
    /// The largest Hankel singular value the reduction discarded.
    fn first_discarded_hsv(&self, r: &crate::pipeline::control_stage::Reduction) -> f64 {
        r.hankel_singular_values
            .get(r.order)
            .copied()
            .unwrap_or(0.0)
    }
}

/// Writes the section (nothing for `pid`).
pub(crate) fn render(h: &mut String, v: View<'_>) -> Result<()> {
    match v.run.control.as_ref() {
        Some(c) => append(h, &Section { v, c }),
        None => Ok(()),
    }
}
