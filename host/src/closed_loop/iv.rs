//! Stage 2 of the two-stage method, refined: an output-error (OE) estimate of the SISO transfer
//! function G = B/F from the reference-driven input û to y.
//!
//! Why not N4SID alone: with coloured output noise (the loop's S·v) PO-MOESP at the plant's
//! order estimates a reduced model of plant and noise together and is biased (an integrator
//! pole at 0.985 instead of 1 on the test loop). The OE criterion Σ (y − B/F·û − c)² is
//! consistent for any noise uncorrelated with û, whatever its colour (Ljung 1999, §8.3: the
//! noise model is fixed to 1, so only G must be right), and û is uncorrelated with the noise by
//! construction. c absorbs the constant left by the initial state (an integrator's initial
//! position). Minimised by Levenberg–Marquardt on θ = (f₁..f_n, b₁..b_n[, b₀], c), started from
//! the N4SID model, with the exact gradient: ∂ŷ/∂b_k = q⁻ᵏ û / F, ∂ŷ/∂f_k = −q⁻ᵏ ŷ / F. A step
//! whose F simulates to non-finite values is rejected like one that raises the cost.
use crate::error::{Error, Result};
use crate::lti::{StateSpace, TransferFunction};
use faer::Mat;

/// Largest number of Levenberg–Marquardt iterations.
const MAX_ITER: usize = 100;

/// y_out(t) = x(t) − Σ_k f_k y_out(t−k): filtering by 1/F (F monic, `f` = f₁..f_n).
fn filter(f: &[f64], x: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; x.len()];
    for t in 0..x.len() {
        let mut v = x[t];
        for (k, fk) in f.iter().enumerate() {
            if t > k {
                v -= fk * out[t - 1 - k];
            }
        }
        out[t] = v;
    }
    out
}

/// ŷ = B/F û + c for θ = (f, b, c); b₀ on û(t) when `ft`.
fn simulate(theta: &[f64], n: usize, ft: bool, u: &[f64]) -> Vec<f64> {
    let nb = n + usize::from(ft);
    let (f, b, c) = (&theta[..n], &theta[n..n + nb], theta[n + nb]);
    let shift = usize::from(!ft);
    let bu: Vec<f64> = (0..u.len())
        .map(|t| {
            b.iter()
                .enumerate()
                .filter(|(k, _)| t >= k + shift)
                .map(|(k, bk)| bk * u[t - k - shift])
                .sum()
        })
        .collect();
    filter(f, &bu).into_iter().map(|v| v + c).collect()
}

fn cost(theta: &[f64], n: usize, ft: bool, u: &[f64], y: &[f64]) -> (f64, Vec<f64>) {
    let yh = simulate(theta, n, ft, u);
    let e: Vec<f64> = y.iter().zip(&yh).map(|(a, b)| a - b).collect();
    let v = e.iter().map(|x| x * x).sum::<f64>();
    (if v.is_finite() { v } else { f64::INFINITY }, yh)
}

/// One Levenberg–Marquardt step on the normal equations `jtj`·δ = `jte` (JᵀJ and Jᵀe): tries δ with the diagonal damped by `lambda` (Marquardt's scaling),
/// up to 20 times, multiplying `lambda` by 10 after a singular or non-improving trial. The
/// first trial that lowers the cost `v` is taken (θ, `v`, the simulation `yh` updated and
/// `lambda` divided by 10, at least 1e-12). `eval` gives (cost, simulation) of a θ. Returns
/// whether the accepted step lowered the cost by more than 1e-12 relative (false also when no
/// trial improved: the caller stops).
fn damped_step<S>(
    jtj: &Mat<f64>,
    jte: &Mat<f64>,
    theta: &mut Vec<f64>,
    v: &mut f64,
    yh: &mut S,
    lambda: &mut f64,
    eval: impl Fn(&[f64]) -> (f64, S),
) -> bool {
    let p = theta.len();
    for _ in 0..20 {
        let mut m = jtj.clone();
        for a in 0..p {
            m[(a, a)] += *lambda * jtj[(a, a)].max(f64::MIN_POSITIVE);
        }
        let Ok(step) = crate::lti::dense::solve_square(m.as_ref(), jte.as_ref(), "OE step") else {
            *lambda *= 10.0;
            continue;
        };
        let trial: Vec<f64> = (0..p).map(|k| theta[k] + step[(k, 0)]).collect();
        let (vt, yt) = eval(&trial);
        if vt < *v {
            let rel = (*v - vt) / *v;
            *theta = trial;
            *v = vt;
            *yh = yt;
            *lambda = (*lambda / 10.0).max(1e-12);
            return rel > 1e-12;
        }
        *lambda *= 10.0;
    }
    false
}

/// The OE estimate of order `n` (strictly proper; with `feedthrough` also b₀ on û(t)) from
/// `uhat` to `y` (mean-removed, equal length), started from `start` (discrete SISO, order n).
pub(super) fn refine(
    start: &StateSpace,
    uhat: &[f64],
    y: &[f64],
    n: usize,
    feedthrough: bool,
) -> Result<StateSpace> {
    let ts = start.ts;
    let tf = start.to_transfer_function()?;
    // Monic denominator of degree n and the numerator aligned to it.
    let lead = tf.den[0];
    let f0: Vec<f64> = tf.den[1..].iter().map(|v| v / lead).collect();
    if f0.len() != n {
        return Err(Error::Numerical(format!(
            "closed loop, stage 2: start model of order {} for an order-{n} refinement",
            f0.len()
        )));
    }
    let nb = n + usize::from(feedthrough);
    let mut b0 = vec![0.0; nb];
    // num has degree <= n; align its coefficients to z^n .. z^0, then take b₀ (z^n) if wanted.
    let pad = n + 1 - tf.num.len();
    let full: Vec<f64> = (0..=n)
        .map(|k| if k < pad { 0.0 } else { tf.num[k - pad] / lead })
        .collect();
    let skip = usize::from(!feedthrough);
    b0.copy_from_slice(&full[skip..]);
    let mut theta: Vec<f64> = f0;
    theta.extend(b0);
    theta.push(0.0);
    let p = theta.len();
    let (mut v, mut yh) = cost(&theta, n, feedthrough, uhat, y);
    if !v.is_finite() {
        return Err(Error::Numerical(
            "closed loop, stage 2: the N4SID start does not simulate (unstable)".into(),
        ));
    }
    let mut lambda = 1e-3;
    for _ in 0..MAX_ITER {
        // Gradient columns of ŷ.
        let f = &theta[..n];
        let shift = usize::from(!feedthrough);
        let uf = filter(f, uhat);
        let c = theta[p - 1];
        let yf = filter(f, &yh.iter().map(|v| v - c).collect::<Vec<_>>());
        let col = |k: usize, t: usize| -> f64 {
            if k < n {
                if t > k {
                    -yf[t - 1 - k]
                } else {
                    0.0
                }
            } else if k < n + nb {
                let lag = k - n + shift;
                if t >= lag {
                    uf[t - lag]
                } else {
                    0.0
                }
            } else {
                1.0
            }
        };
        let mut jtj = Mat::<f64>::zeros(p, p);
        let mut jte = Mat::<f64>::zeros(p, 1);
        for t in 0..y.len() {
            let e = y[t] - yh[t];
            let g: Vec<f64> = (0..p).map(|k| col(k, t)).collect();
            for a in 0..p {
                jte[(a, 0)] += g[a] * e;
                for b in a..p {
                    jtj[(a, b)] += g[a] * g[b];
                }
            }
        }
        for a in 0..p {
            for b in 0..a {
                jtj[(a, b)] = jtj[(b, a)];
            }
        }
        let improved = damped_step(&jtj, &jte, &mut theta, &mut v, &mut yh, &mut lambda, |t| {
            cost(t, n, feedthrough, uhat, y)
        });
        if !improved {
            break;
        }
    }
    let mut den = vec![1.0];
    den.extend_from_slice(&theta[..n]);
    let num = theta[n..n + nb].to_vec();
    TransferFunction::new(num, den, ts)?.to_state_space()
}

/// One output channel of [`refine_common`]: the start numerator aligned to z^n .. z^0 (monic
/// denominator), the measured signal and whether it has feedthrough (b₀).
pub(super) struct Channel<'a> {
    pub num: Vec<f64>,
    pub y: &'a [f64],
    pub feedthrough: bool,
}

/// Output-error fit of several channels B_i/F driven by the same input `r` with one common
/// monic denominator F (started from `f0` = f₁..f_n and each channel's numerator): minimises
/// Σ_i Σ_t (y_i − B_i/F·r − c_i)² by Levenberg–Marquardt with the exact gradient, as
/// [`refine`]. Returns (F, [B_i]) as coefficient vectors in descending powers of z (B_i padded
/// to degree n).
pub(super) fn refine_common(
    f0: &[f64],
    channels: &[Channel<'_>],
    r: &[f64],
) -> Result<(Vec<f64>, Vec<Vec<f64>>)> {
    let n = f0.len();
    // Parameter layout: f (n), then per channel its b (n or n+1) and c.
    let mut theta: Vec<f64> = f0.to_vec();
    let mut offs = Vec::new();
    for ch in channels {
        if ch.num.len() != n + 1 {
            return Err(Error::Numerical(format!(
                "closed loop, joint refinement: numerator of {} coefficients for order {n}",
                ch.num.len()
            )));
        }
        offs.push(theta.len());
        let skip = usize::from(!ch.feedthrough);
        theta.extend_from_slice(&ch.num[skip..]);
        theta.push(0.0);
    }
    let p = theta.len();
    let sim = |th: &[f64]| -> Vec<Vec<f64>> {
        channels
            .iter()
            .zip(&offs)
            .map(|(ch, &o)| {
                let nb = n + usize::from(ch.feedthrough);
                let mut t = th[..n].to_vec();
                t.extend_from_slice(&th[o..o + nb + 1]);
                simulate(&t, n, ch.feedthrough, r)
            })
            .collect()
    };
    let total = |yh: &[Vec<f64>]| -> f64 {
        let v: f64 = channels
            .iter()
            .zip(yh)
            .map(|(ch, h)| {
                ch.y.iter()
                    .zip(h)
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum::<f64>()
            })
            .sum();
        if v.is_finite() {
            v
        } else {
            f64::INFINITY
        }
    };
    let mut yh = sim(&theta);
    let mut v = total(&yh);
    if !v.is_finite() {
        return Err(Error::Numerical(
            "closed loop, joint refinement: the N4SID start does not simulate".into(),
        ));
    }
    let mut lambda = 1e-3;
    for _ in 0..MAX_ITER {
        let f = &theta[..n];
        let rf = filter(f, r);
        let mut jtj = Mat::<f64>::zeros(p, p);
        let mut jte = Mat::<f64>::zeros(p, 1);
        for ((ch, &o), h) in channels.iter().zip(&offs).zip(&yh) {
            let nb = n + usize::from(ch.feedthrough);
            let c = theta[o + nb];
            let hf = filter(f, &h.iter().map(|v| v - c).collect::<Vec<_>>());
            let shift = usize::from(!ch.feedthrough);
            // Non-zero gradient entries of this channel: f (0..n), its b and c.
            let idx: Vec<usize> = (0..n).chain(o..o + nb + 1).collect();
            let mut g = vec![0.0; idx.len()];
            for t in 0..r.len() {
                for k in 0..n {
                    g[k] = if t > k { -hf[t - 1 - k] } else { 0.0 };
                }
                for k in 0..nb {
                    let lag = k + shift;
                    g[n + k] = if t >= lag { rf[t - lag] } else { 0.0 };
                }
                g[n + nb] = 1.0;
                let e = ch.y[t] - h[t];
                for (a, &ia) in idx.iter().enumerate() {
                    jte[(ia, 0)] += g[a] * e;
                    for (b, &ib) in idx.iter().enumerate() {
                        jtj[(ia, ib)] += g[a] * g[b];
                    }
                }
            }
        }
        let improved = damped_step(&jtj, &jte, &mut theta, &mut v, &mut yh, &mut lambda, |t| {
            let yt = sim(t);
            (total(&yt), yt)
        });
        if !improved {
            break;
        }
    }
    let mut den = vec![1.0];
    den.extend_from_slice(&theta[..n]);
    let nums = channels
        .iter()
        .zip(&offs)
        .map(|(ch, &o)| {
            let mut b = if ch.feedthrough { vec![] } else { vec![0.0] };
            b.extend_from_slice(&theta[o..o + n + usize::from(ch.feedthrough)]);
            b
        })
        .collect();
    Ok((den, nums))
}
