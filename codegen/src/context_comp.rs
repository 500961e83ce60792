//! The compensation block of the template context (`c.comp`): every number of a
//! [`Compensation`] as C and Rust literals, plus the few derived constants the firmware should
//! not compute itself (the velocity filter's α needs `exp`, computed here in f64).
use serde::Serialize;

use crate::compensation::{Compensation, VelocitySource};
use crate::context::{lit, Lit};
use crate::text::{c_string, comment_text, f64_text, rust_string};

/// What the templates see under `c.comp` (all numbers 0 for absent parts, flags say which are
/// present).
#[derive(Debug, Clone, Serialize)]
pub(crate) struct CompLit {
    /// A compensation block was given.
    pub has: bool,
    /// `enabled` as `1`/`0` (C) and `true`/`false` (Rust).
    pub enabled_c: String,
    pub enabled_rs: String,
    /// Provenance and law as comment lines.
    pub doc: Vec<String>,
    /// Provenance strings as C and Rust string literals.
    pub effect_c: String,
    pub effect_rs: String,
    pub place_c: String,
    pub place_rs: String,
    pub verdict_c: String,
    pub verdict_rs: String,
    pub source_c: String,
    pub source_rs: String,
    pub has_ff: bool,
    pub ff_coulomb: Lit,
    pub ff_viscous: Lit,
    pub ff_smoothing_velocity: Lit,
    /// 0 output, 1 output difference, 2 reference.
    pub ff_velocity_c: u8,
    /// The Rust `VelocitySource` expression.
    pub ff_velocity_rs: String,
    pub ff_filter_hz: Lit,
    pub ff_filter_alpha: Lit,
    /// The lag-aware form (`friction_feedforward.lag_aware`) is present.
    pub has_ff_lag: bool,
    pub ff_lag_s: Lit,
    pub ff_lag_horizon_s: Lit,
    pub ff_lag_stick_band: Lit,
    /// p = exp(−ts/lag_s), computed here in f64.
    pub ff_lag_pole: Lit,
    /// horizon_s plus the velocity estimate's own delay (ts/2 + ts(1−α)/α for the output
    /// difference, 0 otherwise): the firmware's prediction time.
    pub ff_lag_prediction_s: Lit,
    pub has_dz: bool,
    pub dz_width: Lit,
    pub dz_smoothing: Lit,
    pub has_bl: bool,
    pub bl_gap: Lit,
    pub bl_smoothing: Lit,
    pub has_aw: bool,
    pub aw_u_min: Lit,
    pub aw_u_max: Lit,
    pub aw_tracking_time_s: Lit,
    /// Back-calculation gain per sample, ts/T_t.
    pub aw_gain: Lit,
}

fn opt_text(v: Option<f64>) -> String {
    v.map_or_else(|| "n/a".to_string(), f64_text)
}

/// Builds `c.comp` for an already validated compensation (see `Compensation::validate_at`)
/// and the control sample time `ts` (s).
pub(crate) fn comp_lit(comp: Option<&Compensation>, ts: f64) -> CompLit {
    let zero = || lit(0.0);
    let mut out = CompLit {
        has: comp.is_some(),
        enabled_c: "0".into(),
        enabled_rs: "false".into(),
        doc: Vec::new(),
        effect_c: c_string(""),
        effect_rs: rust_string(""),
        place_c: c_string(""),
        place_rs: rust_string(""),
        verdict_c: c_string(""),
        verdict_rs: rust_string(""),
        source_c: c_string(""),
        source_rs: rust_string(""),
        has_ff: false,
        ff_coulomb: zero(),
        ff_viscous: zero(),
        ff_smoothing_velocity: zero(),
        ff_velocity_c: 0,
        ff_velocity_rs: "VelocitySource::Output".into(),
        ff_filter_hz: zero(),
        ff_filter_alpha: zero(),
        has_ff_lag: false,
        ff_lag_s: zero(),
        ff_lag_horizon_s: zero(),
        ff_lag_stick_band: zero(),
        ff_lag_pole: zero(),
        ff_lag_prediction_s: zero(),
        has_dz: false,
        dz_width: zero(),
        dz_smoothing: zero(),
        has_bl: false,
        bl_gap: zero(),
        bl_smoothing: zero(),
        has_aw: false,
        aw_u_min: zero(),
        aw_u_max: zero(),
        aw_tracking_time_s: zero(),
        aw_gain: zero(),
    };
    let Some(c) = comp else {
        out.doc
            .push("none given: the firmware runs the plain PID law.".into());
        return out;
    };
    let pv = &c.provenance;
    out.enabled_c = if c.enabled { "1" } else { "0" }.into();
    out.enabled_rs = c.enabled.to_string();
    out.effect_c = c_string(&pv.effect);
    out.effect_rs = rust_string(&pv.effect);
    out.place_c = c_string(&pv.place);
    out.place_rs = rust_string(&pv.place);
    out.verdict_c = c_string(&pv.verdict);
    out.verdict_rs = rust_string(&pv.verdict);
    out.source_c = c_string(&pv.source);
    out.source_rs = rust_string(&pv.source);
    out.doc.push(comment_text(&format!(
        "{}: effect {:?} at {:?}, verdict {:?}, from {}",
        if c.enabled {
            "ENABLED"
        } else {
            "DISABLED (numbers kept for inspection)"
        },
        pv.effect,
        pv.place,
        pv.verdict,
        pv.source
    )));
    out.doc.push(format!(
        "model NRMSE without the effect {}, with it {}",
        opt_text(pv.nrmse_before),
        opt_text(pv.nrmse_after)
    ));
    if let Some(ff) = &c.friction_feedforward {
        out.has_ff = true;
        out.ff_coulomb = lit(ff.coulomb);
        out.ff_viscous = lit(ff.viscous);
        out.ff_smoothing_velocity = lit(ff.smoothing_velocity);
        let mut estimate_delay = 0.0;
        let (code, rs, what) = match ff.velocity {
            VelocitySource::Output => (0, "VelocitySource::Output".to_string(), "w = y"),
            VelocitySource::OutputDifference { filter_hz } => {
                let alpha = 1.0 - (-2.0 * std::f64::consts::PI * filter_hz * ts).exp();
                estimate_delay = ts / 2.0 + ts * (1.0 - alpha) / alpha;
                out.ff_filter_hz = lit(filter_hz);
                out.ff_filter_alpha = lit(alpha);
                (
                    1,
                    format!(
                        "VelocitySource::OutputDifference {{ filter_hz: {}, alpha: {} }}",
                        out.ff_filter_hz.rs, out.ff_filter_alpha.rs
                    ),
                    "w += alpha ((y - y_prev)/ts - w)",
                )
            }
            VelocitySource::Reference => (2, "VelocitySource::Reference".to_string(), "w = r"),
        };
        out.ff_velocity_c = code;
        out.ff_velocity_rs = rs;
        match &ff.lag_aware {
            None => out.doc.push(format!(
                "friction feedforward: u_ff = {} clamp(w / {}, -1, 1) + {} w, {what}",
                f64_text(ff.coulomb),
                f64_text(ff.smoothing_velocity),
                f64_text(ff.viscous)
            )),
            Some(la) => {
                let pole = (-ts / la.lag_s).exp();
                let prediction = la.horizon_s + estimate_delay;
                out.has_ff_lag = true;
                out.ff_lag_s = lit(la.lag_s);
                out.ff_lag_horizon_s = lit(la.horizon_s);
                out.ff_lag_stick_band = lit(la.stick_band);
                out.ff_lag_pole = lit(pole);
                out.ff_lag_prediction_s = lit(prediction);
                out.doc.push(format!(
                    "lag-aware friction feedforward (actuator lag {} s, {what}): w_p = w + {} \
                     (w - w_prev)/ts; T = {} T + {} u_pid; s = sign(w_p) if |w_p| >= {} else \
                     clamp(T / {}, -1, 1); f = {} s + {} w_p; u_ff = f + {} (f - f_prev)",
                    f64_text(la.lag_s),
                    f64_text(prediction),
                    f64_text(pole),
                    f64_text(1.0 - pole),
                    f64_text(ff.smoothing_velocity),
                    f64_text(la.stick_band),
                    f64_text(ff.coulomb),
                    f64_text(ff.viscous),
                    f64_text(pole / (1.0 - pole))
                ));
            }
        }
    }
    if let Some(dz) = &c.dead_zone_inverse {
        out.has_dz = true;
        out.dz_width = lit(dz.width);
        out.dz_smoothing = lit(dz.smoothing);
        out.doc.push(format!(
            "dead-zone inverse: u_dz = u_c + {} clamp(u_c / {}, -1, 1)",
            f64_text(dz.width / 2.0),
            f64_text(dz.smoothing)
        ));
    }
    if let Some(bl) = &c.backlash_inverse {
        out.has_bl = true;
        out.bl_gap = lit(bl.gap);
        out.bl_smoothing = lit(bl.smoothing);
        out.doc.push(format!(
            "backlash inverse: o = clamp(o + {} (u_dz - u_dz_prev), -{h}, {h}), u_bl = u_dz + o",
            f64_text(bl.gap / 2.0 / bl.smoothing),
            h = f64_text(bl.gap / 2.0)
        ));
    }
    if let Some(aw) = &c.anti_windup {
        out.has_aw = true;
        out.aw_u_min = lit(aw.u_min);
        out.aw_u_max = lit(aw.u_max);
        out.aw_tracking_time_s = lit(aw.tracking_time_s);
        out.aw_gain = lit(ts / aw.tracking_time_s);
        out.doc.push(format!(
            "anti-windup: u = clamp(u_bl, {}, {}), i += {} (u - u_bl) (ts/T_t, T_t = {} s)",
            f64_text(aw.u_min),
            f64_text(aw.u_max),
            f64_text(ts / aw.tracking_time_s),
            f64_text(aw.tracking_time_s)
        ));
    }
    out
}
