//! The spectra scipy.signal computed (welch, csd, coherence) as the spectral fixtures store
//! them; shared by `spectral_scipy` (synthetic signals) and `spectral_real_data` (DaISy files).
use num_complex::Complex64;
use serde::Deserialize;

/// One-sided spectra of an input/output pair on scipy's frequency grid.
#[derive(Deserialize)]
pub struct ScipySpectra {
    /// Frequencies.
    pub f: Vec<f64>,
    /// Input auto-spectrum.
    pub pxx: Vec<f64>,
    /// Output auto-spectrum.
    pub pyy: Vec<f64>,
    /// Cross-spectrum, real part.
    pub pxy_re: Vec<f64>,
    /// Cross-spectrum, imaginary part.
    pub pxy_im: Vec<f64>,
    /// Magnitude-squared coherence.
    pub cxy: Vec<f64>,
}

impl ScipySpectra {
    /// The cross-spectrum per bin.
    pub fn pxy(&self) -> Vec<Complex64> {
        self.pxy_re
            .iter()
            .zip(&self.pxy_im)
            .map(|(&r, &i)| Complex64::new(r, i))
            .collect()
    }
}
