//! Stage 1 of the candidate fit: the grid of an effect's parameters over the data's scales,
//! added to a base with its poles and effects fixed ([`initial_search`]).
use super::eval::{eval_added, log_grid, Fitted, TrainData};
use super::model::{AugmentedModel, VelocitySource};
use super::resonance::resonance_grid_hz;
use super::{FRICTION_SUBSTEPS, MAX_DELAY_SAMPLES};
use crate::gap::effect::{Effect, EffectKind};
use crate::gap::friction_port::{slowest_mode, FrictionPort};
use crate::gap::place::{Candidate, Place};
use crate::gap::state_limit::limited_mode;

/// Stage 1 of [`fit_placed`]: every point of the grid of the candidate's parameters added to
/// `base` with its poles and effects fixed (the residues re-fitted at every point), on the
/// (coarse) data `td`.
pub(super) fn initial_search(
    cand: Candidate,
    td: &TrainData,
    base: &AugmentedModel,
) -> Vec<Fitted> {
    if cand.place.needs_two_mass() || base.two_mass.is_some() {
        return crate::gap::structure::initial_search_two_mass(cand, td, base);
    }
    let s = td.u_rms.max(1e-300);
    let ts = td.ts;
    let out = base.velocity;
    let m = FRICTION_SUBSTEPS;
    let place = cand.place;
    let on_grid = |grid: &[f64], make: &dyn Fn(f64) -> Effect| -> Vec<Fitted> {
        grid.iter()
            .filter_map(|&p| eval_added(td, base, make(p), place, out, m))
            .collect()
    };
    match cand.kind {
        EffectKind::CoulombFriction => {
            // Sample-rate friction (only the basin matters here). The velocity follows from
            // the structure: the derivative of the output when the linear part integrates
            // (position output); otherwise both proxies are tried.
            let grid = log_grid(0.01 * s, 1.5 * s, 12);
            let mut all = Vec::new();
            let sources: &[(VelocitySource, FrictionPort)] = if base.linear.real.contains(&1.0) {
                &[(VelocitySource::OutputDerivative, FrictionPort::Input)]
            } else if place == Place::Motor && slowest_mode(&base.linear).is_some() {
                &[
                    (VelocitySource::Output, FrictionPort::Input),
                    (VelocitySource::OutputDerivative, FrictionPort::Input),
                    (VelocitySource::Output, FrictionPort::SlowestMode),
                ]
            } else {
                &[
                    (VelocitySource::Output, FrictionPort::Input),
                    (VelocitySource::OutputDerivative, FrictionPort::Input),
                ]
            };
            for &(vel, port) in sources {
                all.extend(grid.iter().filter_map(|&p| {
                    let mut b = base.clone();
                    b.friction_port = port;
                    eval_added(td, &b, Effect::CoulombFriction { level: p }, place, vel, 1)
                }));
            }
            all
        }
        EffectKind::Backlash => on_grid(&log_grid(0.01 * s, 2.0 * s, 16), &|p| Effect::Backlash {
            gap: p,
        }),
        EffectKind::Deadzone => on_grid(&log_grid(0.01 * s, 2.0 * s, 16), &|p| Effect::Deadzone {
            width: p,
        }),
        EffectKind::Saturation if place == Place::Sensor => {
            let y_peak = td
                .base
                .y
                .iter()
                .flat_map(|y| y.iter())
                .fold(0.0f64, |a, v| a.max(v.abs()));
            on_grid(&log_grid(0.6 * y_peak, 1.02 * y_peak, 12), &|p| {
                Effect::Saturation { limit: p }
            })
        }
        EffectKind::Saturation => {
            let hi = td.u_peak.max(0.25 * s);
            on_grid(&log_grid(0.2 * s, hi, 16), &|p| Effect::Saturation {
                limit: p,
            })
        }
        EffectKind::TimeDelay => {
            let grid: Vec<f64> = (0..=(2.0 * MAX_DELAY_SAMPLES) as usize)
                .map(|i| 0.5 * i as f64 * ts)
                .collect();
            on_grid(&grid, &|p| Effect::TimeDelay { seconds: p })
        }
        EffectKind::SlewRate => {
            let dmax =
                td.u.iter()
                    .flat_map(|u| u.windows(2).map(|w| (w[1] - w[0]).abs()))
                    .fold(0.0f64, f64::max);
            if dmax <= 0.0 {
                return Vec::new();
            }
            on_grid(&log_grid(0.03 * dmax / ts, dmax / ts, 12), &|p| {
                Effect::SlewRate { rate: p }
            })
        }
        EffectKind::Resonance => {
            let mut all = Vec::new();
            for f in resonance_grid_hz(td, base) {
                for &z in &[0.02, 0.1] {
                    all.extend(eval_added(
                        td,
                        base,
                        Effect::Resonance {
                            freq_hz: f,
                            damping: z,
                        },
                        place,
                        out,
                        m,
                    ));
                }
            }
            all
        }
        EffectKind::StateLimit | EffectKind::CurrentLimit => {
            // The grid spans the values the clamped quantity takes on the training inputs (in
            // input units), from a tenth of its RMS to its peak: for a state limit the limited
            // mode's level, state·(1 − p) (a slow mode low-passes the input, so its level can
            // sit far below the input's); for a current limit the input's excess over the one
            // that holds the mode, w − (1 − p)·state.
            let Some(b) = limited_mode(&base.linear) else {
                return Vec::new();
            };
            let p = base.linear.real[b];
            let rate = cand.kind == EffectKind::CurrentLimit;
            let (mut sum2, mut count, mut peak) = (0.0, 0usize, 0.0f64);
            for u in &td.u {
                let Ok(w) = base.drive_input(u) else {
                    return Vec::new();
                };
                let mut x = 0.0;
                for wk in w {
                    let excess = wk - (1.0 - p) * x;
                    x = p * x + wk;
                    let v = if rate { excess } else { x * (1.0 - p) };
                    sum2 += v * v;
                    count += 1;
                    peak = peak.max(v.abs());
                }
            }
            let rms = (sum2 / count.max(1) as f64).sqrt();
            if !(rms > 0.0 && peak.is_finite()) {
                return Vec::new();
            }
            on_grid(&log_grid(0.1 * rms, peak, 16), &|v| {
                if rate {
                    Effect::CurrentLimit { limit: v }
                } else {
                    Effect::StateLimit { limit: v }
                }
            })
        }
        EffectKind::Stiction | EffectKind::Quantization => Vec::new(),
    }
}
