//! Stage 2 of the candidate fit: Levenberg–Marquardt over the poles and every effect's
//! parameters at once ([`joint_fit`]), in unconstrained coordinates.
use super::eval::{Fitted, TrainData};
use super::model::AugmentedModel;
use super::{
    resonance_range_hz, JOINT_RTOL, MAX_DELAY_SAMPLES, MAX_RESONANCE_DAMPING, MIN_RESONANCE_DAMPING,
};
use crate::gap::drift::detrended;
use crate::gap::effect::{Effect, EffectKind};
use crate::gap::optim::levenberg_marquardt_steps;
use crate::gap::place::Place;

/// Unconstrained coordinates of an effect's parameters and back (see [`joint_fit`]). Stiction
/// has a third coordinate, ln v_s, only when it carries a Stribeck curve (a Karnopp stiction
/// stays one).
pub(super) fn effect_to_coords(e: &Effect, ts: f64) -> Vec<f64> {
    match *e {
        Effect::CoulombFriction { level } => vec![level.ln()],
        Effect::Stiction { .. } => stiction_coords(e),
        Effect::Backlash { gap } => vec![gap.ln()],
        Effect::Deadzone { width } => vec![width.ln()],
        Effect::Saturation { limit } => vec![limit.ln()],
        Effect::TimeDelay { seconds } => vec![seconds / ts],
        Effect::Resonance { freq_hz, damping } => vec![freq_hz.ln(), damping.ln()],
        Effect::Quantization { step } => vec![step.ln()],
        Effect::SlewRate { rate } => vec![rate.ln()],
        Effect::StateLimit { limit } | Effect::CurrentLimit { limit } => vec![limit.ln()],
    }
}

pub(super) fn effect_from_coords(kind: EffectKind, c: &[f64], ts: f64) -> Option<Effect> {
    let e = match kind {
        EffectKind::CoulombFriction => Effect::CoulombFriction { level: c[0].exp() },
        EffectKind::Stiction => stiction_from_coords(c)?,
        EffectKind::Backlash => Effect::Backlash { gap: c[0].exp() },
        EffectKind::Deadzone => Effect::Deadzone { width: c[0].exp() },
        EffectKind::Saturation => Effect::Saturation { limit: c[0].exp() },
        EffectKind::TimeDelay => {
            if c[0] < 0.0 || c[0] > MAX_DELAY_SAMPLES {
                return None;
            }
            Effect::TimeDelay { seconds: c[0] * ts }
        }
        EffectKind::Resonance => {
            let (f, z) = (c[0].exp(), c[1].exp());
            let (flo, fhi) = resonance_range_hz(ts);
            if !(flo..=fhi).contains(&f)
                || !(MIN_RESONANCE_DAMPING..=MAX_RESONANCE_DAMPING).contains(&z)
            {
                return None;
            }
            Effect::Resonance {
                freq_hz: f,
                damping: z,
            }
        }
        EffectKind::Quantization => Effect::Quantization { step: c[0].exp() },
        EffectKind::SlewRate => Effect::SlewRate { rate: c[0].exp() },
        EffectKind::StateLimit => Effect::StateLimit { limit: c[0].exp() },
        EffectKind::CurrentLimit => Effect::CurrentLimit { limit: c[0].exp() },
    };
    e.validate().ok().map(|_| e)
}

/// Coordinates of a stiction effect: ln level, ln(breakaway/level − 1) and, with a Stribeck
/// curve, ln v_s. Empty for another effect.
pub(crate) fn stiction_coords(e: &Effect) -> Vec<f64> {
    let Effect::Stiction {
        level,
        breakaway,
        stribeck_velocity,
    } = *e
    else {
        return Vec::new();
    };
    let mut c = vec![level.ln(), (breakaway / level - 1.0).max(1e-4).ln()];
    if stribeck_velocity > 0.0 {
        c.push(stribeck_velocity.ln());
    }
    c
}

/// The stiction of [`stiction_coords`] (two or three coordinates).
pub(crate) fn stiction_from_coords(c: &[f64]) -> Option<Effect> {
    let (level, excess) = (c.first()?.exp(), c.get(1)?.exp());
    Some(Effect::Stiction {
        level,
        breakaway: level * (1.0 + excess),
        stribeck_velocity: c.get(2).map_or(0.0, |v| v.exp()),
    })
}

/// Forward-difference step for an effect coordinate: 1e-3 (log units, or samples for the
/// delay) — these costs are only piecewise smooth in the parameter — and 1e-5 for the smooth
/// resonance coordinates.
pub(super) fn effect_coord_step(kind: EffectKind) -> f64 {
    match kind {
        EffectKind::Resonance => 1e-5,
        _ => 1e-3,
    }
}

/// Whether the LM refinement moves this effect's parameters (the quantization step is read
/// off the data's lattice and stays fixed).
pub(super) fn is_free(kind: EffectKind) -> bool {
    kind != EffectKind::Quantization
}

/// [`joint_fit`] from `start`, kept only when it lowers the training cost (else `start`).
pub fn refined(td: &TrainData, start: Fitted, max_iter: usize) -> Fitted {
    match joint_fit(td, &start, max_iter) {
        Some(j) if j.train_cost < start.train_cost => j,
        _ => start,
    }
}

/// Stage 2 of [`fit_placed`]: Levenberg–Marquardt on the simulated error over all parameters
/// at once, from `start`. When the linear part's input does not depend on the model (effects
/// in the drive, quantization at the sensor), the coordinates are the pole parameters and the
/// effect parameters, with residues, feedthrough and offset eliminated by variable projection
/// (exact for these structures). Otherwise (motor friction, whose force depends on the model
/// output; a sensor clip) residues, feedthrough and offset are coordinates too. Models on a
/// two-mass plant are refined in physical coordinates by [`crate::gap::structure`].
/// (Alternating between the linear part and the effect stalls: a linear part fitted to a
/// wrongly distorted input is self-consistent.)
pub fn joint_fit(td: &TrainData, start: &Fitted, max_iter: usize) -> Option<Fitted> {
    let m0 = &start.model;
    if m0.two_mass.is_some() {
        return crate::gap::structure::joint_fit_two_mass(td, start, max_iter);
    }
    let list0 = m0.effects_in_selection_order();
    if list0.is_empty() || !list0.iter().any(|p| is_free(p.effect.kind())) {
        return None;
    }
    let lin0 = &m0.linear;
    let n = lin0.n_states();
    let ts = td.ts;
    let projectable = list0.iter().all(|p| {
        p.place == Place::Drive
            || (p.place == Place::Sensor && p.effect.kind() == EffectKind::Quantization)
            || p.effect.kind().is_state_clamp()
    });
    let mut theta0 = lin0.pole_params();
    let mut steps: Vec<f64> = theta0.iter().map(|t| 1e-6 * t.abs().max(1.0)).collect();
    let mut spans: Vec<(usize, usize)> = Vec::new();
    for p in &list0 {
        let k = p.effect.kind();
        if is_free(k) {
            let c = effect_to_coords(&p.effect, ts);
            spans.push((theta0.len(), c.len()));
            steps.extend(std::iter::repeat_n(effect_coord_step(k), c.len()));
            theta0.extend(c);
        } else {
            spans.push((theta0.len(), 0));
        }
    }
    let n_eff_end = theta0.len();
    // Linear coordinates (when not projectable), scaled to O(1).
    let cmax = lin0
        .residues
        .iter()
        .fold(0.0f64, |a, b| a.max(b.abs()))
        .max(1e-300);
    let cscale: Vec<f64> = lin0
        .residues
        .iter()
        .map(|c| c.abs().max(1e-3 * cmax))
        .collect();
    let ystd = td.y_std();
    let dscale = lin0.d.abs().max(1e-3 * ystd / td.u_rms.max(1e-300));
    let use_d = lin0.use_d;
    if !projectable {
        let extra = n + usize::from(use_d) + 1;
        theta0.extend(std::iter::repeat_n(0.0, extra));
        steps.extend(std::iter::repeat_n(1e-6, extra));
    }
    let build = |th: &[f64]| -> Option<AugmentedModel> {
        let mut lin = lin0.clone();
        lin.set_pole_params(&th[..n]);
        let mut list = list0.clone();
        for (p, &(at, len)) in list.iter_mut().zip(&spans) {
            if len > 0 {
                p.effect = effect_from_coords(p.effect.kind(), &th[at..at + len], ts)?;
            }
        }
        if !projectable {
            let mut k = n_eff_end;
            for i in 0..n {
                lin.residues[i] = lin0.residues[i] + cscale[i] * th[k + i];
            }
            k += n;
            if use_d {
                lin.d = lin0.d + dscale * th[k];
                k += 1;
            }
            lin.offset = lin0.offset + ystd * th[k];
        }
        let mut m = m0.clone();
        m.linear = lin;
        m.set_effects_in_selection_order(&list);
        Some(m)
    };
    let scored = td.base.scored_samples();
    // Variable projection: residues, feedthrough and offset by least squares on the drive's
    // output (exact when the linear part's input does not depend on them).
    let project = |model: &mut AugmentedModel| -> Option<()> {
        let mut w = Vec::with_capacity(td.u.len());
        for u in &td.u {
            w.push(model.drive_input(u).ok()?);
        }
        model
            .linear
            .fit_linear_params_with_input(&td.base, &w, None)?;
        Some(())
    };
    let residuals = |th: &[f64]| -> Option<Vec<f64>> {
        let mut model = build(th)?;
        if projectable {
            project(&mut model)?;
        }
        let mut r = Vec::with_capacity(scored);
        for ((u, y), &wt) in td.u.iter().zip(&td.base.y).zip(&td.base.weight) {
            let yh = model.simulate(u).ok()?;
            let sw = wt.sqrt();
            let e = y.iter().zip(&yh).skip(td.base.warmup).map(|(a, b)| a - b);
            match td.base.drift_window {
                Some(w) => r.extend(detrended(&e.collect::<Vec<_>>(), w).iter().map(|v| sw * v)),
                None => r.extend(e.map(|v| sw * v)),
            }
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    };
    let (theta, _) = levenberg_marquardt_steps(residuals, &theta0, &steps, max_iter, JOINT_RTOL);
    let mut model = build(&theta)?;
    if projectable {
        project(&mut model)?;
    }
    Fitted::free_run(td, model)
}
