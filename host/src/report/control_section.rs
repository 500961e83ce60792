//! The report's "Chosen controller" section for `[control] method = "loopshape" | "hinf" |
//! "mpc"`
//! ([`crate::pipeline::control_stage`]): the design (notches or H∞ levels and weights), a
//! comparison table of the chosen loop against the PID baseline on the same plant, the Bode
//! plot of L (figure `control_loop`), |S| and |T| against 1/|W_m| (`control_sensitivity`) and
//! the saturated step (`control_step`). Nothing is rendered for `pid`.
use super::charts::{db, thin};
use super::{esc, figure_html, Figure, FIG_WIDTH};
use crate::error::Result;
use crate::pipeline::control_stage::{ControlOutcome, DesignSummary};
use crate::pipeline::{fmt_num, PipelineRun};
use crate::plot::{self, colors, Kind, LegendAt, Panel, RefLine, Series};
use crate::robust::receipts::Receipt;
use std::fmt::Write as _;

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
            caption: format!(
                "Loop transfer L = G0·K of the {m} controller (sampled loop); lowest gain \
                 crossover {} Hz.",
                c.gain_crossover_hz.map_or("none".into(), fmt_num)
            ),
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
            caption: format!(
                "|S| and |T| of the {m} loop against 1/|W_m|: robust stability needs |T| < \
                 1/|W_m| at every frequency."
            ),
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
            caption: format!(
                "Saturated step of the {} loop: {} {} against rails ±{} {}; overshoot {} %, \
                 settling {}.",
                c.method.name(),
                fmt_num(s.amplitude),
                sig.output_unit,
                fmt_num(s.actuator_limit),
                sig.input_unit,
                fmt_num(s.overshoot_pct),
                s.settling_time_s
                    .map_or("not reached".into(), |t| format!("{} s", fmt_num(t)))
            ) + &step_effect_caption(c.step_effect.as_ref()),
            svg: plot::render("control_step", FIG_WIDTH, &[(py, 260), (pu, 220)])?,
        });
    }
    Ok(out)
}

/// The caption's note on the diagnosed effect an MPC step simulates between the controller and
/// G0 (empty when none is simulated: the step is G0's).
fn step_effect_caption(e: Option<&crate::pipeline::control_mpc::StepEffect>) -> String {
    match e {
        Some(e) if e.simulated => {
            let params = e.params.as_ref().map_or(String::new(), |p| {
                let v: Vec<String> = p
                    .iter()
                    .map(|(k, v)| format!("{k} {}", fmt_num(*v)))
                    .collect();
                format!(" ({})", v.join(", "))
            });
            format!(
                " With the diagnosed {}{} at {} in the loop; the command is the controller's, \
                 before the effect (the same step on G0 alone: control.linear_step_receipts).",
                e.effect.as_deref().unwrap_or("effect"),
                params,
                e.place.as_deref().unwrap_or("?")
            )
        }
        _ => String::new(),
    }
}

/// Writes the section (nothing for `pid`).
pub(crate) fn render(h: &mut String, run: &PipelineRun, figs: &[Figure]) {
    let Some(c) = run.control.as_ref() else {
        return;
    };
    let _ = writeln!(
        h,
        "<section id=\"chosen-controller\">\n<h2>Chosen controller: {}</h2>",
        esc(c.method.name())
    );
    if let Some(e) = &c.error {
        let _ = writeln!(h, "<p><b>No controller.</b> {}</p>", esc(e));
    }
    if let Some(d) = &c.design {
        design_table(h, d);
    }
    if c.status == "designed" {
        comparison(h, c);
    }
    if !c.not_applicable.is_empty() {
        h.push_str("<p>Receipts that do not apply to this method:</p>\n<ul>\n");
        for n in &c.not_applicable {
            let _ = writeln!(h, "<li><b>{}</b>: {}</li>", esc(&n.name), esc(&n.reason));
        }
        h.push_str("</ul>\n");
    }
    for name in ["control_loop", "control_sensitivity", "control_step"] {
        figure_html(h, figs, name);
    }
    h.push_str("</section>\n");
}

/// The design as a key/value table, one function per method.
fn design_table(h: &mut String, d: &DesignSummary) {
    let mut rows = Vec::new();
    let mut row = |k: &'static str, v: String| rows.push((k, v));
    match d {
        DesignSummary::Loopshape { .. } => loopshape_rows(d, &mut row),
        DesignSummary::Hinf { .. } => hinf_rows(d, &mut row),
        DesignSummary::Mpc { .. } => mpc_rows(d, &mut row),
    }
    super::kv_table(h, &rows);
}

/// Rows of a `loopshape` design.
fn loopshape_rows(d: &DesignSummary, row: &mut dyn FnMut(&'static str, String)) {
    let DesignSummary::Loopshape {
        pid,
        design,
        notches,
        notch_max_damping,
        ..
    } = d
    else {
        return;
    };
    {
        row(
            "PID",
            format!(
                "Kp {}, Ki {} 1/s, Kd {} s, τ_f {} s; design crossover {} Hz",
                fmt_num(pid.kp),
                fmt_num(pid.ki),
                fmt_num(pid.kd),
                fmt_num(pid.tau_f),
                fmt_num(design.crossover_hz)
            ),
        );
        for n in notches {
            row(
                "notch",
                format!(
                    "centre {} Hz, depth {} dB (ζ_n {}, ζ_d {})",
                    fmt_num(n.centre_hz),
                    fmt_num(n.depth_db()),
                    fmt_num(n.zeta_num),
                    fmt_num(n.zeta_den)
                ),
            );
        }
        row(
            "notched modes",
            format!("damping below {}", fmt_num(*notch_max_damping)),
        );
    }
}

/// Rows of an `hinf` design.
fn hinf_rows(d: &DesignSummary, row: &mut dyn FnMut(&'static str, String)) {
    let DesignSummary::Hinf {
        bandwidth_hz,
        ws_floor,
        ws_rolloff_hz,
        wks,
        wt_order,
        gamma_lower,
        gamma_upper,
        gamma,
        closed_loop_gamma,
        riccati_residuals,
        order,
        controller_stable,
        reduction,
        ..
    } = d
    else {
        return;
    };
    {
        row(
            "weights",
            format!(
                "W_S bandwidth {} Hz (floor {}, roll-off {} Hz), W_KS {}, W_T = W_m {}",
                fmt_num(*bandwidth_hz),
                fmt_num(*ws_floor),
                fmt_num(*ws_rolloff_hz),
                fmt_num(*wks),
                wt_order.map_or("absent".into(), |o| format!("(order {o})"))
            ),
        );
        row(
            "γ",
            format!(
                "γ_opt in [{}, {}], built at {}, closed loop {} (recomputed from G and K)",
                fmt_num(*gamma_lower),
                fmt_num(*gamma_upper),
                fmt_num(*gamma),
                fmt_num(*closed_loop_gamma)
            ),
        );
        row(
            "controller",
            format!(
                "order {order}, {}; Riccati residuals {:.1e}, {:.1e}",
                if *controller_stable {
                    "stable"
                } else {
                    "unstable"
                },
                riccati_residuals[0],
                riccati_residuals[1]
            ),
        );
        if let Some(r) = reduction {
            row(
                "reduction",
                format!(
                    "balanced truncation {} → {} states before Tustin: ‖K − K_r‖∞ {} ≤ \
                         bound 2Σσ {} (σ_{} = {}); receipts of the full-order loop: {}",
                    r.full_order,
                    r.order,
                    fmt_num(r.measured_error),
                    fmt_num(r.error_bound),
                    r.order + 1,
                    fmt_num(
                        r.hankel_singular_values
                            .get(r.order)
                            .copied()
                            .unwrap_or(0.0)
                    ),
                    r.receipts_before.as_ref().map_or("—".into(), |b| {
                        b.receipts
                            .iter()
                            .map(|x| format!("{} {}", x.name, x.value_text))
                            .collect::<Vec<_>>()
                            .join(", ")
                    })
                ),
            );
        }
    }
}

/// Rows of an `mpc` design.
fn mpc_rows(d: &DesignSummary, row: &mut dyn FnMut(&'static str, String)) {
    let DesignSummary::Mpc {
        spec,
        sigma,
        model_states,
        unconstrained_kx,
        unconstrained_kr,
        unconstrained_ku,
        unconstrained_pole_modulus,
        unconstrained_bandwidth_hz,
        step_max_abs_du,
        step_max_raw_excess,
    } = d
    else {
        return;
    };
    {
        row(
            "QP",
            format!(
                "horizon N = {}, output weight q {}, rate weight ρ_Δ {}, box [{}, {}], \
                     |Δu| ≤ {} per sample; prediction model G0 ({model_states} states, state \
                     feedback)",
                spec.horizon,
                fmt_num(spec.output_weight),
                fmt_num(spec.rate_weight),
                fmt_num(spec.u_min),
                fmt_num(spec.u_max),
                fmt_num(spec.rate_limit)
            ),
        );
        row(
            "solver",
            format!(
                "ADMM, ρ {}, σ {:.1e}, {} iterations per sample from the shifted previous \
                     solution (the firmware's budget)",
                fmt_num(spec.rho),
                sigma,
                spec.iterations
            ),
        );
        row(
            "unconstrained law",
            format!(
                "u = −k_x·x + {}·r + {}·u_prev, k_x = [{}]; closed-loop pole modulus {}, \
                     −3 dB bandwidth {}",
                fmt_num(*unconstrained_kr),
                fmt_num(*unconstrained_ku),
                unconstrained_kx
                    .iter()
                    .map(|v| fmt_num(*v))
                    .collect::<Vec<_>>()
                    .join(", "),
                fmt_num(*unconstrained_pole_modulus),
                unconstrained_bandwidth_hz
                    .map_or("above Nyquist".into(), |f| format!("{} Hz", fmt_num(f)))
            ),
        );
        row(
            "constrained step",
            format!(
                "largest |Δu| {}; raw ADMM U₀ at most {} outside the box before the clamp",
                fmt_num(*step_max_abs_du),
                fmt_num(*step_max_raw_excess)
            ),
        );
    }
}

/// The chosen loop's receipts next to the PID baseline's.
fn comparison(h: &mut String, c: &ControlOutcome) {
    let what = if matches!(c.design, Some(DesignSummary::Mpc { .. })) {
        "−3 dB bandwidth of the MPC's unconstrained closed loop"
    } else {
        "Lowest gain crossover"
    };
    let _ = writeln!(
        h,
        "<p>{what} {} Hz against the PID baseline's crossover {} Hz on the same plant. \
         The chosen controller's receipts replace the PID's in the receipts table.</p>",
        c.gain_crossover_hz.map_or("none".into(), fmt_num),
        c.baseline_pid_crossover_hz.map_or("n/a".into(), fmt_num)
    );
    h.push_str(
        "<table>\n<tr><th>receipt</th><th>chosen</th><th>PID baseline</th><th>limit</th></tr>\n",
    );
    let cell = |r: Option<&Receipt>| {
        r.map_or("—".to_string(), |r| {
            format!("{} {}", r.value_text, if r.pass { "pass" } else { "FAIL" })
        })
    };
    for r in &c.receipts.receipts {
        let base = c.replaced_pid_receipts.iter().find(|b| b.name == r.name);
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{} {} {}</td></tr>",
            esc(&r.name),
            esc(&cell(Some(r))),
            esc(&cell(base)),
            r.comparison.symbol(),
            fmt_num(r.limit),
            esc(&r.unit)
        );
    }
    h.push_str("</table>\n");
}
