//! Fitted parameters the logs themselves contradict: a candidate whose fit lowers the cost may
//! still describe a plant the data rule out, and such a candidate is rejected with the reason
//! in the notes before it can be ranked.
//!
//! * a **sensor clip** whose limit lies below readings present in the very logs it was fitted
//!   on (a sensor cannot report beyond its range): more than [`MAX_SHARE_BEYOND_CLIP`] of the
//!   raw training readings beyond [`CLIP_TOL`] times the limit;
//! * **friction** on logs whose velocity never reverses: a friction force of constant sign is an
//!   input offset, so its level is not identifiable (fewer than [`MIN_REVERSALS`] reversals
//!   over all training logs);
//! * a **resonance** where the training inputs carry no power (their Welch PSD there below
//!   [`MIN_INPUT_POWER`] of its peak, in every log): a mode the data never excited is not
//!   identifiable, and a fit that puts one there shapes the residual, it does not find a mode;
//! * a **time delay** that, added to the sample alignment of the logs, stays within
//!   ±[`crate::gap::align::MAX_ALIGNMENT`] samples: a lag of that size is the alignment's to hold
//!   (a logging offset and a dead time are the same thing in input/output data), and the
//!   alignment estimate, with its likelihood-ratio test, has already weighed it.
use super::dwell::velocity_signal;
use crate::gap::align::MAX_ALIGNMENT;
use crate::gap::effect::Effect;
use crate::gap::fit::VelocitySource;
use crate::gap::place::{Place, PlacedEffect};
use crate::spectral::Welch;

/// Raw readings may exceed a fitted sensor clip by this factor (noise on a clipped reading).
pub const CLIP_TOL: f64 = 1.02;

/// Share of the raw training readings beyond [`CLIP_TOL`]·limit that contradicts a sensor clip.
pub const MAX_SHARE_BEYOND_CLIP: f64 = 1e-3;

/// Fewest velocity reversals (sign changes through a hysteresis band of
/// [`REVERSAL_BAND`]·RMS of the velocity) that make a friction level identifiable.
pub const MIN_REVERSALS: usize = 2;

/// Hysteresis band of a velocity reversal, relative to the velocity's RMS.
pub const REVERSAL_BAND: f64 = 0.05;

/// Input PSD below this share of its peak marks a frequency the training inputs did not excite
/// (−30 dB).
pub const MIN_INPUT_POWER: f64 = 1e-3;

/// What the raw training logs say about the candidates' parameters.
#[derive(Debug, Clone)]
pub(crate) struct DataFacts {
    /// |raw reading| over every training log, ascending.
    abs_sorted: Vec<f64>,
    /// Velocity reversals over every training log.
    reversals: usize,
    /// Bin frequencies (Hz) and the largest over the training inputs of their PSD relative to
    /// its own peak; empty when no PSD could be taken (logs too short).
    input_band: (Vec<f64>, Vec<f64>),
    /// Sample alignment already applied to the logs, samples.
    alignment: f64,
    /// Sample time, s.
    ts: f64,
}

/// Relative input PSD of the training inputs `u` (the largest over the logs at each bin).
fn input_band(u: &[Vec<f64>], ts: f64) -> (Vec<f64>, Vec<f64>) {
    let shortest = u.iter().map(Vec::len).min().unwrap_or(0);
    let nperseg = (shortest / 8).clamp(64, 1024).next_power_of_two() / 2;
    if shortest < 2 * nperseg || nperseg < 32 {
        return (Vec::new(), Vec::new());
    }
    let w = Welch::new(nperseg);
    let mut freqs = Vec::new();
    let mut rel: Vec<f64> = Vec::new();
    for x in u {
        let Ok(p) = w.psd(x, 1.0 / ts) else { continue };
        let top = p.density.iter().cloned().fold(0.0, f64::max);
        if !(top > 0.0) {
            continue;
        }
        if rel.is_empty() {
            rel = vec![0.0; p.density.len()];
            freqs = p.freq_hz.clone();
        }
        for (r, d) in rel.iter_mut().zip(&p.density) {
            *r = r.max(d / top);
        }
    }
    (freqs, rel)
}

/// Sign changes of `v` through ±`band` (a change counts once the signal has crossed the whole
/// band).
fn reversals(v: &[f64], band: f64) -> usize {
    let mut last = 0i8;
    let mut n = 0;
    for &x in v {
        let s = if x > band {
            1
        } else if x < -band {
            -1
        } else {
            0
        };
        if s != 0 {
            if last != 0 && s != last {
                n += 1;
            }
            last = s;
        }
    }
    n
}

impl DataFacts {
    /// The facts of the raw training outputs `raw` (sample time `ts`), the velocity read as
    /// `velocity`; `warmup` samples of each log left out of the reversal count.
    pub(crate) fn of(
        raw: &[Vec<f64>],
        u: &[Vec<f64>],
        ts: f64,
        velocity: VelocitySource,
        warmup: usize,
        alignment: f64,
    ) -> Self {
        let mut abs_sorted: Vec<f64> = raw.iter().flatten().map(|v| v.abs()).collect();
        abs_sorted.sort_by(f64::total_cmp);
        let reversals = raw
            .iter()
            .map(|y| {
                let v = velocity_signal(y, ts, velocity);
                let v = v.get(warmup..).unwrap_or(&[]);
                let rms = (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
                reversals(v, REVERSAL_BAND * rms)
            })
            .sum();
        Self {
            abs_sorted,
            reversals,
            input_band: input_band(u, ts),
            alignment,
            ts,
        }
    }

    /// Relative input PSD at `f_hz` (the nearest bin), `None` without a PSD.
    fn input_power_at(&self, f_hz: f64) -> Option<f64> {
        let (f, r) = &self.input_band;
        let k = f.partition_point(|&x| x < f_hz);
        [k.checked_sub(1), Some(k)]
            .into_iter()
            .flatten()
            .filter(|&i| i < f.len())
            .min_by(|&a, &b| (f[a] - f_hz).abs().total_cmp(&(f[b] - f_hz).abs()))
            .map(|i| r[i])
    }

    /// Why the logs rule out `pe`, or `None`.
    pub(crate) fn contradiction(&self, pe: &PlacedEffect) -> Option<String> {
        match (pe.effect, pe.place) {
            (Effect::Saturation { limit }, Place::Sensor) => {
                let above = self.abs_sorted.len()
                    - self.abs_sorted.partition_point(|&v| v <= CLIP_TOL * limit);
                let share = above as f64 / self.abs_sorted.len().max(1) as f64;
                (share > MAX_SHARE_BEYOND_CLIP).then(|| {
                    format!(
                        "{pe}: rejected: {above} training readings ({:.2} %) lie beyond the fitted \
                         sensor range ±{limit:.6e} (a sensor cannot report beyond its range)",
                        100.0 * share
                    )
                })
            }
            (Effect::CoulombFriction { .. } | Effect::Stiction { .. }, _)
                if self.reversals < MIN_REVERSALS =>
            {
                Some(format!(
                    "{pe}: rejected: the velocity reverses {} time(s) in the training logs; \
                     friction of one sign is an input offset, so its level is not identifiable \
                     from these logs",
                    self.reversals
                ))
            }
            (Effect::Resonance { freq_hz, .. }, _) => self
                .input_power_at(freq_hz)
                .filter(|&p| p < MIN_INPUT_POWER)
                .map(|p| {
                    format!(
                        "{pe}: rejected: the training inputs carry {:.1} dB of their peak power \
                         at {freq_hz:.1} Hz (below {:.0} dB): a mode there is not identifiable \
                         from these logs",
                        10.0 * p.max(1e-300).log10(),
                        10.0 * MIN_INPUT_POWER.log10()
                    )
                }),
            (Effect::TimeDelay { seconds }, _)
                if (self.alignment + seconds / self.ts).abs() <= MAX_ALIGNMENT =>
            {
                Some(format!(
                    "{pe}: rejected: with the logs' alignment of {:+.2} samples the lag is {:.2} \
                     samples, within the alignment range of ±{MAX_ALIGNMENT} samples that the \
                     alignment estimate already weighed",
                    self.alignment,
                    self.alignment + seconds / self.ts
                ))
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clip(limit: f64) -> PlacedEffect {
        PlacedEffect {
            effect: Effect::Saturation { limit },
            place: Place::Sensor,
        }
    }

    fn coulomb() -> PlacedEffect {
        PlacedEffect {
            effect: Effect::CoulombFriction { level: 0.1 },
            place: Place::Motor,
        }
    }

    #[test]
    fn a_clip_below_logged_readings_is_rejected_and_one_above_them_is_not() {
        // A sine of amplitude 2 clipped at 1.5 by the sensor: readings stop at 1.5.
        let y: Vec<f64> = (0..4000)
            .map(|k| (2.0 * (k as f64 * 0.01).sin()).clamp(-1.5, 1.5))
            .collect();
        let f = DataFacts::of(&[y], &[], 1e-3, VelocitySource::Output, 0, 0.0);
        assert!(f.contradiction(&clip(1.5)).is_none());
        assert!(
            f.contradiction(&clip(1.49)).is_none(),
            "within the tolerance"
        );
        let why = f.contradiction(&clip(0.99)).expect("readings up to 1.5");
        assert!(why.contains("beyond the fitted sensor range"), "{why}");
    }

    #[test]
    fn friction_is_rejected_on_a_velocity_that_never_reverses() {
        // A velocity output that stays positive (a spinning axis with a ripple).
        let one_way: Vec<f64> = (0..4000).map(|k| 3.0 + (k as f64 * 0.02).sin()).collect();
        let f = DataFacts::of(&[one_way], &[], 1e-3, VelocitySource::Output, 0, 0.0);
        assert!(f
            .contradiction(&coulomb())
            .unwrap()
            .contains("not identifiable"));
        // The same ripple about zero reverses every half period.
        let both: Vec<f64> = (0..4000).map(|k| (k as f64 * 0.02).sin()).collect();
        let f = DataFacts::of(&[both], &[], 1e-3, VelocitySource::Output, 0, 0.0);
        assert!(f.contradiction(&coulomb()).is_none());
        assert_eq!(
            f.reversals, 25,
            "4000 samples of sin(0.02 k): 80/π ≈ 25.5 half periods"
        );
    }

    #[test]
    fn a_mode_outside_the_excited_band_and_a_delay_inside_the_alignment_range_are_rejected() {
        use crate::gap::simulator::rng::Rng;
        let mut rng = Rng::new(4);
        // Input: a 2 kHz-sampled sum of lines up to 100 Hz (nothing above).
        let ts = 5e-4;
        let phases: Vec<f64> = (0..100).map(|_| 6.283 * rng.uniform()).collect();
        let u: Vec<f64> = (0..16384)
            .map(|k| {
                (1..=100)
                    .map(|l| (6.283185307 * l as f64 * k as f64 * ts + phases[l - 1]).cos())
                    .sum()
            })
            .collect();
        let y = u.clone();
        let f = DataFacts::of(&[y], &[u], ts, VelocitySource::Output, 0, 1.0);
        let mode = |freq_hz: f64| PlacedEffect {
            effect: Effect::Resonance {
                freq_hz,
                damping: 0.05,
            },
            place: Place::Drive,
        };
        assert!(f.contradiction(&mode(60.0)).is_none());
        assert!(f
            .contradiction(&mode(400.0))
            .unwrap()
            .contains("not identifiable"));
        let delay = |samples: f64| PlacedEffect {
            effect: Effect::TimeDelay {
                seconds: samples * ts,
            },
            place: Place::Drive,
        };
        assert!(f
            .contradiction(&delay(1.5))
            .unwrap()
            .contains("alignment range"));
        assert!(
            f.contradiction(&delay(2.5)).is_none(),
            "1 + 2.5 samples is beyond ±3"
        );
    }
}
