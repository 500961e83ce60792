//! Explicit, recorded preprocessing of logs: mean removal, linear-trend removal and
//! anti-aliased decimation by an integer factor.
//!
//! Steps are applied in the order given, to every input and output channel. [`preprocess`]
//! returns the new [`Log`] and a [`Preprocessing`] record (serde `Serialize`) listing each step
//! with its parameters and the values it removed, so a report can show exactly what was done.
//! The computation is deterministic and the record holds no timestamps or hash-ordered maps:
//! the same log and steps give bit-identical data and byte-identical serialised records.
//!
//! **Decimation filter** (as `scipy.signal.decimate(x, q)` with its defaults, `ftype='iir'`,
//! `zero_phase=True`, which agrees to round-off): a Chebyshev type I low-pass of order 8 with
//! 0.05 dB passband ripple and passband edge `0.8 * fs_out / 2` (`fs_out = fs / q`), designed
//! by the bilinear transform with pre-warping, realised as second-order sections and applied
//! forward and backward (zero phase, `sosfiltfilt` with odd extension of 27 samples at both
//! ends and steady-state initial conditions); then every `q`-th sample is kept, starting with
//! the first. Because the filter runs twice, the passband ripple is 0.1 dB (DC gain -0.1 dB,
//! the ripple trough of an even-order Chebyshev filter). Stopband: at least 45.6 dB of
//! attenuation at the new Nyquist frequency `fs_out / 2` (66 dB for q = 2) and at least 83 dB
//! from `1.2 * fs_out / 2` upwards, which is where the components that alias into the
//! retained band `0 .. 0.8 * fs_out / 2` come from. Content between `0.8` and `1.0 * fs_out/2`
//! is attenuated but not removed: treat that band as unreliable after decimation.
use num_complex::Complex64;
use serde::{Deserialize, Serialize};

use crate::data::Log;
use crate::error::{Error, Result};

/// One preprocessing step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "step", rename_all = "snake_case")]
pub enum Step {
    /// Subtract each channel's mean.
    RemoveMean,
    /// Subtract each channel's least-squares straight line (offset and slope).
    RemoveTrend,
    /// Anti-aliased decimation by an integer factor >= 2 (see the module documentation).
    Decimate {
        /// Decimation factor q: the sample rate becomes fs / q.
        factor: usize,
    },
}

/// Offset removal before identification: `[preprocess].remove` of the pipeline file and
/// `--remove` of `ferrosid identify` (feature `cli`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum Removal {
    /// Subtract each channel's mean (default).
    Mean,
    /// Subtract each channel's least-squares line.
    Trend,
    /// Keep offsets (only for data already centred).
    None,
}

/// The preprocessing steps of an offset removal followed by decimation by `decimate` (none
/// when 1), in the order applied.
pub fn steps(remove: Removal, decimate: usize) -> Vec<Step> {
    let mut s = Vec::new();
    match remove {
        Removal::None => {}
        Removal::Mean => s.push(Step::RemoveMean),
        Removal::Trend => s.push(Step::RemoveTrend),
    }
    if decimate > 1 {
        s.push(Step::Decimate { factor: decimate });
    }
    s
}

/// Mean removed from one channel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RemovedMean {
    /// Channel name.
    pub channel: String,
    /// Removed mean, in the channel's units.
    pub mean: f64,
}

/// Line removed from one channel: `offset + slope_per_s * t`, t in seconds from the first
/// sample.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RemovedTrend {
    /// Channel name.
    pub channel: String,
    /// Line value at the first sample (channel units).
    pub offset: f64,
    /// Slope in channel units per second.
    pub slope_per_s: f64,
}

/// What one step did.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "step", rename_all = "snake_case")]
pub enum StepRecord {
    /// Means removed, per channel (inputs first, then outputs).
    RemoveMean {
        /// One entry per channel.
        channels: Vec<RemovedMean>,
    },
    /// Lines removed, per channel (inputs first, then outputs).
    RemoveTrend {
        /// One entry per channel.
        channels: Vec<RemovedTrend>,
    },
    /// Decimation performed.
    Decimate {
        /// Factor q.
        factor: usize,
        /// Filter description.
        filter: String,
        /// Passband edge of the anti-aliasing filter in Hz (`0.8 * fs_out / 2`).
        passband_edge_hz: f64,
        /// Sample rate before, Hz.
        fs_in_hz: f64,
        /// Sample rate after, Hz.
        fs_out_hz: f64,
        /// Samples before.
        samples_in: usize,
        /// Samples after (`ceil(samples_in / q)`).
        samples_out: usize,
    },
}

/// The record of a preprocessing run on one log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Preprocessing {
    /// The log's file path, as given.
    pub source: String,
    /// Samples before preprocessing.
    pub samples_in: usize,
    /// Samples after.
    pub samples_out: usize,
    /// Sample time before, s.
    pub ts_in: f64,
    /// Sample time after, s.
    pub ts_out: f64,
    /// The steps in the order applied.
    pub steps: Vec<StepRecord>,
}

/// Applies `steps` in order to all channels of `log`. The returned log keeps the path and the
/// warnings of the input.
///
/// Errors: [`Error::InvalidArgument`] for a decimation factor < 2; [`Error::Data`] naming the
/// file when the log is too short for a step (trend removal needs 2 samples, decimation more
/// than 27 samples and at least 2 samples after decimation).
pub fn preprocess(log: &Log, steps: &[Step]) -> Result<(Log, Preprocessing)> {
    let mut out = log.clone();
    let mut records = Vec::with_capacity(steps.len());
    for step in steps {
        let rec = match *step {
            Step::RemoveMean => {
                let mut channels = Vec::new();
                for c in out.inputs.iter_mut().chain(out.outputs.iter_mut()) {
                    let mean = mean(&c.data);
                    for v in &mut c.data {
                        *v -= mean;
                    }
                    channels.push(RemovedMean {
                        channel: c.name.clone(),
                        mean,
                    });
                }
                StepRecord::RemoveMean { channels }
            }
            Step::RemoveTrend => {
                if out.len() < 2 {
                    return Err(Error::Data {
                        file: log.path.clone(),
                        msg: "trend removal needs at least 2 samples".into(),
                    });
                }
                let ts = out.ts;
                let mut channels = Vec::new();
                for c in out.inputs.iter_mut().chain(out.outputs.iter_mut()) {
                    let (offset, slope) = remove_line(&mut c.data);
                    channels.push(RemovedTrend {
                        channel: c.name.clone(),
                        offset,
                        slope_per_s: slope / ts,
                    });
                }
                StepRecord::RemoveTrend { channels }
            }
            Step::Decimate { factor } => {
                if !(2..=MAX_DECIMATION).contains(&factor) {
                    return Err(Error::InvalidArgument(format!(
                        "decimation factor must be an integer in 2..={MAX_DECIMATION}, got \
                         {factor}"
                    )));
                }
                let n = out.len();
                let n_out = n.div_ceil(factor);
                if n <= PAD || n_out < 2 {
                    return Err(Error::Data {
                        file: log.path.clone(),
                        msg: format!(
                            "too few samples for decimation by {factor}: need more than {PAD} \
                             and at least 2 after decimating, the log has {n}"
                        ),
                    });
                }
                let sos = AntiAlias::design(factor);
                let mut work = Work::new(n);
                for c in out.inputs.iter_mut().chain(out.outputs.iter_mut()) {
                    let y = sos.filtfilt(&c.data, &mut work);
                    c.data = y.iter().step_by(factor).copied().collect();
                }
                let fs_in = out.fs();
                out.ts *= factor as f64;
                StepRecord::Decimate {
                    factor,
                    filter: "Chebyshev type I low-pass, order 8, 0.05 dB ripple, second-order \
                             sections applied forward and backward (zero phase, odd extension \
                             of 27 samples, steady-state initial conditions), as \
                             scipy.signal.decimate"
                        .into(),
                    passband_edge_hz: 0.8 * fs_in / factor as f64 / 2.0,
                    fs_in_hz: fs_in,
                    fs_out_hz: fs_in / factor as f64,
                    samples_in: n,
                    samples_out: n_out,
                }
            }
        };
        records.push(rec);
    }
    let record = Preprocessing {
        source: log.path.display().to_string(),
        samples_in: log.len(),
        samples_out: out.len(),
        ts_in: log.ts,
        ts_out: out.ts,
        steps: records,
    };
    Ok((out, record))
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// Removes the least-squares line over sample index i = 0..n-1; returns (value at i = 0,
/// slope per sample).
fn remove_line(x: &mut [f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let ic = (n - 1.0) / 2.0;
    let m = mean(x);
    let (mut sxi, mut sii) = (0.0, 0.0);
    for (i, &v) in x.iter().enumerate() {
        let d = i as f64 - ic;
        sxi += d * (v - m);
        sii += d * d;
    }
    let slope = if sii > 0.0 { sxi / sii } else { 0.0 };
    for (i, v) in x.iter_mut().enumerate() {
        *v -= m + slope * (i as f64 - ic);
    }
    (m - slope * ic, slope)
}

/// Decimation filter order (scipy's default).
const ORDER: usize = 8;

/// Largest accepted decimation factor. The anti-aliasing filter's normalised cut-off is
/// 0.8/factor; beyond 1000 the order-8 Chebyshev design loses its accuracy in f64, and a rate
/// reduction that large belongs in several stages.
pub const MAX_DECIMATION: usize = 1000;
/// Odd-extension length used by the zero-phase filter: 3 * (2 * sections + 1).
const PAD: usize = 3 * (2 * (ORDER / 2) + 1);

/// Second-order sections `[b0, b1, b2, a0 = 1, a1, a2]` of the anti-aliasing filter.
#[derive(Debug, Clone, PartialEq)]
pub struct AntiAlias {
    /// Sections, in application order (poles closest to the unit circle last).
    pub sos: Vec<[f64; 6]>,
}

/// Scratch buffers for the zero-phase filter (reused across channels).
struct Work {
    ext: Vec<f64>,
}

impl Work {
    fn new(n: usize) -> Self {
        Self {
            ext: Vec::with_capacity(n + 2 * PAD),
        }
    }
}

impl AntiAlias {
    /// The order-8, 0.05 dB Chebyshev type I low-pass for decimation by `factor` (>= 2): the
    /// same design as `scipy.signal.cheby1(8, 0.05, 0.8 / factor, output='sos')`.
    pub fn design(factor: usize) -> Self {
        let n = ORDER;
        let rp_db = 0.05;
        let wn = 0.8 / factor as f64; // normalised to Nyquist
                                      // Analog prototype (cutoff 1 rad/s): poles -sinh(mu + j theta_m).
        let eps = (10f64.powf(0.1 * rp_db) - 1.0).sqrt();
        let mu = (1.0 / eps).asinh() / n as f64;
        let mut poles: Vec<Complex64> = (0..n)
            .map(|i| {
                let m = -(n as f64) + 1.0 + 2.0 * i as f64;
                let theta = std::f64::consts::PI * m / (2.0 * n as f64);
                -Complex64::new(mu, theta).sinh()
            })
            .collect();
        let mut k = poles
            .iter()
            .fold(Complex64::new(1.0, 0.0), |acc, p| acc * -p)
            .re;
        if n.is_multiple_of(2) {
            k /= (1.0 + eps * eps).sqrt();
        }
        // Pre-warped frequency scaling (fs = 2 convention), then the bilinear transform.
        let fs2 = 4.0;
        let warped = fs2 * (std::f64::consts::PI * wn / 2.0).tan();
        for p in &mut poles {
            *p *= warped;
        }
        k *= warped.powi(n as i32);
        let denom = poles
            .iter()
            .fold(Complex64::new(1.0, 0.0), |acc, p| acc * (fs2 - p));
        k /= denom.re;
        let zp: Vec<Complex64> = poles.iter().map(|p| (fs2 + p) / (fs2 - p)).collect();
        // Conjugate pairs (upper half plane), ordered by distance to the unit circle: farthest
        // first. All zeros are at z = -1.
        let mut upper: Vec<Complex64> = zp.into_iter().filter(|p| p.im > 0.0).collect();
        upper.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
        let sos = upper
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let g = if i == 0 { k } else { 1.0 };
                [g, 2.0 * g, g, 1.0, -2.0 * p.re, p.norm_sqr()]
            })
            .collect();
        AntiAlias { sos }
    }

    /// Frequency response at `f` cycles/sample (0..0.5) of one pass.
    pub fn response(&self, f: f64) -> Complex64 {
        let z1 = Complex64::from_polar(1.0, -2.0 * std::f64::consts::PI * f);
        let z2 = z1 * z1;
        self.sos.iter().fold(Complex64::new(1.0, 0.0), |acc, s| {
            acc * (s[0] + s[1] * z1 + s[2] * z2) / (s[3] + s[4] * z1 + s[5] * z2)
        })
    }

    /// Steady-state states (direct form II transposed) of every section for a unit step input,
    /// scaled by the DC gain of the preceding sections (scipy's `sosfilt_zi`).
    fn zi(&self) -> Vec<[f64; 2]> {
        let mut scale = 1.0;
        self.sos
            .iter()
            .map(|s| {
                let (b0, b1, b2, a1, a2) = (s[0], s[1], s[2], s[4], s[5]);
                let g = (b0 + b1 + b2) / (1.0 + a1 + a2);
                let z2 = b2 - a2 * g;
                let z1 = b1 - a1 * g + z2;
                let out = [scale * z1, scale * z2];
                scale *= g;
                out
            })
            .collect()
    }

    /// Filters `x` in place through all sections starting from states `zi * x0`.
    fn run(&self, x: &mut [f64], zi: &[[f64; 2]], x0: f64) {
        for (s, z0) in self.sos.iter().zip(zi) {
            let (b0, b1, b2, a1, a2) = (s[0], s[1], s[2], s[4], s[5]);
            let (mut z1, mut z2) = (z0[0] * x0, z0[1] * x0);
            for v in x.iter_mut() {
                let xin = *v;
                let y = b0 * xin + z1;
                z1 = b1 * xin - a1 * y + z2;
                z2 = b2 * xin - a2 * y;
                *v = y;
            }
        }
    }

    /// Zero-phase filtering (scipy `sosfiltfilt` with `padtype='odd'`, default `padlen`).
    /// Requires `x.len() > 27`.
    fn filtfilt(&self, x: &[f64], work: &mut Work) -> Vec<f64> {
        let n = x.len();
        let ext = &mut work.ext;
        ext.clear();
        let (first, last) = (x[0], x[n - 1]);
        ext.extend((1..=PAD).rev().map(|i| 2.0 * first - x[i]));
        ext.extend_from_slice(x);
        ext.extend((1..=PAD).map(|i| 2.0 * last - x[n - 1 - i]));
        let zi = self.zi();
        let x0 = ext[0];
        self.run(ext, &zi, x0);
        ext.reverse();
        let y0 = ext[0];
        self.run(ext, &zi, y0);
        ext.reverse();
        ext[PAD..PAD + n].to_vec()
    }
}
