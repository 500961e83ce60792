//! Loop curves for figures: |S|, |T|, 1/|W_m| on the analysis grid.

use crate::error::Result;
use crate::lti::FreqEvaluator;
use crate::robust::loops::FeedbackLoop;
use crate::robust::uncertainty::UncertaintyWeight;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Magnitudes of the loop transfers on a frequency list, for plots (|S|, |T|, |KS|, 1/|W_m|).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoopCurves {
    /// Frequencies, Hz.
    pub freq_hz: Vec<f64>,
    /// |L|.
    pub l_mag: Vec<f64>,
    /// ∠L, degrees (wrapped).
    pub l_phase_deg: Vec<f64>,
    /// |S|.
    pub s_mag: Vec<f64>,
    /// |T|.
    pub t_mag: Vec<f64>,
    /// |KS|.
    pub ks_mag: Vec<f64>,
    /// 1/|W_m(j2πf)| (continuous weight), when a weight is given.
    pub inv_wm_mag: Option<Vec<f64>>,
}

/// Evaluates [`LoopCurves`] at `freq_hz` (Hz, below Nyquist for discrete loops).
pub fn loop_curves(
    lp: &FeedbackLoop,
    weight: Option<&UncertaintyWeight>,
    freq_hz: &[f64],
) -> Result<LoopCurves> {
    let (el, es, et, ek) = (
        FreqEvaluator::new(&lp.l),
        FreqEvaluator::new(&lp.s),
        FreqEvaluator::new(&lp.t),
        FreqEvaluator::new(&lp.ks),
    );
    let mut c = LoopCurves {
        freq_hz: freq_hz.to_vec(),
        l_mag: Vec::new(),
        l_phase_deg: Vec::new(),
        s_mag: Vec::new(),
        t_mag: Vec::new(),
        ks_mag: Vec::new(),
        inv_wm_mag: weight.map(|_| Vec::new()),
    };
    for &f in freq_hz {
        let w = 2.0 * PI * f;
        let l = el.at_rad_s(w)?[(0, 0)];
        c.l_mag.push(l.norm());
        c.l_phase_deg.push(l.arg().to_degrees());
        c.s_mag.push(es.at_rad_s(w)?[(0, 0)].norm());
        c.t_mag.push(et.at_rad_s(w)?[(0, 0)].norm());
        c.ks_mag.push(ek.at_rad_s(w)?[(0, 0)].norm());
        if let (Some(v), Some(wm)) = (c.inv_wm_mag.as_mut(), weight) {
            v.push(1.0 / wm.freq_response(w).norm());
        }
    }
    Ok(c)
}
