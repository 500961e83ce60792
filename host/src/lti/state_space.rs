//! The state-space model (A, B, C, D, ts): construction with checked invariants, shape queries,
//! poles, stability, DC gain, and the row-major serde form used by model files.
use super::dense::{check_finite, check_ts, eigenvalues};
use crate::error::{Error, Result};
use faer::Mat;
use num_complex::Complex64;
use serde::{Deserialize, Serialize};

/// A state-space model (A, B, C, D) with its sample time.
#[derive(Debug, Clone)]
pub struct StateSpace {
    /// State matrix, n×n.
    pub a: Mat<f64>,
    /// Input matrix, n×m.
    pub b: Mat<f64>,
    /// Output matrix, p×n.
    pub c: Mat<f64>,
    /// Feedthrough matrix, p×m.
    pub d: Mat<f64>,
    /// Sample time in seconds; 0 for continuous time.
    pub ts: f64,
}

impl StateSpace {
    /// Builds a model after checking shapes (A n×n, B n×m, C p×n, D p×m, m, p >= 1), that every
    /// entry is finite and that `ts` is finite and >= 0 (seconds; 0 = continuous time).
    pub fn new(a: Mat<f64>, b: Mat<f64>, c: Mat<f64>, d: Mat<f64>, ts: f64) -> Result<Self> {
        let n = a.nrows();
        if a.ncols() != n {
            return Err(Error::InvalidArgument(format!(
                "A must be square, got {}x{}",
                a.nrows(),
                a.ncols()
            )));
        }
        if b.nrows() != n {
            return Err(Error::InvalidArgument(format!(
                "B must have n = {n} rows (one per state), got {}x{}",
                b.nrows(),
                b.ncols()
            )));
        }
        if c.ncols() != n {
            return Err(Error::InvalidArgument(format!(
                "C must have n = {n} columns (one per state), got {}x{}",
                c.nrows(),
                c.ncols()
            )));
        }
        let (m, p) = (d.ncols(), d.nrows());
        if m == 0 || p == 0 {
            return Err(Error::InvalidArgument(format!(
                "D must be p×m with at least one input and one output, got {p}x{m}"
            )));
        }
        if b.ncols() != m {
            return Err(Error::InvalidArgument(format!(
                "B has {} columns but D has {m} (inputs must agree)",
                b.ncols()
            )));
        }
        if c.nrows() != p {
            return Err(Error::InvalidArgument(format!(
                "C has {} rows but D has {p} (outputs must agree)",
                c.nrows()
            )));
        }
        check_finite("A", a.as_ref())?;
        check_finite("B", b.as_ref())?;
        check_finite("C", c.as_ref())?;
        check_finite("D", d.as_ref())?;
        check_ts(ts)?;
        Ok(Self { a, b, c, d, ts })
    }

    /// A static gain y = D·u (no states), p×m.
    pub fn gain(d: Mat<f64>, ts: f64) -> Result<Self> {
        let (p, m) = (d.nrows(), d.ncols());
        Self::new(Mat::zeros(0, 0), Mat::zeros(0, m), Mat::zeros(p, 0), d, ts)
    }

    /// The p×p identity as a static model (handy for S = (I + L)⁻¹ via [`Self::feedback`]).
    pub fn identity(p: usize, ts: f64) -> Result<Self> {
        Self::gain(Mat::identity(p, p), ts)
    }

    /// Checks the invariants of [`Self::new`] on a value built through the public fields.
    pub fn validate(&self) -> Result<()> {
        Self::new(
            self.a.clone(),
            self.b.clone(),
            self.c.clone(),
            self.d.clone(),
            self.ts,
        )
        .map(|_| ())
    }

    /// Number of states n.
    pub fn n_states(&self) -> usize {
        self.a.nrows()
    }
    /// Number of inputs m.
    pub fn n_inputs(&self) -> usize {
        self.d.ncols()
    }
    /// Number of outputs p.
    pub fn n_outputs(&self) -> usize {
        self.d.nrows()
    }
    /// True for a discrete-time model (`ts > 0`).
    pub fn is_discrete(&self) -> bool {
        self.ts > 0.0
    }
    /// True for a single-input single-output model.
    pub fn is_siso(&self) -> bool {
        self.n_inputs() == 1 && self.n_outputs() == 1
    }

    /// Eigenvalues of A (poles; s-plane for continuous, z-plane for discrete models), least
    /// stable first: sorted by decreasing real part (continuous) or modulus (discrete), then by
    /// decreasing imaginary part.
    pub fn poles(&self) -> Result<Vec<Complex64>> {
        let mut p = eigenvalues(self.a.as_ref())?;
        let discrete = self.is_discrete();
        let key = |z: &Complex64| if discrete { z.norm() } else { z.re };
        p.sort_by(|x, y| key(y).total_cmp(&key(x)).then(y.im.total_cmp(&x.im)));
        Ok(p)
    }

    /// True when every pole lies inside the stability region shrunk by `margin`:
    /// Re(p) < −margin (rad/s) for continuous models, |p| < 1 − margin for discrete ones.
    /// A model without states is stable.
    pub fn is_stable(&self, margin: f64) -> Result<bool> {
        let p = self.poles()?;
        Ok(if self.is_discrete() {
            p.iter().all(|z| z.norm() < 1.0 - margin)
        } else {
            p.iter().all(|s| s.re < -margin)
        })
    }

    /// Steady-state gain G(0) (continuous) or G(1) (discrete), p×m. Errors when the model has
    /// a pole at s = 0 / z = 1 (integrator: infinite DC gain).
    pub fn dc_gain(&self) -> Result<Mat<f64>> {
        let point = if self.is_discrete() {
            Complex64::new(1.0, 0.0)
        } else {
            Complex64::new(0.0, 0.0)
        };
        let g = self.evaluate(point).map_err(|_| {
            Error::Numerical(
                "infinite DC gain: the model has a pole at s = 0 (z = 1), an integrator".into(),
            )
        })?;
        Ok(Mat::from_fn(g.nrows(), g.ncols(), |i, j| g[(i, j)].re))
    }
}

/// Serde-friendly row-major form of a [`StateSpace`] (for JSON model files and reports).
/// `a[i]` is row i of A, and so on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateSpaceData {
    /// A, n rows of n.
    pub a: Vec<Vec<f64>>,
    /// B, n rows of m.
    pub b: Vec<Vec<f64>>,
    /// C, p rows of n.
    pub c: Vec<Vec<f64>>,
    /// D, p rows of m.
    pub d: Vec<Vec<f64>>,
    /// Sample time in seconds; 0 for continuous time.
    pub ts: f64,
    /// The operating point and preprocessing the model was identified with (absent in files
    /// written before it existed, and for models not identified from logs). Apply it with
    /// [`crate::operating_point::simulate_raw`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operating_point: Option<crate::data::OperatingPoint>,
}

fn to_rows(m: &Mat<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect()
}

fn from_rows(name: &str, rows: &[Vec<f64>], ncols_if_empty: usize) -> Result<Mat<f64>> {
    let nc = rows.first().map_or(ncols_if_empty, |r| r.len());
    if let Some((i, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != nc) {
        return Err(Error::InvalidArgument(format!(
            "{name}: row {i} has {} entries, row 0 has {nc}",
            r.len()
        )));
    }
    Ok(Mat::from_fn(rows.len(), nc, |i, j| rows[i][j]))
}

impl From<&StateSpace> for StateSpaceData {
    fn from(s: &StateSpace) -> Self {
        Self {
            a: to_rows(&s.a),
            b: to_rows(&s.b),
            c: to_rows(&s.c),
            d: to_rows(&s.d),
            ts: s.ts,
            operating_point: None,
        }
    }
}

impl TryFrom<&StateSpaceData> for StateSpace {
    type Error = Error;
    fn try_from(s: &StateSpaceData) -> Result<Self> {
        let m = s.d.first().map_or(0, |r| r.len());
        let n = s.a.len();
        StateSpace::new(
            from_rows("A", &s.a, 0)?,
            from_rows("B", &s.b, m)?,
            from_rows("C", &s.c, n)?,
            from_rows("D", &s.d, 0)?,
            s.ts,
        )
    }
}
