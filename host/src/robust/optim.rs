//! Derivative-free minimisation (Nelder–Mead simplex) for the small, non-smooth problems of
//! this module: weight fitting (2–6 parameters) and controller refinement.
//!
//! Standard coefficients (reflection 1, expansion 2, contraction ½, shrink ½; Lagarias et al.
//! 1998), with restarts from the best vertex on a fresh simplex so that a collapsed simplex
//! cannot stall the search. Non-finite objective values are treated as +∞.

/// Result of [`nelder_mead`].
#[derive(Debug, Clone, PartialEq)]
pub struct Minimum {
    /// Best point found.
    pub x: Vec<f64>,
    /// Objective at `x`.
    pub f: f64,
    /// Objective evaluations used.
    pub evaluations: usize,
}

/// Minimises `f` from `x0` with initial simplex steps `step` (one per coordinate, non-zero),
/// at most `max_evals` evaluations per restart and `restarts` restarts. Stops a restart when
/// the spread of simplex values falls below `ftol·(|f_best| + 1e-30)` and the simplex diameter
/// below `xtol`. The best vertex never gets worse, so the result is at least as good as `x0`.
pub fn nelder_mead<F: FnMut(&[f64]) -> f64>(
    mut f: F,
    x0: &[f64],
    step: &[f64],
    max_evals: usize,
    restarts: usize,
    ftol: f64,
    xtol: f64,
) -> Minimum {
    let n = x0.len();
    let mut evals = 0usize;
    let mut eval = |x: &[f64], evals: &mut usize| -> f64 {
        *evals += 1;
        let v = f(x);
        if v.is_finite() {
            v
        } else {
            f64::INFINITY
        }
    };
    let mut best_x = x0.to_vec();
    let mut best_f = eval(&best_x, &mut evals);
    if n == 0 {
        return Minimum {
            x: best_x,
            f: best_f,
            evaluations: evals,
        };
    }
    for round in 0..=restarts {
        let scale = if round == 0 {
            1.0
        } else {
            0.5f64.powi(round as i32 - 1)
        };
        let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(n + 1);
        simplex.push((best_x.clone(), best_f));
        for i in 0..n {
            let mut x = best_x.clone();
            x[i] += step[i] * scale;
            let fx = eval(&x, &mut evals);
            simplex.push((x, fx));
        }
        let start = evals;
        while evals - start < max_evals {
            simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
            let (fb, fw) = (simplex[0].1, simplex[n].1);
            let diam = simplex[1..]
                .iter()
                .map(|(x, _)| {
                    x.iter()
                        .zip(&simplex[0].0)
                        .map(|(a, b)| (a - b).abs())
                        .fold(0.0, f64::max)
                })
                .fold(0.0, f64::max);
            if (fw - fb).abs() <= ftol * (fb.abs() + 1e-30) && diam <= xtol {
                break;
            }
            let centroid: Vec<f64> = (0..n)
                .map(|j| simplex[..n].iter().map(|(x, _)| x[j]).sum::<f64>() / n as f64)
                .collect();
            let along = |t: f64| -> Vec<f64> {
                centroid
                    .iter()
                    .zip(&simplex[n].0)
                    .map(|(c, w)| c + t * (c - w))
                    .collect()
            };
            let xr = along(1.0);
            let fr = eval(&xr, &mut evals);
            if fr < simplex[0].1 {
                let xe = along(2.0);
                let fe = eval(&xe, &mut evals);
                simplex[n] = if fe < fr { (xe, fe) } else { (xr, fr) };
            } else if fr < simplex[n - 1].1 {
                simplex[n] = (xr, fr);
            } else {
                let (xc, fc) = if fr < fw {
                    let xc = along(0.5);
                    let fc = eval(&xc, &mut evals);
                    (xc, fc)
                } else {
                    let xc = along(-0.5);
                    let fc = eval(&xc, &mut evals);
                    (xc, fc)
                };
                if fc < fr.min(fw) {
                    simplex[n] = (xc, fc);
                } else {
                    let x0 = simplex[0].0.clone();
                    for v in simplex.iter_mut().skip(1) {
                        let xs: Vec<f64> = x0
                            .iter()
                            .zip(&v.0)
                            .map(|(a, b)| a + 0.5 * (b - a))
                            .collect();
                        let fs = eval(&xs, &mut evals);
                        *v = (xs, fs);
                    }
                }
            }
        }
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        if simplex[0].1 < best_f {
            best_f = simplex[0].1;
            best_x = simplex[0].0.clone();
        }
    }
    Minimum {
        x: best_x,
        f: best_f,
        evaluations: evals,
    }
}
