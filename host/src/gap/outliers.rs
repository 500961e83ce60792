//! Isolated spikes in the logged output (a sensor glitch, a dropped bus frame): data-quality
//! evidence, found on the linear model's residual and kept out of the noise floor and every
//! fit.
//!
//! A sample k is a spike when the residual r = y − ŷ of the linear model jumps away from both
//! neighbours in the same direction by more than [`SPIKE_THRESHOLD`] robust standard deviations
//! of the residual's first difference (1.4826·MAD, at least a tenth of its RMS so that a coarse
//! output lattice with a zero MAD does not make every step a spike): (r[k] − r[k−1]) and
//! (r[k] − r[k+1]) share a sign and both exceed the threshold. A step of the residual (a stick–
//! slip event, a lattice step) moves away from one neighbour only and is never a spike.
//!
//! A spike is masked by replacing the sample with the model's value plus the mean of the two
//! neighbouring residuals, y[k] ← ŷ[k] + (r[k−1] + r[k+1])/2: the residual's local level without
//! the spike.
use serde::Serialize;

/// Spike threshold in robust standard deviations of the residual's first difference (white
/// Gaussian noise passes it with probability about 2e-15 per sample).
pub const SPIKE_THRESHOLD: f64 = 8.0;

/// Time stamps listed per log at most.
pub const MAX_LISTED: usize = 10;

/// Spikes of one log.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LogSpikes {
    /// The log's path.
    pub log: String,
    /// Spikes found.
    pub count: usize,
    /// Their times, s (at most [`MAX_LISTED`], earliest first).
    pub times_s: Vec<f64>,
    /// Largest spike, output units (signed: its departure from the local residual level).
    pub largest: f64,
}

/// Spikes over every log of a diagnosis.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Outliers {
    /// Spikes over every log.
    pub count: usize,
    /// Share of all samples.
    pub share: f64,
    /// Per log with spikes.
    pub logs: Vec<LogSpikes>,
}

fn robust_sd(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let rms = (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    v.iter_mut().for_each(|x| *x = x.abs());
    let mid = v.len() / 2;
    let mad = *v.select_nth_unstable_by(mid, f64::total_cmp).1;
    (1.4826 * mad).max(0.1 * rms)
}

/// Indices of the spikes of residual `r` from sample `from` on (module docs).
pub fn spikes(r: &[f64], from: usize) -> Vec<usize> {
    if r.len() < from + 3 {
        return Vec::new();
    }
    let mut diffs: Vec<f64> = r[from..].windows(2).map(|w| w[1] - w[0]).collect();
    let sd = robust_sd(&mut diffs);
    if !(sd > 0.0) {
        return Vec::new();
    }
    let cut = SPIKE_THRESHOLD * sd;
    (from.max(1)..r.len() - 1)
        .filter(|&k| {
            let (e1, e2) = (r[k] - r[k - 1], r[k] - r[k + 1]);
            e1 * e2 > 0.0 && e1.abs() > cut && e2.abs() > cut
        })
        .collect()
}

/// Masks the spikes `at` of output `y` whose model output is `yh` (module docs).
pub fn mask(y: &mut [f64], yh: &[f64], at: &[usize]) {
    for &k in at {
        let r = |j: usize| y[j] - yh[j];
        let level = 0.5 * (r(k - 1) + r(k + 1));
        y[k] = yh[k] + level;
    }
}

/// The report of the spikes found in each log: (name, spike indices, residual) per log, sample
/// time `ts`; `None` when there are none.
pub fn report(
    found: &[(String, Vec<usize>, &[f64])],
    ts: f64,
    total_samples: usize,
) -> Option<Outliers> {
    let count: usize = found.iter().map(|f| f.1.len()).sum();
    (count > 0).then(|| Outliers {
        count,
        share: count as f64 / total_samples.max(1) as f64,
        logs: found
            .iter()
            .filter(|f| !f.1.is_empty())
            .map(|(log, at, r)| LogSpikes {
                log: log.clone(),
                count: at.len(),
                times_s: at.iter().take(MAX_LISTED).map(|&k| k as f64 * ts).collect(),
                largest: at
                    .iter()
                    .map(|&k| r[k] - 0.5 * (r[k - 1] + r[k + 1]))
                    .max_by(|a, b| a.abs().total_cmp(&b.abs()))
                    .unwrap_or(0.0),
            })
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::simulator::rng::Rng;

    #[test]
    fn finds_every_spike_of_white_noise_and_nothing_else() {
        let mut rng = Rng::new(21);
        let mut r: Vec<f64> = (0..20_000).map(|_| 0.01 * rng.normal()).collect();
        let clean = spikes(&r, 0);
        assert!(clean.is_empty(), "{clean:?}");
        let at = [500usize, 7_000, 7_003, 19_998];
        for (i, &k) in at.iter().enumerate() {
            r[k] += if i % 2 == 0 { 0.3 } else { -0.2 };
        }
        assert_eq!(spikes(&r, 0), at.to_vec());
    }

    #[test]
    fn a_step_and_a_lattice_are_not_spikes() {
        // A residual that steps once (stick-slip) and sits on a coarse lattice.
        let r: Vec<f64> = (0..4000)
            .map(|k| if k < 2000 { 0.0 } else { 1.0 } + ((k / 7) % 3) as f64 * 0.25)
            .collect();
        assert!(spikes(&r, 0).is_empty());
    }

    #[test]
    fn masking_restores_the_local_level() {
        let yh = vec![1.0; 5];
        let mut y = vec![1.1, 1.1, 9.0, 1.3, 1.1];
        mask(&mut y, &yh, &[2]);
        assert!((y[2] - 1.2).abs() < 1e-12, "{}", y[2]);
        let rep = report(
            &[("a.csv".into(), vec![2], &[0.1, 0.1, 8.0, 0.3, 0.1])],
            0.5,
            5,
        )
        .unwrap();
        assert_eq!(rep.count, 1);
        assert_eq!(rep.logs[0].times_s, vec![1.0]);
        assert!((rep.logs[0].largest - 7.8).abs() < 1e-12);
    }
}
