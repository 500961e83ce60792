//! Phase agreement of the model with the measured ETFE (receipt `etfe_phase_agreement`).

use crate::error::{Error, Result};
use crate::lti::{FreqEvaluator, StateSpace};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

use super::*;

/// A measured frequency response to compare the model's phase with.
#[derive(Debug, Clone, Copy)]
pub struct EtfeView<'a> {
    /// Bin frequencies, Hz.
    pub freq_hz: &'a [f64],
    /// Measured response at each bin.
    pub h: &'a [Complex64],
    /// Coherence gate: true for bins to use (None: all bins).
    pub gate: Option<&'a [bool]>,
}

impl<'a> EtfeView<'a> {
    /// A view of a Welch H1 estimate with an optional coherence gate (e.g. `etfe.gate(0.8)`).
    pub fn from_etfe(etfe: &'a crate::spectral::Etfe, gate: Option<&'a [bool]>) -> Self {
        Self {
            freq_hz: &etfe.freq_hz,
            h: &etfe.h,
            gate,
        }
    }
}

/// Phase agreement of G0 with the ETFE over a slice of frequency.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseSlice {
    /// Slice start, Hz.
    pub f_lo_hz: f64,
    /// Slice end, Hz.
    pub f_hi_hz: f64,
    /// Gated bins in the slice.
    pub bins: usize,
    /// Largest |phase error| in the slice, degrees (0 without bins).
    pub max_abs_error_deg: f64,
}

/// Phase agreement of the model with the ETFE at gated bins below `f_max_hz`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseAgreement {
    /// Upper frequency checked, Hz.
    pub f_max_hz: f64,
    /// Gated bins used.
    pub bins_used: usize,
    /// Largest |∠G0 − ∠ETFE| (wrapped to (−180°, 180°]), degrees.
    pub max_abs_error_deg: f64,
    /// Where it occurs, Hz.
    pub at_hz: f64,
    /// Octave slices ending at `f_max_hz`, lowest first.
    pub slices: Vec<PhaseSlice>,
    /// (f_hz, signed error deg) for every bin used.
    pub per_bin: Vec<(f64, f64)>,
}

/// Phase of the model `plant` against a measured response at gated bins with f <= `f_max_hz`,
/// sliced into octaves. Errors: mismatched lengths or a model evaluation failure.
pub fn phase_agreement(
    plant: &StateSpace,
    etfe: &EtfeView<'_>,
    f_max_hz: f64,
) -> Result<PhaseAgreement> {
    let n = etfe.freq_hz.len();
    if etfe.h.len() != n || etfe.gate.is_some_and(|g| g.len() != n) {
        return Err(Error::InvalidArgument(format!(
            "ETFE: {} frequencies, {} responses, {} gate flags (must agree)",
            n,
            etfe.h.len(),
            etfe.gate.map_or(n, |g| g.len())
        )));
    }
    let ev = FreqEvaluator::new(plant);
    let mut per_bin = Vec::new();
    for i in 0..n {
        let f = etfe.freq_hz[i];
        if !(f > 0.0 && f <= f_max_hz && etfe.gate.is_none_or(|g| g[i])) {
            continue;
        }
        let h = etfe.h[i];
        if !(h.re.is_finite() && h.im.is_finite()) || h.norm() == 0.0 {
            continue;
        }
        let g = ev.at_rad_s(2.0 * PI * f)?[(0, 0)];
        per_bin.push((f, (g / h).arg().to_degrees()));
    }
    let (mut worst, mut at) = (0.0f64, f64::NAN);
    for &(f, e) in &per_bin {
        if e.abs() > worst || at.is_nan() {
            worst = worst.max(e.abs());
            at = f;
        }
    }
    let mut slices = Vec::new();
    if let Some(f_lo) = per_bin.first().map(|p| p.0) {
        let mut hi = f_max_hz;
        loop {
            let lo = hi / 2.0;
            let in_slice: Vec<f64> = per_bin
                .iter()
                .filter(|(f, _)| *f > lo && *f <= hi)
                .map(|p| p.1.abs())
                .collect();
            slices.push(PhaseSlice {
                f_lo_hz: lo,
                f_hi_hz: hi,
                bins: in_slice.len(),
                max_abs_error_deg: in_slice.iter().copied().fold(0.0, f64::max),
            });
            if lo <= f_lo {
                break;
            }
            hi = lo;
        }
        slices.reverse();
    }
    Ok(PhaseAgreement {
        f_max_hz,
        bins_used: per_bin.len(),
        max_abs_error_deg: worst,
        at_hz: at,
        slices,
        per_bin,
    })
}
/// The ETFE phase-agreement receipt of the plant model against the measured ETFE.
pub(super) fn push_etfe_receipt(
    rs: &mut Receipts,
    plant: &StateSpace,
    e: &EtfeView<'_>,
    lim: &ReceiptLimits,
    fc: f64,
) -> Result<PhaseAgreement> {
    let p = phase_agreement(plant, e, lim.etfe_max_freq_factor * fc)?;
    rs.push(etfe_phase_receipt(
        &p,
        lim.etfe_phase_error_deg_max,
        if p.bins_used == 0 {
            format!("no gated ETFE bin below {} Hz", fmt_sig(p.f_max_hz))
        } else {
            format!(
                "{} gated bins up to {} Hz; worst at {} Hz; octave slices: {}",
                p.bins_used,
                fmt_sig(p.f_max_hz),
                fmt_sig(p.at_hz),
                p.slices
                    .iter()
                    .map(|s| format!(
                        "{}–{} Hz: {} deg ({} bins)",
                        fmt_sig(s.f_lo_hz),
                        fmt_sig(s.f_hi_hz),
                        fmt_sig(s.max_abs_error_deg),
                        s.bins
                    ))
                    .collect::<Vec<_>>()
                    .join("; ")
            )
        },
    ));
    Ok(p)
}

/// The `etfe_phase_agreement` receipt of a phase comparison (undefined, hence failing, when no
/// gated bin was compared); `limit_deg` the largest accepted |phase error|, degrees.
pub fn etfe_phase_receipt(p: &PhaseAgreement, limit_deg: f64, detail: String) -> Receipt {
    Receipt::new(
        ReceiptKind::EtfePhaseAgreement,
        "largest |phase(G0) − phase(ETFE)| at coherence-gated bins up to the stated multiple \
         of crossover",
        if p.bins_used == 0 {
            f64::NAN
        } else {
            p.max_abs_error_deg
        },
        Comparison::AtMost,
        limit_deg,
        "deg",
        detail,
    )
}
