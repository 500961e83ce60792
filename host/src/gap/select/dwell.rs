//! Dwells at zero velocity while the input pushes, read off the training logs: the evidence of
//! static friction (stiction) used by [`super::select_effects`].
use crate::gap::fit::VelocitySource;

/// Dwells at zero velocity while the input pushes: the mark of static friction.
#[derive(Debug, Clone, PartialEq)]
pub struct DwellEvidence {
    /// Number of dwells found (runs of at least [`MIN_DWELL_SAMPLES`]).
    pub dwells: usize,
    /// Share of the scored samples spent in dwells.
    pub dwell_share: f64,
    /// Breakaway estimate: the 90th percentile over dwells of the largest |input| held without
    /// moving (at rest the drive balances the friction), input units.
    pub breakaway: f64,
    /// Median |input| at the first sample after a dwell (an upper bound of the breakaway,
    /// inflated by the acceleration that follows), input units.
    pub exit_median: f64,
    /// Median over dwells of the largest |input| held without moving, input units.
    pub hold_max: f64,
    /// Velocity band counted as zero, in velocity units (output units, or output units per
    /// second for a position output).
    pub band: f64,
    /// Which signal stood for the velocity.
    pub velocity: VelocitySource,
}

/// Shortest run at zero velocity that counts as a dwell, samples.
pub const MIN_DWELL_SAMPLES: usize = 8;

/// Fewest dwells for [`dwell_evidence`] to report any.
pub const MIN_DWELLS: usize = 5;

/// Finds dwells in the training logs: runs of at least [`MIN_DWELL_SAMPLES`] samples where the
/// velocity (the output, or its first difference over `ts` for a position output) stays within
/// a band of zero (four times its noise level, estimated from sample-to-sample differences near
/// zero; at least 1e-3 and at most 5 % of its RMS) while the median |input| over the run is at
/// least 5 % of the input RMS. The breakaway estimate is the 90th percentile over dwells of the
/// largest |input| held at rest (the last two samples of each dwell left out). `None` with fewer than [`MIN_DWELLS`] dwells or under 1 % of the
/// samples in dwells.
/// The velocity the friction of `velocity` sees in an output log: the output itself, or its
/// first difference over the sample time `ts` (0 at the first sample) for a position output.
pub fn velocity_signal(y: &[f64], ts: f64, velocity: VelocitySource) -> Vec<f64> {
    match velocity {
        VelocitySource::Output => y.to_vec(),
        VelocitySource::OutputDerivative => {
            let mut v = vec![0.0; y.len()];
            for k in 1..y.len() {
                v[k] = (y[k] - y[k - 1]) / ts;
            }
            v
        }
    }
}

pub fn dwell_evidence(
    u: &[Vec<f64>],
    y: &[Vec<f64>],
    ts: f64,
    velocity: VelocitySource,
    warmup: usize,
) -> Option<DwellEvidence> {
    let vel: Vec<Vec<f64>> = y
        .iter()
        .map(|yl| velocity_signal(yl, ts, velocity))
        .collect();
    let all: Vec<f64> = vel
        .iter()
        .flat_map(|v| v.iter().skip(warmup.max(1)).copied())
        .collect();
    if all.len() < 64 {
        return None;
    }
    let rms = (all.iter().map(|x| x * x).sum::<f64>() / all.len() as f64).sqrt();
    if rms.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let mut near: Vec<f64> = Vec::new();
    for v in &vel {
        for k in warmup.max(1)..v.len() {
            if v[k].abs() < 0.1 * rms && v[k - 1].abs() < 0.1 * rms {
                near.push((v[k] - v[k - 1]).abs());
            }
        }
    }
    let sigma = if near.len() >= 16 {
        near.sort_by(f64::total_cmp);
        1.4826 * near[near.len() / 2] / std::f64::consts::SQRT_2
    } else {
        0.0
    };
    let band = (4.0 * sigma).clamp(1e-3 * rms, 0.05 * rms);
    let u_rms = (u
        .iter()
        .flat_map(|l| l.iter().skip(warmup))
        .map(|x| x * x)
        .sum::<f64>()
        / all.len() as f64)
        .sqrt();
    let (mut dwells, mut in_dwell, mut scored) = (0usize, 0usize, 0usize);
    let mut exits: Vec<f64> = Vec::new();
    let mut holds: Vec<f64> = Vec::new();
    for (ul, v) in u.iter().zip(&vel) {
        let start = warmup.max(1);
        scored += v.len().saturating_sub(start);
        let mut k = start;
        while k < v.len() {
            if v[k].abs() > band {
                k += 1;
                continue;
            }
            let s = k;
            while k < v.len() && v[k].abs() <= band {
                k += 1;
            }
            let len = k - s;
            if len < MIN_DWELL_SAMPLES || k >= v.len() {
                continue;
            }
            let mut mags: Vec<f64> = ul[s..k].iter().map(|x| x.abs()).collect();
            mags.sort_by(f64::total_cmp);
            if mags[mags.len() / 2] < 0.05 * u_rms {
                continue;
            }
            dwells += 1;
            in_dwell += len;
            exits.push(ul[k].abs().max(ul[k - 1].abs()));
            holds.push(
                ul[s..k.saturating_sub(2).max(s + 1)]
                    .iter()
                    .fold(0.0f64, |a, x| a.max(x.abs())),
            );
        }
    }
    let share = in_dwell as f64 / scored.max(1) as f64;
    if dwells < MIN_DWELLS || share < 0.01 {
        return None;
    }
    let quantile = |mut x: Vec<f64>, q: f64| {
        x.sort_by(f64::total_cmp);
        x[((x.len() - 1) as f64 * q).round() as usize]
    };
    Some(DwellEvidence {
        dwells,
        dwell_share: share,
        breakaway: quantile(holds.clone(), 0.9),
        exit_median: quantile(exits, 0.5),
        hold_max: quantile(holds, 0.5),
        band,
        velocity,
    })
}
