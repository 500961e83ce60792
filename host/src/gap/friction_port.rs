//! Friction on the slowest mode of a modal linear part ([`FrictionPort::SlowestMode`]): the
//! realisation, the stick-slip loop and the variable-projection step of the residues.
use super::effect::StickSlip;
use super::fit::AugmentedModel;
use super::modal::{FitSet, ModalModel};

/// Where friction on the modal linear part enters it.
///
/// A body driven through faster dynamics (a DC motor's armature current behind its voltage
/// input: velocity/voltage has relative degree two) feels friction behind them: holding it at
/// rest takes a force that balances the drive's output, not a voltage that stops the current
/// within a sub-step. [`FrictionPort::SlowestMode`] realises the linear part G as the series
/// D·B of a first-order body B(z) = K_b/(z − p_b) at its slowest real pole p_b and the rest D,
/// so y = G(u) − B(f): the force f enters that mode only, and K_b = G(1)·(1 − p_b) keeps f in
/// input units (a constant force cancels an equal constant input).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrictionPort {
    /// Friction subtracts from the input of the whole linear part.
    Input,
    /// Friction acts on the slowest real mode only (output = the body's velocity; models
    /// without an integrator, with at least two states and every real pole in (0, 1)).
    SlowestMode,
}

impl AugmentedModel {
    /// Closed loop of the linear part with stick-slip friction on its slowest mode (body
    /// `b`, [`FrictionPort::SlowestMode`]) in `m` sub-steps per sample: y = G(u) − B(f) with
    /// B(z) = K_b/(z − p_b). Returns the output and the per-sample mean friction force (input
    /// units). `None` without a sub-stepper.
    pub fn friction_loop_body(
        &self,
        u: &[f64],
        law: StickSlip,
        m: usize,
        b: usize,
    ) -> Option<(Vec<f64>, Vec<f64>)> {
        let lin = &self.linear;
        let m = m.max(1);
        let sub = lin.substepper(m)?;
        let pb = *lin.real.get(b)?;
        let ph = pb.powf(1.0 / m as f64);
        let beta = if m == 1 { 1.0 } else { (ph - 1.0) / (pb - 1.0) };
        let kb = body_gain(lin, b);
        let g = kb * beta;
        let cb = sub.cb();
        let mut fr = law;
        let mut x = lin.zero_state();
        let mut xf = 0.0;
        let mut y = Vec::with_capacity(u.len());
        let mut fm = Vec::with_capacity(u.len());
        let mut yo = 0.0;
        for &uk in u {
            let y0 = yo;
            let mut fsum = 0.0;
            for _ in 0..m {
                let next = sub.free_next_output(&x) - kb * ph * xf;
                let f = fr.force(next + lin.offset + cb * uk, g);
                sub.step(&mut x, uk);
                xf = ph * xf + beta * f;
                yo = next + cb * uk - g * f;
                fsum += f;
            }
            y.push(y0 + lin.d * uk + lin.offset);
            fm.push(fsum / m as f64);
        }
        Some((y, fm))
    }
}

/// The slowest real mode of a modal model, the body of [`FrictionPort::SlowestMode`]: the
/// largest real pole, when there are at least two states, no integrator and every real pole in
/// (0, 1) (a sub-step exists).
pub fn slowest_mode(lin: &ModalModel) -> Option<usize> {
    if lin.n_states() < 2 || lin.real.iter().any(|&p| !(p > 0.0 && p < 1.0 - 1e-9)) {
        return None;
    }
    (0..lin.real.len()).max_by(|&i, &j| lin.real[i].total_cmp(&lin.real[j]))
}

/// Steady state of each modal state for a unit constant input: 1/(1 − p) for a real mode,
/// ((1 − r·cos φ), r·sin φ)/det for a pair (det = (1 − r·cos φ)² + (r·sin φ)²).
fn state_dc(lin: &ModalModel) -> Vec<f64> {
    let mut v: Vec<f64> = lin.real.iter().map(|&p| 1.0 / (1.0 - p)).collect();
    for &(r, phi) in &lin.pairs {
        let (s, c) = phi.sin_cos();
        let (a, b) = (1.0 - r * c, r * s);
        let det = a * a + b * b;
        v.push(a / det);
        v.push(b / det);
    }
    v
}

/// K_b = G(1)·(1 − p_b): the gain of the body B(z) = K_b/(z − p_b) that keeps the friction
/// force in input units ([`FrictionPort::SlowestMode`]).
fn body_gain(lin: &ModalModel, b: usize) -> f64 {
    let dc: f64 = state_dc(lin)
        .iter()
        .zip(&lin.residues)
        .map(|(a, c)| a * c)
        .sum::<f64>()
        + lin.d;
    dc * (1.0 - lin.real[b])
}

/// Variable-projection step of a model whose friction acts on its slowest mode `b`: with the
/// inputs `u` and the friction forces `f` (per sample, one list per log) fixed, the residues,
/// feedthrough and offset minimising the weighted squared error of
/// y = Σ c_i·x_i(u) + d·u + offset − K_b·x_f(f), K_b = (1 − p_b)·(Σ c_i·dc_i + d) (linear in
/// them), with x_f the body mode driven by f. `mask` leaves samples out. `None` when the normal
/// equations are singular.
pub(crate) fn fit_linear_params_body(
    lin: &mut ModalModel,
    set: &FitSet,
    u: &[Vec<f64>],
    f: &[Vec<f64>],
    b: usize,
    mask: Option<&[Vec<bool>]>,
) -> Option<()> {
    let n = lin.n_states();
    let k = n + usize::from(lin.use_d) + 1;
    let dc = state_dc(lin);
    let pb = lin.real[b];
    let mut g = faer::Mat::<f64>::zeros(k, k);
    let mut h = faer::Mat::<f64>::zeros(k, 1);
    let st = lin.stepper();
    let mut phi = vec![0.0; k];
    for (l, ((ul, fl), (y, &wt))) in u
        .iter()
        .zip(f)
        .zip(set.y.iter().zip(&set.weight))
        .enumerate()
    {
        let keep = mask.and_then(|m| m.get(l));
        let mut x = lin.zero_state();
        let mut xf = 0.0;
        for (t, ((&uk, &fk), &yk)) in ul.iter().zip(fl).zip(y).enumerate() {
            if t >= set.warmup && keep.is_none_or(|m| m.get(t).copied().unwrap_or(true)) {
                for i in 0..n {
                    phi[i] = x[i] - (1.0 - pb) * dc[i] * xf;
                }
                let mut j = n;
                if lin.use_d {
                    phi[j] = uk - (1.0 - pb) * xf;
                    j += 1;
                }
                phi[j] = 1.0;
                for i in 0..k {
                    h[(i, 0)] += wt * phi[i] * yk;
                    for jj in i..k {
                        g[(i, jj)] += wt * phi[i] * phi[jj];
                    }
                }
            }
            st.step(&mut x, uk);
            xf = pb * xf + fk;
        }
    }
    for i in 0..k {
        for j in 0..i {
            g[(i, j)] = g[(j, i)];
        }
    }
    let c = super::modal::solve_scaled(&g, &h)?;
    if c.iter().any(|v| !v.is_finite()) {
        return None;
    }
    lin.residues.copy_from_slice(&c[..n]);
    let mut j = n;
    if lin.use_d {
        lin.d = c[j];
        j += 1;
    }
    lin.offset = c[j];
    Some(())
}
