//! The spectra scipy.signal computed (welch, csd, coherence) as the spectral fixtures store
//! them; shared by `spectral_scipy` (synthetic signals) and `spectral_real_data` (DaISy files).
use num_complex::Complex64;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Deserializer};

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

/// A fixture entry: its own fields `T` (reached through `Deref`) and the spectra beside them in
/// the same JSON object. Read in two passes over one `serde_json::Value` rather than with
/// `#[serde(flatten)]`: a workspace build can switch on serde_json's `arbitrary_precision`
/// through feature unification, and flatten then buffers every number as a map ("invalid type:
/// map, expected f64").
pub struct WithSpectra<T> {
    /// The entry's own fields.
    pub own: T,
    /// The scipy spectra.
    pub scipy: ScipySpectra,
}

impl<'de, T: DeserializeOwned> Deserialize<'de> for WithSpectra<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = serde_json::Value::deserialize(d)?;
        Ok(Self {
            own: T::deserialize(&v).map_err(serde::de::Error::custom)?,
            scipy: ScipySpectra::deserialize(&v).map_err(serde::de::Error::custom)?,
        })
    }
}

impl<T> std::ops::Deref for WithSpectra<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.own
    }
}
