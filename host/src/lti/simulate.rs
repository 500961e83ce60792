//! Time-domain simulation of discrete state-space models.
use super::state_space::StateSpace;
use crate::error::{Error, Result};
use faer::Mat;

impl StateSpace {
    /// Simulates a discrete model: `u[j]` is input channel j (m channels of equal length N),
    /// `x0` the initial state (zeros when `None`). Returns the p output channels, each of length
    /// N. Continuous models are refused: discretise with [`Self::c2d_zoh`] first.
    pub fn simulate<U: AsRef<[f64]>>(&self, u: &[U], x0: Option<&[f64]>) -> Result<Vec<Vec<f64>>> {
        if !self.is_discrete() {
            return Err(Error::InvalidArgument(
                "simulate needs a discrete-time model; discretise with c2d_zoh(ts) first".into(),
            ));
        }
        let (n, m, p) = (self.n_states(), self.n_inputs(), self.n_outputs());
        if u.len() != m {
            return Err(Error::InvalidArgument(format!(
                "simulate: model has {m} inputs but {} input channels were given",
                u.len()
            )));
        }
        let len = u[0].as_ref().len();
        for (j, ch) in u.iter().enumerate() {
            let ch = ch.as_ref();
            if ch.len() != len {
                return Err(Error::InvalidArgument(format!(
                    "simulate: input channel {j} has {} samples, channel 0 has {len}",
                    ch.len()
                )));
            }
            if let Some(k) = ch.iter().position(|v| !v.is_finite()) {
                return Err(Error::InvalidArgument(format!(
                    "simulate: input channel {j} sample {k} is not finite"
                )));
            }
        }
        let mut x = vec![0.0; n];
        if let Some(x0) = x0 {
            if x0.len() != n {
                return Err(Error::InvalidArgument(format!(
                    "simulate: x0 has {} entries, the model has {n} states",
                    x0.len()
                )));
            }
            x.copy_from_slice(x0);
        }
        let rm = |m: &Mat<f64>| -> Vec<f64> {
            let mut v = Vec::with_capacity(m.nrows() * m.ncols());
            for i in 0..m.nrows() {
                for j in 0..m.ncols() {
                    v.push(m[(i, j)]);
                }
            }
            v
        };
        let (a, b, c, d) = (rm(&self.a), rm(&self.b), rm(&self.c), rm(&self.d));
        let mut y = vec![vec![0.0; len]; p];
        let mut xn = vec![0.0; n];
        let mut uk = vec![0.0; m];
        for k in 0..len {
            for (j, ch) in u.iter().enumerate() {
                uk[j] = ch.as_ref()[k];
            }
            for (i, yi) in y.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (cij, xj) in c[i * n..(i + 1) * n].iter().zip(&x) {
                    acc += cij * xj;
                }
                for (dij, uj) in d[i * m..(i + 1) * m].iter().zip(&uk) {
                    acc += dij * uj;
                }
                yi[k] = acc;
            }
            for (i, xni) in xn.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (aij, xj) in a[i * n..(i + 1) * n].iter().zip(&x) {
                    acc += aij * xj;
                }
                for (bij, uj) in b[i * m..(i + 1) * m].iter().zip(&uk) {
                    acc += bij * uj;
                }
                *xni = acc;
            }
            std::mem::swap(&mut x, &mut xn);
        }
        Ok(y)
    }

    /// SISO convenience for [`Self::simulate`].
    pub fn simulate_siso(&self, u: &[f64], x0: Option<&[f64]>) -> Result<Vec<f64>> {
        if !self.is_siso() {
            return Err(Error::InvalidArgument(format!(
                "simulate_siso on a {}x{} model",
                self.n_outputs(),
                self.n_inputs()
            )));
        }
        Ok(self.simulate(&[u], x0)?.remove(0))
    }
}
