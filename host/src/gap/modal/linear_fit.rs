//! The linear half of the variable-projection fit of a [`ModalModel`]: for fixed poles the
//! output is linear in (residues, feedthrough, offset), solved by weighted least squares from
//! normal equations accumulated over the free-run states; and the Levenberg–Marquardt output-error
//! refinement of the poles on the projected residual.
use super::{FitSet, ModalModel, Stepper};
use crate::gap::drift::detrended;
use crate::lti::solve_square;
use faer::Mat;

impl ModalModel {
    fn n_regressors(&self) -> usize {
        self.n_states() + usize::from(self.use_d) + 1
    }

    /// Fills `phi` with the regressors at the current state and input.
    #[inline]
    fn regressors(&self, x: &[f64], w: f64, phi: &mut [f64]) {
        let n = x.len();
        phi[..n].copy_from_slice(x);
        let mut k = n;
        if self.use_d {
            phi[k] = w;
            k += 1;
        }
        phi[k] = 1.0;
    }

    /// One log's unweighted normal equations of the variable-projection step: the upper
    /// triangle of Σ φφᵀ (row-major, k×k), Σ φ·y and Σ y² over the scored samples (`keep`: a
    /// flag per sample, missing flags count as kept). Fixed-size kernels for up to 16
    /// regressors (the sums in the same order as the generic loop, so the same bits).
    fn normal_equations_of_log(
        &self,
        st: &Stepper<'_>,
        w: &[f64],
        y: &[f64],
        warmup: usize,
        keep: Option<&[bool]>,
    ) -> (Vec<f64>, Vec<f64>, f64) {
        macro_rules! fixed {
            ($($k:literal)*) => {
                match self.n_regressors() {
                    $($k => {
                        let (g, h, yl) = self.normal_equations_fixed::<$k>(st, w, y, warmup, keep);
                        return (g.iter().flatten().copied().collect(), h.to_vec(), yl);
                    })*
                    _ => {}
                }
            };
        }
        fixed!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16);
        let k = self.n_regressors();
        let mut x = self.zero_state();
        let mut phi = vec![0.0; k];
        let mut gl = vec![0.0; k * k];
        let mut hl = vec![0.0; k];
        let mut yl = 0.0;
        for (t, (&wk, &yk)) in w.iter().zip(y).enumerate() {
            if t >= warmup && keep.is_none_or(|m| m.get(t).copied().unwrap_or(true)) {
                self.regressors(&x, wk, &mut phi);
                for i in 0..k {
                    let pi = phi[i];
                    hl[i] += pi * yk;
                    let row = &mut gl[i * k..i * k + k];
                    for j in i..k {
                        row[j] += pi * phi[j];
                    }
                }
                yl += yk * yk;
            }
            st.step(&mut x, wk);
        }
        (gl, hl, yl)
    }

    /// [`Self::normal_equations_of_log`] for exactly `K` regressors.
    #[allow(clippy::needless_range_loop)]
    fn normal_equations_fixed<const K: usize>(
        &self,
        st: &Stepper<'_>,
        w: &[f64],
        y: &[f64],
        warmup: usize,
        keep: Option<&[bool]>,
    ) -> ([[f64; K]; K], [f64; K], f64) {
        let mut x = self.zero_state();
        let mut phi = [0.0; K];
        let mut gl = [[0.0; K]; K];
        let mut hl = [0.0; K];
        let mut yl = 0.0;
        for (t, (&wk, &yk)) in w.iter().zip(y).enumerate() {
            if t >= warmup && keep.is_none_or(|m| m.get(t).copied().unwrap_or(true)) {
                self.regressors(&x, wk, &mut phi);
                for i in 0..K {
                    let pi = phi[i];
                    hl[i] += pi * yk;
                    for j in i..K {
                        gl[i][j] += pi * phi[j];
                    }
                }
                yl += yk * yk;
            }
            st.step(&mut x, wk);
        }
        (gl, hl, yl)
    }

    fn set_linear_params(&mut self, c: &[f64]) {
        let n = self.n_states();
        self.residues.copy_from_slice(&c[..n]);
        let mut k = n;
        if self.use_d {
            self.d = c[k];
            k += 1;
        } else {
            self.d = 0.0;
        }
        self.offset = c[k];
    }

    /// Variable projection step: with the poles fixed, sets residues, feedthrough and offset to
    /// the weighted least-squares optimum on `set` and returns the cost Σ NRMSE². `None` when
    /// the normal equations are singular or the result is not finite.
    pub fn fit_linear_params(&mut self, set: &FitSet) -> Option<f64> {
        self.fit_linear_params_masked(set, None)
    }

    /// [`Self::fit_linear_params`] using only the samples where `mask` (one flag per sample
    /// and log) is true; the returned cost is over those samples (same weights).
    pub fn fit_linear_params_masked(
        &mut self,
        set: &FitSet,
        mask: Option<&[Vec<bool>]>,
    ) -> Option<f64> {
        self.fit_linear_params_with_input(set, &set.w, mask)
    }

    /// [`Self::fit_linear_params_masked`] with the inputs `w` (one per log) in place of
    /// `set.w`: the same result as on `set.with_input(w)`, without copying the outputs.
    ///
    /// With `set.drift_window` the step minimises the drift-free cost instead (the metric of
    /// an integrating model, [`crate::gap::drift::scored_sse`]): see
    /// [`Self::fit_linear_params_drift_free`].
    pub fn fit_linear_params_with_input(
        &mut self,
        set: &FitSet,
        w: &[Vec<f64>],
        mask: Option<&[Vec<bool>]>,
    ) -> Option<f64> {
        if let Some(win) = set.drift_window.filter(|&win| win >= 3) {
            return self.fit_linear_params_drift_free(set, w, mask, win);
        }
        let k = self.n_regressors();
        let mut g = Mat::<f64>::zeros(k, k);
        let mut h = Mat::<f64>::zeros(k, 1);
        let mut yy = 0.0;
        let st = self.stepper();
        for (l, ((w, y), &wt)) in w.iter().zip(&set.y).zip(&set.weight).enumerate() {
            let keep = mask.and_then(|m| m.get(l)).map(Vec::as_slice);
            let (gl, hl, yl) = self.normal_equations_of_log(&st, w, y, set.warmup, keep);
            for i in 0..k {
                for j in i..k {
                    g[(i, j)] += wt * gl[i * k + j];
                }
                h[(i, 0)] += wt * hl[i];
            }
            yy += wt * yl;
        }
        let (c, cost) = least_squares_from_normal(&mut g, &h, yy)?;
        if !cost.is_finite() {
            return None;
        }
        self.set_linear_params(&c);
        Some(cost)
    }

    /// The variable-projection step in the drift-free metric: the residues and feedthrough
    /// minimise Σ weight·‖detrended(y − Φc)‖² over the scored (and kept) samples, which is
    /// linear least squares in the detrended regressors because [`detrended`] is linear (each
    /// regressor column is simulated, stored and detrended per log: O(K·N) memory). The
    /// detrended offset column is zero, so the offset is not in that problem: it is set to
    /// the weighted mean of the plain residual y − Φc (the level a plot of the free run needs;
    /// no drift-free cost depends on it). Returns the drift-free cost; `None` as
    /// [`Self::fit_linear_params_with_input`].
    fn fit_linear_params_drift_free(
        &mut self,
        set: &FitSet,
        w: &[Vec<f64>],
        mask: Option<&[Vec<bool>]>,
        window: usize,
    ) -> Option<f64> {
        let k = self.n_regressors() - 1; // without the offset
        let mut g = Mat::<f64>::zeros(k, k);
        let mut h = Mat::<f64>::zeros(k, 1);
        let mut yy = 0.0;
        // Per log: weight, Σy, Σφ_i and count over the kept samples (for the offset).
        let mut level: Vec<(f64, f64, Vec<f64>, f64)> = Vec::with_capacity(set.y.len());
        let st = self.stepper();
        let mut phi = vec![0.0; k + 1];
        for (l, ((w, y), &wt)) in w.iter().zip(&set.y).zip(&set.weight).enumerate() {
            let n = y.len().min(w.len());
            if n <= set.warmup {
                continue;
            }
            let keep = mask.and_then(|m| m.get(l)).map(Vec::as_slice);
            let kept = |t: usize| keep.is_none_or(|m| m.get(t).copied().unwrap_or(true));
            let mut cols = vec![Vec::with_capacity(n - set.warmup); k];
            let mut x = self.zero_state();
            for (t, &wk) in w[..n].iter().enumerate() {
                if t >= set.warmup {
                    self.regressors(&x, wk, &mut phi);
                    for (c, &p) in cols.iter_mut().zip(&phi[..k]) {
                        c.push(p);
                    }
                }
                st.step(&mut x, wk);
            }
            let yd = detrended(&y[set.warmup..n], window);
            let cd: Vec<Vec<f64>> = cols.iter().map(|c| detrended(c, window)).collect();
            let (mut sy, mut sphi, mut cnt) = (0.0, vec![0.0; k], 0.0);
            for (j, &yj) in yd.iter().enumerate() {
                if !kept(set.warmup + j) {
                    continue;
                }
                for i in 0..k {
                    let pi = cd[i][j];
                    h[(i, 0)] += wt * pi * yj;
                    for jj in i..k {
                        g[(i, jj)] += wt * pi * cd[jj][j];
                    }
                    sphi[i] += cols[i][j];
                }
                yy += wt * yj * yj;
                sy += y[set.warmup + j];
                cnt += 1.0;
            }
            level.push((wt, sy, sphi, cnt));
        }
        let (c, cost) = least_squares_from_normal(&mut g, &h, yy)?;
        let (num, den) = level
            .iter()
            .fold((0.0, 0.0), |(a, b), (wt, sy, sphi, cnt)| {
                let fitted: f64 = c.iter().zip(sphi).map(|(ci, si)| ci * si).sum();
                (a + wt * (sy - fitted), b + wt * cnt)
            });
        let offset = if den > 0.0 { num / den } else { 0.0 };
        if !(cost.is_finite() && offset.is_finite()) {
            return None;
        }
        let mut all = c;
        all.push(offset);
        self.set_linear_params(&all);
        Some(cost)
    }

    /// Weighted residual vector √weight·(y − ŷ) after the variable-projection step (for
    /// Levenberg–Marquardt); with `set.drift_window` the residual of each log has its local
    /// linear trend removed ([`detrended`]), the metric every candidate of an integrating
    /// model is fitted and scored in, so the linear re-fit minimises the same cost.
    pub fn projected_residuals(&mut self, set: &FitSet) -> Option<Vec<f64>> {
        self.fit_linear_params(set)?;
        let scored: usize = set
            .y
            .iter()
            .map(|y| y.len().saturating_sub(set.warmup))
            .sum();
        let mut r = Vec::with_capacity(scored);
        for ((w, y), &wt) in set.w.iter().zip(&set.y).zip(&set.weight) {
            let sw = wt.sqrt();
            let yh = self.simulate(w);
            let e = y.iter().zip(&yh).skip(set.warmup).map(|(a, b)| a - b);
            match set.drift_window {
                Some(win) => r.extend(
                    detrended(&e.collect::<Vec<_>>(), win)
                        .iter()
                        .map(|v| sw * v),
                ),
                None => r.extend(e.map(|v| sw * v)),
            }
        }
        Some(r)
    }

    /// Output-error fit of poles and linear parameters on `set`, starting from the current
    /// poles: Levenberg–Marquardt over the pole parameters (at most `max_iter` steps) with the
    /// variable-projection step inside. Returns the final cost Σ NRMSE² in the set's metric
    /// (drift-free with `set.drift_window`).
    pub fn fit_output_error(&mut self, set: &FitSet, max_iter: usize) -> Option<f64> {
        let theta0 = self.pole_params();
        let mut work = self.clone();
        let (theta, _) = crate::optim::levenberg_marquardt(
            |th| {
                work.set_pole_params(th);
                work.projected_residuals(set)
            },
            &theta0,
            max_iter,
            1e-7,
        );
        self.set_pole_params(&theta);
        self.fit_linear_params(set)
    }

    /// Cost Σ NRMSE² of the current model on `set` (free run; no refit).
    pub fn cost(&self, set: &FitSet) -> f64 {
        let mut c = 0.0;
        for ((w, y), &wt) in set.w.iter().zip(&set.y).zip(&set.weight) {
            let yh = self.simulate(w);
            c += wt
                * y.iter()
                    .zip(&yh)
                    .skip(set.warmup)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>();
        }
        c
    }
}

/// The least-squares solution c of the normal equations (upper triangle of `g` filled, `h`,
/// and Σy² = `yy`; `g` is mirrored in place) and its cost yy − 2cᵀh + cᵀgc, clamped at 0.
fn least_squares_from_normal(g: &mut Mat<f64>, h: &Mat<f64>, yy: f64) -> Option<(Vec<f64>, f64)> {
    let k = g.nrows();
    for i in 0..k {
        for j in 0..i {
            g[(i, j)] = g[(j, i)];
        }
    }
    let c = solve_scaled(g, h)?;
    let quad: f64 = (0..k)
        .map(|i| c[i] * ((0..k).map(|j| g[(i, j)] * c[j]).sum::<f64>() - 2.0 * h[(i, 0)]))
        .sum();
    Some((c, (yy + quad).max(0.0)))
}

/// Solves the symmetric positive semi-definite system g·c = h after equilibrating by the
/// diagonal, with a relative ridge of 1e-12 for nearly collinear regressors.
pub(crate) fn solve_scaled(g: &Mat<f64>, h: &Mat<f64>) -> Option<Vec<f64>> {
    let k = g.nrows();
    let s: Vec<f64> = (0..k)
        .map(|i| {
            let d = g[(i, i)];
            if d > 0.0 {
                1.0 / d.sqrt()
            } else {
                1.0
            }
        })
        .collect();
    let gs = Mat::from_fn(k, k, |i, j| {
        g[(i, j)] * s[i] * s[j] + if i == j { 1e-12 } else { 0.0 }
    });
    let hs = Mat::from_fn(k, 1, |i, _| h[(i, 0)] * s[i]);
    let z = solve_square(gs.as_ref(), hs.as_ref(), "variable projection").ok()?;
    let c: Vec<f64> = (0..k).map(|i| z[(i, 0)] * s[i]).collect();
    c.iter().all(|v| v.is_finite()).then_some(c)
}
