//! A limit-cycle detector for a recorded stretch of a loop signal (the steady-state tail).
//!
//! Frequency from the upward crossings of the record's mean (linear interpolation between the
//! samples around each crossing; a crossing counts only after the signal was below
//! mean − min_amplitude/2, a hysteresis against noise): (crossings − 1) / (time from the first to the last
//! crossing). Amplitude: half the peak-to-peak range. A record counts as oscillating when it
//! has at least `min_cycles` upward crossings and its amplitude is at least `min_amplitude`
//! (the caller's floor: e.g. the sensor noise, below which no cycle is observable).
//!
//! ```
//! use ferrosid_firmware::control::analyse_oscillation;
//! let ts = 1e-3f32;
//! let mut x = [0.0f32; 2000];
//! for (k, v) in x.iter_mut().enumerate() {
//!     *v = 0.3 + 0.5 * (2.0 * core::f32::consts::PI * 12.5 * k as f32 * ts).sin();
//! }
//! let o = analyse_oscillation(&x, ts, 5, 1e-3);
//! assert!(o.oscillating);
//! assert!((o.freq_hz - 12.5).abs() < 0.01 && (o.amplitude - 0.5).abs() < 1e-3);
//! ```

/// What [`analyse_oscillation`] found.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Oscillation {
    /// Frequency of the mean crossings, Hz (0 with fewer than two crossings).
    pub freq_hz: f32,
    /// Half the peak-to-peak range, signal units.
    pub amplitude: f32,
    /// Mean of the record.
    pub mean: f32,
    /// Upward mean crossings.
    pub crossings: u32,
    /// At least `min_cycles` crossings and `amplitude >= min_amplitude`.
    pub oscillating: bool,
}

/// Analyses `x` sampled every `ts_s` seconds (see the module docs). Non-finite samples are
/// skipped for the mean and range and break no crossing count (they are treated as absent).
pub fn analyse_oscillation(
    x: &[f32],
    ts_s: f32,
    min_cycles: u32,
    min_amplitude: f32,
) -> Oscillation {
    let (mut sum, mut n) = (0.0f64, 0u32);
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for &v in x.iter().filter(|v| v.is_finite()) {
        sum += f64::from(v);
        n += 1;
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if n == 0 {
        return Oscillation::default();
    }
    let mean = (sum / f64::from(n)) as f32;
    let amplitude = 0.5 * (hi - lo);
    let (mut first, mut last, mut crossings) = (0.0f32, 0.0f32, 0u32);
    let mut prev: Option<(usize, f32)> = None;
    // Hysteresis: a crossing counts only after the signal has been below mean − hyst since
    // the previous one, so noise riding on a slow signal does not add crossings.
    let hyst = 0.5 * min_amplitude.max(0.0);
    let mut armed = false;
    for (k, &v) in x.iter().enumerate() {
        if !v.is_finite() {
            continue;
        }
        let d = v - mean;
        if d < -hyst {
            armed = true;
        }
        if let Some((kp, dp)) = prev {
            if armed && dp < 0.0 && d >= 0.0 {
                armed = false;
                // Crossing between kp and k at the interpolated fraction.
                let t = kp as f32 + (k - kp) as f32 * (-dp / (d - dp));
                if crossings == 0 {
                    first = t;
                }
                last = t;
                crossings += 1;
            }
        }
        prev = Some((k, d));
    }
    let freq_hz = if crossings >= 2 && last > first {
        (crossings - 1) as f32 / ((last - first) * ts_s)
    } else {
        0.0
    };
    Oscillation {
        freq_hz,
        amplitude,
        mean,
        crossings,
        oscillating: crossings >= min_cycles.max(2) && amplitude >= min_amplitude,
    }
}
