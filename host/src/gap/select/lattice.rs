//! The lattice of a quantizing sensor read off the measured outputs (scale-free): the evidence
//! that decides quantization by itself in [`super::select_effects`].

/// The lattice of measured output values of a quantizing sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatticeEvidence {
    /// Lattice step, output units.
    pub step: f64,
    /// Lattice origin (one lattice point), output units.
    pub origin: f64,
    /// Share of all samples within 1 % of a step of a lattice point.
    pub share_on_lattice: f64,
    /// Number of distinct lattice levels occupied.
    pub levels: usize,
    /// Step over the output standard deviation.
    pub step_over_std: f64,
}

/// Share of samples on the lattice for [`lattice_evidence`] to report one.
pub const MIN_LATTICE_SHARE: f64 = 0.95;

/// Relative tolerance (in steps) within which a sample counts as on the lattice.
pub const LATTICE_TOL_STEPS: f64 = 0.01;

/// Reads a quantization lattice off the measured outputs (all logs pooled), scale-free: the
/// step is the median gap between neighbouring distinct values (values closer than 1e-9 of the
/// range merged), refined by least squares of the values on their level indices; the evidence
/// holds when at least [`MIN_LATTICE_SHARE`] of the samples lie within
/// [`LATTICE_TOL_STEPS`] of a lattice point, at least 3 levels are occupied, and there are at
/// most half as many distinct values as samples. A few off-lattice values (glitches, a
/// differently rounded file) do not break it. `None` for continuous-valued outputs.
pub fn lattice_evidence(y: &[Vec<f64>]) -> Option<LatticeEvidence> {
    let all: Vec<f64> = y
        .iter()
        .flat_map(|l| l.iter().copied())
        .filter(|v| v.is_finite())
        .collect();
    let total = all.len();
    if total < 16 {
        return None;
    }
    let mut v = all.clone();
    v.sort_by(f64::total_cmp);
    let range = v[total - 1] - v[0];
    if range.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let merge = 1e-9 * range;
    let mut distinct: Vec<f64> = Vec::new();
    for &x in &v {
        if distinct.last().is_none_or(|&d| x - d > merge) {
            distinct.push(x);
        }
    }
    if distinct.len() < 3 || distinct.len() * 2 > total {
        return None;
    }
    let mut gaps: Vec<f64> = distinct.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_by(f64::total_cmp);
    let s0 = gaps[gaps.len() / 2];
    if s0.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    // Refine: least squares of the distinct values on their level indices (near-lattice ones).
    let o0 = distinct[distinct.len() / 2];
    let (mut sq, mut sv, mut sqq, mut sqv, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &d in &distinct {
        let q = (d - o0) / s0;
        if (q - q.round()).abs() <= 0.1 {
            let qi = q.round();
            sq += qi;
            sv += d;
            sqq += qi * qi;
            sqv += qi * d;
            n += 1.0;
        }
    }
    let det = n * sqq - sq * sq;
    let (step, origin) = if n >= 3.0 && det > 0.0 {
        let st = (n * sqv - sq * sv) / det;
        (st, (sv - st * sq) / n)
    } else {
        (s0, o0)
    };
    if !(step > 0.0 && step.is_finite()) {
        return None;
    }
    let on = all
        .iter()
        .filter(|&&x| {
            let q = (x - origin) / step;
            (q - q.round()).abs() <= LATTICE_TOL_STEPS
        })
        .count();
    let share = on as f64 / total as f64;
    let mut lv: Vec<i64> = distinct
        .iter()
        .map(|&d| ((d - origin) / step).round() as i64)
        .collect();
    lv.dedup();
    let mean = all.iter().sum::<f64>() / total as f64;
    let std = (all.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / total as f64).sqrt();
    (share >= MIN_LATTICE_SHARE && lv.len() >= 3).then_some(LatticeEvidence {
        step,
        origin,
        share_on_lattice: share,
        levels: lv.len(),
        step_over_std: step / std.max(1e-300),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = crate::gap::simulator::rng::Rng::new(seed);
        (0..n).map(|_| rng.normal()).collect()
    }

    /// Quantization after noise, steps 3–8 % of the output RMS, at unit and at 6e-6 scale,
    /// written with 9 significant digits: the lattice is found and the step recovered.
    #[test]
    fn lattice_is_found_scale_free_after_noise() {
        for &(scale, rel) in &[(1.0, 0.03), (1.0, 0.08), (2e-4, 0.03), (2e-4, 0.05)] {
            let x = noise(20000, 3);
            // Smooth signal: running mean, then noise before the quantizer.
            let mut s = 0.0;
            let sig: Vec<f64> = x
                .iter()
                .map(|v| {
                    s = 0.95 * s + 0.05 * v;
                    s
                })
                .collect();
            let rms = (sig.iter().map(|v| v * v).sum::<f64>() / sig.len() as f64).sqrt();
            let step = rel * rms * scale;
            let nz = noise(20000, 9);
            let y: Vec<f64> = sig
                .iter()
                .zip(&nz)
                .map(|(a, e)| {
                    let v = (a * scale + 0.01 * rms * scale * e) / step;
                    let q = v.round() * step;
                    format!("{q:.8e}").parse::<f64>().unwrap()
                })
                .collect();
            let l = lattice_evidence(std::slice::from_ref(&y)).expect("lattice");
            assert!(
                (l.step - step).abs() < 1e-6 * step,
                "scale {scale} rel {rel}: step {} vs {step}",
                l.step
            );
            assert!(l.share_on_lattice > 0.999);
            // A few off-lattice glitches do not break it.
            let mut g = y.clone();
            for k in (0..g.len()).step_by(997) {
                g[k] += 0.37 * step;
            }
            let l = lattice_evidence(&[g]).expect("lattice with glitches");
            assert!((l.step - step).abs() < 1e-6 * step);
        }
        // A continuous signal has none.
        assert!(lattice_evidence(&[noise(5000, 4)]).is_none());
    }
}
