//! Small derivative-free and least-squares optimisers (the gap diagnosis's effect fits, the
//! W_m Nelder–Mead reference, the H∞-norm peak search).
//!
//! * [`golden_section`] — 1-D minimisation of a unimodal function on a bracket (Kiefer 1953);
//!   `iters` evaluations shrink the bracket by 0.618^iters.
//! * [`nelder_mead`] — simplex search (Nelder & Mead 1965, standard coefficients 1, 2, 0.5, 0.5)
//!   for the 2-D effect parameters.
//! * [`levenberg_marquardt`] — damped Gauss–Newton on a residual vector with forward-difference
//!   Jacobians (Marquardt 1963), for the pole parameters of the linear part.
//!
//! All three only ever call the objective with finite arguments and treat a non-finite objective
//! value as "worse than anything", so a model that blows up during a search is simply rejected.
use crate::lti::solve_square;
use faer::Mat;

/// Replaces NaN by +inf so comparisons treat it as the worst value.
fn sane(v: f64) -> f64 {
    if v.is_nan() {
        f64::INFINITY
    } else {
        v
    }
}

/// Minimises `f` on `[lo, hi]` by golden-section search with `iters` shrink steps.
/// Returns `(x_best, f_best)` over every point evaluated (so a non-unimodal `f` still returns
/// the best point seen). Requires `lo <= hi`.
pub fn golden_section(mut f: impl FnMut(f64) -> f64, lo: f64, hi: f64, iters: usize) -> (f64, f64) {
    const INV_PHI: f64 = 0.618_033_988_749_894_8;
    let (mut a, mut b) = (lo, hi);
    let mut c = b - INV_PHI * (b - a);
    let mut d = a + INV_PHI * (b - a);
    let mut fc = sane(f(c));
    let mut fd = sane(f(d));
    let (mut xb, mut fb) = if fc <= fd { (c, fc) } else { (d, fd) };
    for _ in 0..iters {
        if fc <= fd {
            b = d;
            d = c;
            fd = fc;
            c = b - INV_PHI * (b - a);
            fc = sane(f(c));
            if fc < fb {
                xb = c;
                fb = fc;
            }
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + INV_PHI * (b - a);
            fd = sane(f(d));
            if fd < fb {
                xb = d;
                fb = fd;
            }
        }
    }
    (xb, fb)
}

/// Nelder–Mead simplex minimisation from `x0` with initial step sizes `step` (one per
/// coordinate), at most `max_evals` objective evaluations, stopping early when the simplex's
/// spread of function values falls below `ftol` (absolute). Returns `(x_best, f_best)`.
pub fn nelder_mead(
    mut f: impl FnMut(&[f64]) -> f64,
    x0: &[f64],
    step: &[f64],
    max_evals: usize,
    ftol: f64,
) -> (Vec<f64>, f64) {
    let n = x0.len();
    let mut simplex: Vec<Vec<f64>> = Vec::with_capacity(n + 1);
    simplex.push(x0.to_vec());
    for i in 0..n {
        let mut x = x0.to_vec();
        x[i] += step[i];
        simplex.push(x);
    }
    let mut fx: Vec<f64> = simplex.iter().map(|x| sane(f(x))).collect();
    let mut evals = n + 1;
    while evals < max_evals {
        // Order: best first.
        let mut idx: Vec<usize> = (0..=n).collect();
        idx.sort_by(|&i, &j| fx[i].total_cmp(&fx[j]));
        simplex = idx.iter().map(|&i| simplex[i].clone()).collect();
        fx = idx.iter().map(|&i| fx[i]).collect();
        if (fx[n] - fx[0]).abs() <= ftol {
            break;
        }
        let centroid: Vec<f64> = (0..n)
            .map(|j| simplex[..n].iter().map(|x| x[j]).sum::<f64>() / n as f64)
            .collect();
        let along = |t: f64| -> Vec<f64> {
            (0..n)
                .map(|j| centroid[j] + t * (simplex[n][j] - centroid[j]))
                .collect()
        };
        let xr = along(-1.0);
        let fr = sane(f(&xr));
        evals += 1;
        if fr < fx[0] {
            let xe = along(-2.0);
            let fe = sane(f(&xe));
            evals += 1;
            if fe < fr {
                simplex[n] = xe;
                fx[n] = fe;
            } else {
                simplex[n] = xr;
                fx[n] = fr;
            }
        } else if fr < fx[n - 1] {
            simplex[n] = xr;
            fx[n] = fr;
        } else {
            let (xc, fc) = if fr < fx[n] {
                let xc = along(-0.5);
                (xc.clone(), sane(f(&xc)))
            } else {
                let xc = along(0.5);
                (xc.clone(), sane(f(&xc)))
            };
            evals += 1;
            if fc < fx[n].min(fr) {
                simplex[n] = xc;
                fx[n] = fc;
            } else {
                // Shrink towards the best vertex.
                let (best, rest) = simplex.split_at_mut(1);
                for (i, v) in rest.iter_mut().enumerate().take(n) {
                    for (vj, bj) in v.iter_mut().zip(&best[0]) {
                        *vj = bj + 0.5 * (*vj - bj);
                    }
                    fx[i + 1] = sane(f(v));
                    evals += 1;
                }
            }
        }
    }
    let best = (0..=n)
        .min_by(|&i, &j| fx[i].total_cmp(&fx[j]))
        .unwrap_or(0);
    (simplex[best].clone(), fx[best])
}

/// Levenberg–Marquardt on `residuals(theta) -> Option<Vec<f64>>` (None = infeasible point),
/// minimising the sum of squares. Forward-difference Jacobian with step
/// `1e-6 · max(1, |theta_i|)`; at most `max_iter` accepted or rejected steps; stops when the
/// relative cost decrease of an accepted step is below `rtol`. Returns `(theta, cost)`; if the
/// start point is infeasible the start is returned with an infinite cost.
pub fn levenberg_marquardt(
    residuals: impl FnMut(&[f64]) -> Option<Vec<f64>>,
    theta0: &[f64],
    max_iter: usize,
    rtol: f64,
) -> (Vec<f64>, f64) {
    let steps: Vec<f64> = theta0.iter().map(|t| 1e-6 * t.abs().max(1.0)).collect();
    levenberg_marquardt_steps(residuals, theta0, &steps, max_iter, rtol)
}

/// [`levenberg_marquardt`] with explicit forward-difference steps per parameter (larger steps
/// for parameters whose effect on the residual is piecewise smooth, such as friction levels).
pub fn levenberg_marquardt_steps(
    mut residuals: impl FnMut(&[f64]) -> Option<Vec<f64>>,
    theta0: &[f64],
    steps: &[f64],
    max_iter: usize,
    rtol: f64,
) -> (Vec<f64>, f64) {
    let p = theta0.len();
    let ss = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
    let mut theta = theta0.to_vec();
    let Some(mut r) = residuals(&theta) else {
        return (theta, f64::INFINITY);
    };
    let mut cost = sane(ss(&r));
    if p == 0 || !cost.is_finite() {
        return (theta, cost);
    }
    let mut lambda = 1e-3;
    let mut jac: Vec<Vec<f64>> = Vec::new();
    let mut need_jac = true;
    for _ in 0..max_iter {
        if need_jac {
            jac.clear();
            for i in 0..p {
                let h = steps[i];
                let mut t = theta.clone();
                t[i] += h;
                match residuals(&t) {
                    Some(ri) if ri.len() == r.len() => {
                        jac.push(ri.iter().zip(&r).map(|(a, b)| (a - b) / h).collect())
                    }
                    _ => jac.push(vec![0.0; r.len()]),
                }
            }
            need_jac = false;
        }
        // Normal equations (JᵀJ + λ diag(JᵀJ)) δ = −Jᵀr.
        let mut jtj = Mat::<f64>::zeros(p, p);
        let mut jtr = Mat::<f64>::zeros(p, 1);
        for i in 0..p {
            // Four columns per pass over the residual length: four independent sums (each in
            // the same order as a plain iterator sum) instead of one latency-bound chain.
            let mut k = i;
            while k + 4 <= p {
                let v = dot4(&jac[i], [&jac[k], &jac[k + 1], &jac[k + 2], &jac[k + 3]]);
                for (q, &vq) in v.iter().enumerate() {
                    jtj[(i, k + q)] = vq;
                    jtj[(k + q, i)] = vq;
                }
                k += 4;
            }
            for k in k..p {
                let v: f64 = jac[i].iter().zip(&jac[k]).map(|(a, b)| a * b).sum();
                jtj[(i, k)] = v;
                jtj[(k, i)] = v;
            }
            jtr[(i, 0)] = -jac[i].iter().zip(&r).map(|(a, b)| a * b).sum::<f64>();
        }
        let mut lhs = jtj.clone();
        let diag_max = (0..p)
            .map(|i| jtj[(i, i)])
            .fold(0.0f64, f64::max)
            .max(1e-300);
        for i in 0..p {
            lhs[(i, i)] += lambda * jtj[(i, i)].max(1e-12 * diag_max);
        }
        let Ok(delta) = solve_square(lhs.as_ref(), jtr.as_ref(), "Levenberg-Marquardt step") else {
            lambda *= 10.0;
            if lambda > 1e12 {
                break;
            }
            continue;
        };
        let trial: Vec<f64> = (0..p).map(|i| theta[i] + delta[(i, 0)]).collect();
        if trial.iter().any(|v| !v.is_finite()) {
            lambda *= 10.0;
            continue;
        }
        match residuals(&trial) {
            Some(rt) if rt.len() == r.len() && sane(ss(&rt)) < cost => {
                let new_cost = ss(&rt);
                let rel = (cost - new_cost) / cost.max(1e-300);
                theta = trial;
                r = rt;
                cost = new_cost;
                lambda = (lambda * 0.3).max(1e-9);
                need_jac = true;
                if rel < rtol {
                    break;
                }
            }
            _ => {
                lambda *= 10.0;
                if lambda > 1e12 {
                    break;
                }
            }
        }
    }
    (theta, cost)
}

/// The dot products of `a` with each of `b` (over the shortest length), each summed in index
/// order from −0 like `Iterator::sum` (so the same bits as four separate sums).
#[allow(clippy::needless_range_loop)]
fn dot4(a: &[f64], b: [&[f64]; 4]) -> [f64; 4] {
    let n = b.iter().fold(a.len(), |m, v| m.min(v.len()));
    let (a, b0, b1, b2, b3) = (&a[..n], &b[0][..n], &b[1][..n], &b[2][..n], &b[3][..n]);
    let mut s = [-0.0f64; 4];
    for t in 0..n {
        let at = a[t];
        s[0] += at * b0[t];
        s[1] += at * b1[t];
        s[2] += at * b2[t];
        s[3] += at * b3[t];
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The four-way dot product gives the bits of four separate iterator sums (exact
    /// comparison: same products summed in the same order), including an all-negative-zero
    /// column and unequal lengths.
    #[test]
    fn dot4_matches_iterator_sums_bit_for_bit() {
        let n = 1001;
        let f = |s: f64| -> Vec<f64> {
            (0..n)
                .map(|t| ((t as f64 * s).sin() * 1e3).fract())
                .collect()
        };
        let a = f(0.37);
        let b = [f(1.1), f(2.3), vec![-0.0; n], f(0.05)[..n - 7].to_vec()];
        let got = dot4(&a, [&b[0], &b[1], &b[2], &b[3]]);
        let n_min = n - 7;
        for (q, bq) in b.iter().enumerate() {
            let want: f64 = a[..n_min].iter().zip(bq).map(|(x, y)| x * y).sum();
            assert_eq!(got[q].to_bits(), want.to_bits(), "column {q}");
        }
    }

    #[test]
    fn golden_finds_parabola_minimum() {
        let (x, f) = golden_section(|x| (x - 0.3).powi(2) + 1.0, -2.0, 5.0, 60);
        assert!((x - 0.3).abs() < 1e-6, "x = {x}");
        assert!((f - 1.0).abs() < 1e-12);
    }

    #[test]
    fn nelder_mead_rosenbrock() {
        let rosen = |x: &[f64]| 100.0 * (x[1] - x[0] * x[0]).powi(2) + (1.0 - x[0]).powi(2);
        let (x, f) = nelder_mead(rosen, &[-1.2, 1.0], &[0.5, 0.5], 2000, 1e-14);
        assert!(
            (x[0] - 1.0).abs() < 1e-3 && (x[1] - 1.0).abs() < 1e-3,
            "{x:?}"
        );
        assert!(f < 1e-6);
    }

    #[test]
    fn lm_fits_exponential() {
        // y = 2 exp(-0.7 t), fit (a, b) from (1, -0.1).
        let t: Vec<f64> = (0..50).map(|k| k as f64 * 0.1).collect();
        let y: Vec<f64> = t.iter().map(|t| 2.0 * (-0.7 * t).exp()).collect();
        let (th, cost) = levenberg_marquardt(
            |p| {
                Some(
                    t.iter()
                        .zip(&y)
                        .map(|(t, y)| p[0] * (p[1] * t).exp() - y)
                        .collect(),
                )
            },
            &[1.0, -0.1],
            100,
            1e-15,
        );
        assert!(
            (th[0] - 2.0).abs() < 1e-6 && (th[1] + 0.7).abs() < 1e-6,
            "{th:?}"
        );
        assert!(cost < 1e-12);
    }
}
