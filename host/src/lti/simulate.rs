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
        if m == 1 && p == 1 {
            // SISO models of small order: the same operations in the same order with the
            // state in fixed-size arrays (no slice bounds or loop set-up per sample).
            let (u0, mut y0) = (u[0].as_ref(), vec![0.0; len]);
            let done = match n {
                1 => simulate_siso_fixed::<1>(&a, &b, &c, d[0], &x, u0, &mut y0),
                2 => simulate_siso_fixed::<2>(&a, &b, &c, d[0], &x, u0, &mut y0),
                3 => simulate_siso_fixed::<3>(&a, &b, &c, d[0], &x, u0, &mut y0),
                4 => simulate_siso_fixed::<4>(&a, &b, &c, d[0], &x, u0, &mut y0),
                5 => simulate_siso_fixed::<5>(&a, &b, &c, d[0], &x, u0, &mut y0),
                6 => simulate_siso_fixed::<6>(&a, &b, &c, d[0], &x, u0, &mut y0),
                7 => simulate_siso_fixed::<7>(&a, &b, &c, d[0], &x, u0, &mut y0),
                8 => simulate_siso_fixed::<8>(&a, &b, &c, d[0], &x, u0, &mut y0),
                _ => false,
            };
            if done {
                return Ok(vec![y0]);
            }
        }
        if m == 2 && p == 1 {
            // The one-step predictor of a SISO model (inputs u and y): the same, two inputs.
            let (u2, mut y0) = ([u[0].as_ref(), u[1].as_ref()], vec![0.0; len]);
            let done = match n {
                1 => simulate_two_input_fixed::<1>(&a, &b, &c, &d, &x, u2, &mut y0),
                2 => simulate_two_input_fixed::<2>(&a, &b, &c, &d, &x, u2, &mut y0),
                3 => simulate_two_input_fixed::<3>(&a, &b, &c, &d, &x, u2, &mut y0),
                4 => simulate_two_input_fixed::<4>(&a, &b, &c, &d, &x, u2, &mut y0),
                5 => simulate_two_input_fixed::<5>(&a, &b, &c, &d, &x, u2, &mut y0),
                6 => simulate_two_input_fixed::<6>(&a, &b, &c, &d, &x, u2, &mut y0),
                7 => simulate_two_input_fixed::<7>(&a, &b, &c, &d, &x, u2, &mut y0),
                8 => simulate_two_input_fixed::<8>(&a, &b, &c, &d, &x, u2, &mut y0),
                _ => false,
            };
            if done {
                return Ok(vec![y0]);
            }
        }
        Ok(simulate_general(&a, &b, &c, &d, (n, m, p), x, u))
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

/// The SISO simulation of [`StateSpace::simulate`] for `N` states, with the model in row-major
/// vectors (`a` N×N, `b` N×1, `c` 1×N) and `d`: per sample `y = Σ_j c_j x_j + d u`, then
/// `x⁺_i = Σ_j a_ij x_j + b_i u`, each sum accumulated from 0.0 in index order exactly as the
/// general loop does, so the outputs are the same to the bit. Returns `false` (nothing written)
/// if the sizes do not match `N`.
fn simulate_siso_fixed<const N: usize>(
    a: &[f64],
    b: &[f64],
    c: &[f64],
    d: f64,
    x0: &[f64],
    u: &[f64],
    y: &mut [f64],
) -> bool {
    if a.len() != N * N || y.len() != u.len() {
        return false;
    }
    let (Some((a, _)), Ok(b), Ok(c), Ok(x0)) = (
        a.as_chunks::<N>().0.split_first_chunk::<N>(),
        <[f64; N]>::try_from(b),
        <[f64; N]>::try_from(c),
        <[f64; N]>::try_from(x0),
    ) else {
        return false;
    };
    let mut x = x0;
    for (yk, &uk) in y.iter_mut().zip(u) {
        let mut acc = 0.0;
        for j in 0..N {
            acc += c[j] * x[j];
        }
        acc += d * uk;
        *yk = acc;
        let mut xn = [0.0; N];
        for i in 0..N {
            let mut acc = 0.0;
            for j in 0..N {
                acc += a[i][j] * x[j];
            }
            acc += b[i] * uk;
            xn[i] = acc;
        }
        x = xn;
    }
    true
}

/// [`simulate_siso_fixed`] for one output and two inputs (`b` N×2 and `d` 1×2 row-major):
/// each sum from 0.0 in the general loop's order (states, then input 0, then input 1), so the
/// outputs are the same to the bit. Returns `false` (nothing written) if the sizes do not
/// match `N`.
fn simulate_two_input_fixed<const N: usize>(
    a: &[f64],
    b: &[f64],
    c: &[f64],
    d: &[f64],
    x0: &[f64],
    u: [&[f64]; 2],
    y: &mut [f64],
) -> bool {
    if a.len() != N * N || b.len() != 2 * N || y.len() != u[0].len() || u[1].len() != u[0].len() {
        return false;
    }
    let (Some((a, _)), Some((b, _)), Ok(c), Ok(d), Ok(x0)) = (
        a.as_chunks::<N>().0.split_first_chunk::<N>(),
        b.as_chunks::<2>().0.split_first_chunk::<N>(),
        <[f64; N]>::try_from(c),
        <[f64; 2]>::try_from(d),
        <[f64; N]>::try_from(x0),
    ) else {
        return false;
    };
    let mut x = x0;
    for (yk, (&u0, &u1)) in y.iter_mut().zip(u[0].iter().zip(u[1])) {
        let mut acc = 0.0;
        for j in 0..N {
            acc += c[j] * x[j];
        }
        acc += d[0] * u0;
        acc += d[1] * u1;
        *yk = acc;
        let mut xn = [0.0; N];
        for i in 0..N {
            let mut acc = 0.0;
            for j in 0..N {
                acc += a[i][j] * x[j];
            }
            acc += b[i][0] * u0;
            acc += b[i][1] * u1;
            xn[i] = acc;
        }
        x = xn;
    }
    true
}

/// The general simulation loop of [`StateSpace::simulate`]: model in row-major vectors, sizes
/// `(n, m, p)`, initial state `x`, `m` input channels of equal length (checked by the caller).
fn simulate_general<U: AsRef<[f64]>>(
    a: &[f64],
    b: &[f64],
    c: &[f64],
    d: &[f64],
    (n, m, p): (usize, usize, usize),
    mut x: Vec<f64>,
    u: &[U],
) -> Vec<Vec<f64>> {
    let len = u.first().map_or(0, |ch| ch.as_ref().len());
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
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fixed-size SISO path equals the general loop to the bit, for every supported order
    /// (a lightly damped resonance plus real poles, a PRBS-like input, a non-zero initial state).
    #[test]
    fn fixed_siso_path_equals_general_loop_bit_for_bit() {
        let len = 5000;
        let mut rng = ferrosid_firmware::rng::SplitMix64::new(12345);
        let u: Vec<f64> = (0..len)
            .map(|_| if rng.next_u64() >> 63 == 1 { 1.0 } else { -0.7 })
            .collect();
        for n in 1..=8usize {
            // Block-diagonal-ish A: a rotation 0.98·R(0.3) then decaying real poles, with
            // small couplings so that every entry is used.
            let mut a = vec![0.0; n * n];
            for i in 0..n {
                a[i * n + i] = 0.9 - 0.05 * i as f64;
                if i + 1 < n {
                    a[i * n + i + 1] = 0.01 * (i + 1) as f64;
                }
            }
            if n >= 2 {
                let (c, s_) = (0.98 * 0.3f64.cos(), 0.98 * 0.3f64.sin());
                a[0] = c;
                a[1] = -s_;
                a[n] = s_;
                a[n + 1] = c;
            }
            let b: Vec<f64> = (0..n).map(|i| 1.0 / (i + 1) as f64).collect();
            let c: Vec<f64> = (0..n).map(|i| 0.5 - 0.1 * i as f64).collect();
            let d = 0.125;
            let x0: Vec<f64> = (0..n).map(|i| 0.3 * i as f64 - 0.2).collect();
            let general = simulate_general(&a, &b, &c, &[d], (n, 1, 1), x0.clone(), &[&u]);
            let mut fixed = vec![0.0; len];
            let ok = match n {
                1 => simulate_siso_fixed::<1>(&a, &b, &c, d, &x0, &u, &mut fixed),
                2 => simulate_siso_fixed::<2>(&a, &b, &c, d, &x0, &u, &mut fixed),
                3 => simulate_siso_fixed::<3>(&a, &b, &c, d, &x0, &u, &mut fixed),
                4 => simulate_siso_fixed::<4>(&a, &b, &c, d, &x0, &u, &mut fixed),
                5 => simulate_siso_fixed::<5>(&a, &b, &c, d, &x0, &u, &mut fixed),
                6 => simulate_siso_fixed::<6>(&a, &b, &c, d, &x0, &u, &mut fixed),
                7 => simulate_siso_fixed::<7>(&a, &b, &c, d, &x0, &u, &mut fixed),
                _ => simulate_siso_fixed::<8>(&a, &b, &c, d, &x0, &u, &mut fixed),
            };
            assert!(ok, "n = {n}: sizes refused");
            assert!(general[0].iter().any(|v| *v != 0.0));
            for (k, (g, f)) in general[0].iter().zip(&fixed).enumerate() {
                assert_eq!(g.to_bits(), f.to_bits(), "n = {n}, sample {k}: {g} vs {f}");
            }
        }
        // A size mismatch is refused, not misread.
        let mut y = vec![0.0; 3];
        assert!(!simulate_siso_fixed::<3>(
            &[0.0; 4], &[0.0; 3], &[0.0; 3], 0.0, &[0.0; 3], &[0.0; 3], &mut y
        ));
    }

    /// The fixed-size two-input path (a SISO model's one-step predictor) equals the general
    /// loop to the bit, for every supported order; a size mismatch is refused.
    #[test]
    fn fixed_two_input_path_equals_general_loop_bit_for_bit() {
        let len = 5000;
        let mut rng = ferrosid_firmware::rng::SplitMix64::new(99);
        let mut next = || rng.next_f64() - 0.5;
        let u0: Vec<f64> = (0..len).map(|_| next()).collect();
        let u1: Vec<f64> = (0..len).map(|_| next()).collect();
        for n in 1..=8usize {
            // Stable: diagonal 0.9 − 0.05 i plus small random couplings.
            let a: Vec<f64> = (0..n * n)
                .map(|k| {
                    if k / n == k % n {
                        0.9 - 0.05 * (k / n) as f64
                    } else {
                        0.02 * next()
                    }
                })
                .collect();
            let b: Vec<f64> = (0..2 * n).map(|_| next()).collect();
            let c: Vec<f64> = (0..n).map(|_| next()).collect();
            let d = [next(), next()];
            let x0: Vec<f64> = (0..n).map(|_| next()).collect();
            let general = simulate_general(&a, &b, &c, &d, (n, 2, 1), x0.clone(), &[&u0, &u1]);
            let mut fixed = vec![0.0; len];
            let uu = [u0.as_slice(), u1.as_slice()];
            let ok = match n {
                1 => simulate_two_input_fixed::<1>(&a, &b, &c, &d, &x0, uu, &mut fixed),
                2 => simulate_two_input_fixed::<2>(&a, &b, &c, &d, &x0, uu, &mut fixed),
                3 => simulate_two_input_fixed::<3>(&a, &b, &c, &d, &x0, uu, &mut fixed),
                4 => simulate_two_input_fixed::<4>(&a, &b, &c, &d, &x0, uu, &mut fixed),
                5 => simulate_two_input_fixed::<5>(&a, &b, &c, &d, &x0, uu, &mut fixed),
                6 => simulate_two_input_fixed::<6>(&a, &b, &c, &d, &x0, uu, &mut fixed),
                7 => simulate_two_input_fixed::<7>(&a, &b, &c, &d, &x0, uu, &mut fixed),
                _ => simulate_two_input_fixed::<8>(&a, &b, &c, &d, &x0, uu, &mut fixed),
            };
            assert!(ok, "n = {n}: sizes refused");
            assert!(general[0].iter().any(|v| *v != 0.0));
            for (k, (g, f)) in general[0].iter().zip(&fixed).enumerate() {
                assert_eq!(g.to_bits(), f.to_bits(), "n = {n}, sample {k}: {g} vs {f}");
            }
        }
        let mut y = vec![0.0; 3];
        assert!(!simulate_two_input_fixed::<3>(
            &[0.0; 9],
            &[0.0; 4],
            &[0.0; 3],
            &[0.0; 2],
            &[0.0; 3],
            [&[0.0; 3], &[0.0; 3]],
            &mut y
        ));
    }
}
