//! Runs a plant with its effects over a sampled input, as a data-acquisition system would see it.
//!
//! The command `u[j]` is held by a DAC from t = j·ts + `input_delay` to the next command (before
//! the first one the drive is at zero); on its way it passes the drive's static maps (dead band,
//! then saturation, then the play operator on the held values). The output is the sensor reading
//! (plant output, through the sensor mode if any) at t = k·ts − `output_delay` (zero before t = 0:
//! the plant starts at rest). Between breakpoints the system is integrated by
//! [`crate::ode::Integrator`]; noise, clipping and quantization are memoryless and applied by
//! [`measure`] afterwards. Delays are arbitrary real numbers (fractional delays included).
use crate::hybrid::Machine;
use crate::laws::{dead_band, play_operator, quantizer, Effects};
use crate::ode::{HybridSystem, Integrator, OdeError, MAXN};
use crate::plants::Plant;
use crate::rng::Xoshiro;

/// Relative tolerance of the integration (absolute tolerances: this times each state's scale).
pub const REL_TOL: f64 = 1e-9;

/// Integration counters of one run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RunStats {
    /// Accepted steps.
    pub steps: usize,
    /// Rejected steps.
    pub rejected: usize,
    /// Located events.
    pub events: usize,
    /// Output samples at which a stick-band friction body was held only by the band
    /// ([`Machine::held_by_stick_band`]): zero means the run is that of Coulomb friction.
    pub band_held_samples: usize,
}

/// The held drive command for `u` after the static maps; `play_state` is the play operator's
/// last output.
pub fn drive_command(fx: &Effects, u: f64, play_state: &mut f64) -> f64 {
    let mut w = u;
    if let Some(width) = fx.drive_deadzone {
        w = dead_band(w, width);
    }
    if let Some(lim) = fx.drive_saturation {
        w = w.clamp(-lim, lim);
    }
    if let Some(play) = fx.drive_play {
        w = play_operator(w, *play_state, play);
        *play_state = w;
    }
    w
}

/// Noise-free sensor readings of `plant` with effects `fx` driven by `u` (sample time `ts`).
/// `u_scale`, `y_scale`: input and output magnitudes (for the absolute tolerances).
pub fn simulate(
    plant: Plant,
    fx: &Effects,
    u: &[f64],
    ts: f64,
    u_scale: f64,
    y_scale: f64,
) -> Result<(Vec<f64>, RunStats), OdeError> {
    let mut m = Machine::new(plant, *fx, u_scale, y_scale, REL_TOL);
    let mut x = [0.0; MAXN];
    let mut integ = Integrator::new(REL_TOL, ts);
    let n = u.len();
    let mut y = Vec::with_capacity(n);
    let (d_in, d_out) = (fx.input_delay.max(0.0), fx.output_delay.max(0.0));
    let mut t = 0.0;
    let (mut j, mut k) = (0usize, 0usize);
    let mut play_state = 0.0;
    let mut band_held = 0usize;
    m.settle(&mut x);
    while k < n {
        let next_in = if j < n {
            j as f64 * ts + d_in
        } else {
            f64::INFINITY
        };
        let next_out = k as f64 * ts - d_out;
        let t_next = next_in.min(next_out);
        if t_next > t {
            integ.advance(&mut m, &mut x, t, t_next)?;
            t = t_next;
        }
        if next_out <= t {
            y.push(if next_out < 0.0 { 0.0 } else { m.output(&x) });
            band_held += usize::from(m.held_by_stick_band(&x));
            k += 1;
        } else {
            m.command = drive_command(fx, u[j], &mut play_state);
            m.settle(&mut x);
            j += 1;
        }
    }
    Ok((
        y,
        RunStats {
            steps: integ.steps,
            rejected: integ.rejected,
            events: integ.events,
            band_held_samples: band_held,
        },
    ))
}

/// The logged output: `clean` plus white Gaussian noise of standard deviation `noise_std`, then
/// the sensor's range (`sensor_clip`) and resolution (`quant_step`) of `fx`.
pub fn measure(clean: &[f64], fx: &Effects, noise_std: f64, rng: &mut Xoshiro) -> Vec<f64> {
    clean
        .iter()
        .map(|&v| {
            let mut r = v + noise_std * rng.normal();
            if let Some(l) = fx.sensor_clip {
                r = r.clamp(-l, l);
            }
            if let Some(q) = fx.quant_step {
                r = quantizer(r, q);
            }
            r
        })
        .collect()
}
