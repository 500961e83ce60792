//! Steps 4–7 per candidate order: Γ from the weighted SVDs, the singular-value order rules
//! (Bauer's SVC and the largest gap) and the fit of one order.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::linalg::{dot, lstsq, tall_lstsq, thin_svd, Svd};
use super::options::{N4sidOptions, Weighting};
use super::output_error::{d_t_ratio, oe_regressors};
use super::stability::{enforce_stability, fmt_pole};
use crate::error::{Error, Result};
use crate::lti::eigenvalues;
use faer::Mat;

/// A largest singular-value gap below this ratio is not "clear": the order is then chosen by
/// BIC on the output-error fits of the candidate orders.
pub(super) const CLEAR_GAP: f64 = 10.0;

/// The SVD results from which Γ is formed for any order.
pub(super) struct Subspace<'a> {
    pub(super) weighting: Weighting,
    pub(super) moesp: &'a Svd,
    pub(super) m_svd: &'a Svd,
    pub(super) cc_svd: &'a Svd,
    pub(super) rank_m: usize,
    pub(super) yf: usize,
    pub(super) p: usize,
}

impl Subspace<'_> {
    /// Extended observability matrix Γ (i·p × n) for order n.
    fn gamma(&self, n: usize) -> Result<Mat<f64>> {
        Ok(match self.weighting {
            Weighting::Moesp => Mat::from_fn(self.yf, n, |i, j| {
                self.moesp.u[(i, j)] * self.moesp.s[j].sqrt()
            }),
            Weighting::Cva => {
                // Γ = U_M Σ_M P_n S_n^½ (P: left singular vectors of G^T).
                if n > self.rank_m {
                    return Err(Error::Numerical(format!(
                        "CVA: order {n} exceeds the rank {} of the future-output projection",
                        self.rank_m
                    )));
                }
                let um_s = Mat::from_fn(self.yf, self.rank_m, |i, j| {
                    self.m_svd.u[(i, j)] * self.m_svd.s[j]
                });
                let pn = Mat::from_fn(self.rank_m, n, |i, j| {
                    self.cc_svd.u[(i, j)] * self.cc_svd.s[j].sqrt()
                });
                &um_s * &pn
            }
        })
    }
}

/// A model of one order in scaled units, with its output-error residual statistics.
pub(super) struct OrderFit {
    pub(super) n: usize,
    pub(super) a: Mat<f64>,
    pub(super) b: Mat<f64>,
    pub(super) c: Mat<f64>,
    pub(super) d: Mat<f64>,
    pub(super) x0: Vec<f64>,
    pub(super) gamma: Mat<f64>,
    /// ln det of the output-error residual covariance (scaled units).
    pub(super) resid_logdet: f64,
    pub(super) notes: Vec<String>,
    /// D was dropped by the significance test.
    pub(super) d_fixed_by_test: bool,
    pub(super) stability_enforced: bool,
}

/// Steps 5–7 of the module docs for order n: A, C by shift invariance, stability handling,
/// then B, D, x0 by output-error least squares.
pub(super) fn fit_order(
    n: usize,
    sub: &Subspace<'_>,
    us: &[Vec<f64>],
    ys: &[Vec<f64>],
    opts: &N4sidOptions,
) -> Result<OrderFit> {
    let mut notes = Vec::new();
    let gamma = sub.gamma(n)?;
    // 5. A, C.
    let (a_s, c_s) = shift_invariance(&gamma, n, sub.p, sub.yf, &mut notes)?;
    // 6. Stability.
    let stable = stability_step(a_s, opts.stability_margin, &mut notes)?;
    // 7. B, D, x0 by output-error least squares.
    let oe = output_error_fit(&stable, &c_s, us, ys, opts, &mut notes)?;
    Ok(OrderFit {
        n,
        a: stable.a,
        b: oe.b,
        c: c_s,
        d: oe.d,
        x0: oe.x0,
        gamma,
        resid_logdet: oe.resid_logdet,
        notes,
        stability_enforced: stable.enforced,
        d_fixed_by_test: opts.estimate_d && !oe.with_d,
    })
}

/// Step 5: C = Γ[0..p] and A by least squares from Γ_up·A = Γ_down, refused when Γ_up is too
/// ill-conditioned (noted when it is poorly conditioned).
fn shift_invariance(
    gamma: &Mat<f64>,
    n: usize,
    p: usize,
    yf: usize,
    notes: &mut Vec<String>,
) -> Result<(Mat<f64>, Mat<f64>)> {
    let c_s = gamma.as_ref().submatrix(0, 0, p, n).to_owned();
    let g_up = gamma.as_ref().submatrix(0, 0, yf - p, n);
    let g_dn = gamma.as_ref().submatrix(p, 0, yf - p, n);
    let g_up_sv = g_up
        .singular_values()
        .map_err(|e| Error::Numerical(format!("SVD of Γ failed: {e:?}")))?;
    let cond_up = g_up_sv[0] / g_up_sv[n - 1];
    if !(cond_up < 1e10) {
        return Err(Error::Numerical(format!(
            "ill-conditioned fit: the shifted observability matrix has condition {cond_up:.1e} \
             for order {n}; choose a lower order"
        )));
    }
    if cond_up > 1e6 {
        notes.push(format!(
            "the shifted observability matrix is ill-conditioned (condition {cond_up:.1e}); A \
             is poorly determined at order {n}"
        ));
    }
    let a_s = lstsq(g_up, g_dn, "shift invariance Γ_up·A = Γ_down")?;
    Ok((a_s, c_s))
}

/// A after step 6, with the spectral radius of the A it came from.
struct Stable {
    a: Mat<f64>,
    /// Spectral radius before any enforcement.
    rho: f64,
    /// The margin moved poles.
    enforced: bool,
}

/// Step 6: with a margin, poles moved inside it (each change noted); without one, unstable
/// poles noted.
fn stability_step(a_s: Mat<f64>, margin: Option<f64>, notes: &mut Vec<String>) -> Result<Stable> {
    let poles = eigenvalues(a_s.as_ref())?;
    let rho = poles.iter().map(|z| z.norm()).fold(0.0, f64::max);
    if let Some(mg) = margin {
        let (a_new, changes) = enforce_stability(&a_s, mg)?;
        if !changes.is_empty() {
            for ch in changes {
                notes.push(format!("stability enforced (margin {mg}): {ch}"));
            }
            return Ok(Stable {
                a: a_new,
                rho,
                enforced: true,
            });
        }
    } else if rho >= 1.0 {
        let bad: Vec<String> = poles
            .iter()
            .filter(|z| z.norm() >= 1.0 && z.im >= 0.0)
            .map(|&z| fmt_pole(z))
            .collect();
        notes.push(format!(
            "identified model is unstable: pole(s) {}; set a stability margin to enforce \
             stability",
            bad.join(", ")
        ));
    }
    Ok(Stable {
        a: a_s,
        rho,
        enforced: false,
    })
}

/// B, D, x0 of step 7 and the residual statistic of the fit.
struct OutputErrorFit {
    b: Mat<f64>,
    d: Mat<f64>,
    x0: Vec<f64>,
    /// D was estimated (not fixed to zero, by the options or the test).
    with_d: bool,
    /// ln det of the residual covariance.
    resid_logdet: f64,
}

/// Step 7: B, D and x0 by output-error least squares for the given A, C; with the
/// significance test, D fixed to zero (and noted) when every entry is within
/// `opts.d_significance` standard errors of zero.
fn output_error_fit(
    stable: &Stable,
    c_s: &Mat<f64>,
    us: &[Vec<f64>],
    ys: &[Vec<f64>],
    opts: &N4sidOptions,
    notes: &mut Vec<String>,
) -> Result<OutputErrorFit> {
    let (a_s, rho) = (&stable.a, stable.rho);
    let (n, p, m) = (a_s.nrows(), c_s.nrows(), us.len());
    let len = us[0].len();
    // The outputs stacked (one output: the channel itself, not a copy).
    let ybig: std::borrow::Cow<'_, [f64]> = match ys {
        [y] => std::borrow::Cow::Borrowed(y.as_slice()),
        _ => std::borrow::Cow::Owned(ys.iter().flat_map(|y| y.iter().copied()).collect()),
    };
    // θ, the output-error residual y − Φθ and, when D is estimated and tested, its largest
    // |D|/SE; for D estimated or fixed to zero. The least squares runs on the R factor of
    // [Φ y], folded in row blocks (the regressors are tall: len·p rows, a few columns).
    let solve = |with_d: bool| -> Result<(Mat<f64>, Vec<f64>, Option<f64>)> {
        // With one output the D regressors are the input channels themselves: used in place
        // instead of copied into the buffer (the same columns, in the same order).
        let d_in_place = with_d && p == 1;
        let (buf, rows, cols) =
            oe_regressors(a_s, c_s, us, len, opts.estimate_x0, with_d && !d_in_place);
        let mut columns: Vec<&[f64]> = if rows == 0 {
            Vec::new()
        } else {
            buf.chunks_exact(rows).take(cols).collect()
        };
        if d_in_place {
            columns.extend(us.iter().map(Vec::as_slice));
        }
        let (theta, r11) = tall_lstsq(&columns, &ybig, "B/D least squares").map_err(|e| {
            if rho >= 1.0 && opts.stability_margin.is_none() {
                Error::Numerical(format!(
                    "unstable fit (spectral radius {rho:.6}): {e}; set a stability margin"
                ))
            } else {
                e
            }
        })?;
        let mut resid = ybig.to_vec();
        for (k, col) in columns.iter().enumerate() {
            let th = theta[(k, 0)];
            resid
                .iter_mut()
                .zip(col.iter())
                .for_each(|(r, v)| *r -= th * v);
        }
        let t_ratio = match opts.d_significance {
            Some(_) if with_d => d_t_ratio(rows, r11.as_ref(), &resid, theta.as_ref(), p * m)?,
            _ => None,
        };
        Ok((theta, resid, t_ratio))
    };
    let (mut theta, mut resid, t_ratio) = solve(opts.estimate_d)?;
    let mut with_d = opts.estimate_d;
    if let (Some(k), Some(worst)) = (opts.d_significance, t_ratio) {
        if worst <= k {
            (theta, resid, _) = solve(false)?;
            with_d = false;
            notes.push(format!(
                "feedthrough D fixed to zero: every entry lies within {k} standard errors \
                 of zero (largest |D|/SE = {worst:.2})"
            ));
        }
    }
    let (x0, b, d) = unpack_theta(&theta, n, m, p, opts.estimate_x0, with_d);
    Ok(OutputErrorFit {
        b,
        d,
        x0,
        with_d,
        resid_logdet: resid_logdet(&resid, p, len),
    })
}

/// θ = [x0; vec(B); vec(D)] (x0 and D only when estimated; column-major blocks) → x0, B, D.
fn unpack_theta(
    theta: &Mat<f64>,
    n: usize,
    m: usize,
    p: usize,
    with_x0: bool,
    with_d: bool,
) -> (Vec<f64>, Mat<f64>, Mat<f64>) {
    let mut idx = 0;
    let x0: Vec<f64> = if with_x0 {
        idx = n;
        (0..n).map(|i| theta[(i, 0)]).collect()
    } else {
        vec![0.0; n]
    };
    let mut b_s = Mat::<f64>::zeros(n, m);
    for j in 0..m {
        for i in 0..n {
            b_s[(i, j)] = theta[(idx + j * n + i, 0)];
        }
    }
    idx += n * m;
    let mut d_s = Mat::<f64>::zeros(p, m);
    if with_d {
        for j in 0..m {
            for i in 0..p {
                d_s[(i, j)] = theta[(idx + j * p + i, 0)];
            }
        }
    }
    (x0, b_s, d_s)
}

/// ln det of the residual covariance (p outputs of `len` samples each, stacked).
fn resid_logdet(resid: &[f64], p: usize, len: usize) -> f64 {
    let sigma = Mat::from_fn(p, p, |i, j| {
        dot(
            &resid[i * len..(i + 1) * len],
            &resid[j * len..(j + 1) * len],
        ) / len as f64
    });
    let lu = sigma.partial_piv_lu();
    (0..p)
        .map(|i| lu.U()[(i, i)].abs().max(f64::MIN_POSITIVE).ln())
        .sum()
}

/// Outcome of the singular-value rules.
pub(super) struct OrderRule {
    /// Largest-gap order among n_lo..=n_svc.
    pub(super) order: usize,
    /// Its gap σ_n/σ_{n+1}.
    pub(super) gap: f64,
    /// SVC minimiser.
    pub(super) n_svc: usize,
    pub(super) reason: String,
    pub(super) svc: Vec<(usize, f64)>,
}

/// Order rule (documented in the module docs): Bauer's SVC on the canonical correlations gives
/// the largest statistically supported order n_svc; the chosen order is the largest log-gap
/// σ_n/σ_{n+1} of the weighted singular values among n_lo..=n_svc. Returns (order, reason, SVC
/// values).
pub(super) fn select_order(
    sv: &[f64],
    cc: &[f64],
    n_lo: usize,
    n_hi: usize,
    jcols: usize,
    m: usize,
    p: usize,
) -> OrderRule {
    let jf = jcols as f64;
    let pen = jf.ln() / jf;
    let d = |n: usize| (n * (2 * p + m)) as f64;
    let crit: Vec<(usize, f64)> = (n_lo..=n_hi)
        .map(|n| {
            let next = cc.get(n).copied().unwrap_or(0.0);
            (n, next * next + d(n) * pen)
        })
        .collect();
    let (n_svc, _) = crit
        .iter()
        .copied()
        .fold((n_lo, f64::INFINITY), |best, (n, v)| {
            if v < best.1 {
                (n, v)
            } else {
                best
            }
        });
    // Singular values below round-off level are treated as equal (no gap among them).
    let tiny = sv[0] * 1e-14;
    let gap = |n: usize| -> f64 {
        let a = sv[n - 1].max(tiny);
        let b = sv.get(n).copied().unwrap_or(0.0).max(tiny);
        a / b
    };
    // Largest gap; on a tie the smaller order.
    let best_gap =
        |hi: usize| (n_lo..=hi).fold(n_lo, |best, n| if gap(n) > gap(best) { n } else { best });
    let n = best_gap(n_svc);
    let mut reason = format!(
        "order {n}: the largest singular-value gap σ{n}/σ{} = {:.3e} among the orders \
         {n_lo}..={n_svc} supported by Bauer's SVC(n) = ρ²(n+1) + n(2p+m)·ln(J)/J on the \
         canonical correlations ρ (minimal at n = {n_svc}, J = {jcols}; range searched \
         {n_lo}..={n_hi})",
        n + 1,
        gap(n)
    );
    if n < n_svc {
        reason.push_str(&format!(
            "; σ{}..σ{n_svc} ({:.3e}..{:.3e}) are statistically supported but weaker than the \
             dominant dynamics: fix the order to {n_svc} to include them",
            n + 1,
            sv[n],
            sv[n_svc - 1]
        ));
    }
    let n_all = best_gap(n_hi);
    if n_all > n_svc {
        reason.push_str(&format!(
            "; a larger gap σ{n_all}/σ{} = {:.3e} lies beyond what SVC supports",
            n_all + 1,
            gap(n_all)
        ));
    }
    OrderRule {
        order: n,
        gap: gap(n),
        n_svc,
        reason,
        svc: crit,
    }
}

/// The SVDs of step 3 for the LQ factor `l` (k block rows, m inputs, p outputs): MOESP (of
/// L₃₂), of M = [L₃₂ L₃₃], and of the canonical correlations (the SVs of V_M1ᵀ).
pub(super) struct WeightedSvds {
    /// SVD of L₃₂.
    pub(super) moesp: Svd,
    /// SVD of [L₃₂ L₃₃].
    pub(super) m_svd: Svd,
    /// SVD whose singular values are the canonical correlations.
    pub(super) cc_svd: Svd,
    /// Numerical rank of M.
    pub(super) rank_m: usize,
    /// Canonical correlations clipped to [0, 1], padded with zeros to k·p.
    pub(super) cc: Vec<f64>,
}

/// Step 3 of the module docs: the weighted SVDs of the LQ factor.
pub(super) fn weighted_svds(l: &Mat<f64>, k: usize, m: usize, p: usize) -> Result<WeightedSvds> {
    let q = m + p;
    let (uf, wp, yf) = (k * m, k * q, k * p);
    let l32 = l.as_ref().submatrix(uf + wp, uf, yf, wp);
    let l33 = l.as_ref().submatrix(uf + wp, uf + wp, yf, yf);
    let moesp = thin_svd(l32, "L32")?;
    // CVA: SVD of M = [L32 L33] = U_M Σ_M V_Mᵀ; canonical correlations = SVs of V_M1ᵀ.
    let mfull = Mat::from_fn(yf, wp + yf, |i, j| {
        if j < wp {
            l32[(i, j)]
        } else {
            l33[(i, j - wp)]
        }
    });
    let m_svd = thin_svd(mfull.as_ref(), "[L32 L33]")?;
    let rank_m = m_svd
        .s
        .iter()
        .take_while(|&&s| s > 1e-7 * m_svd.s[0])
        .count()
        .max(1);
    let g_t = Mat::from_fn(rank_m, wp, |i, j| m_svd.v[(j, i)]);
    let cc_svd = thin_svd(g_t.as_ref(), "canonical correlations")?;
    let mut cc: Vec<f64> = cc_svd.s.iter().map(|s| s.min(1.0)).collect();
    cc.resize(yf, 0.0);
    Ok(WeightedSvds {
        moesp,
        m_svd,
        cc_svd,
        rank_m,
        cc,
    })
}

/// What the order choice of one identification problem works from.
pub(super) struct OrderSearch<'a> {
    /// The SVDs from which Γ is formed.
    pub(super) sub: Subspace<'a>,
    /// Weighted singular values (MOESP: of L₃₂, CVA: the canonical correlations).
    pub(super) sv: &'a [f64],
    /// Canonical correlations.
    pub(super) cc: &'a [f64],
    /// Smallest order considered.
    pub(super) lo: usize,
    /// Largest order considered.
    pub(super) hi: usize,
    /// The order fixed by the caller, if any.
    pub(super) fixed: Option<usize>,
    /// Column count J of the block Hankel matrix.
    pub(super) jcols: usize,
}

/// The chosen order's fit with the evidence for it.
pub(super) struct OrderChoice {
    /// The fit of the chosen order.
    pub(super) fit: OrderFit,
    /// Why this order (human-readable).
    pub(super) reason: String,
    /// (order, SVC) pairs (empty for a fixed order).
    pub(super) svc: Vec<(usize, f64)>,
    /// (order, BIC) pairs when no singular-value gap was clear (empty otherwise).
    pub(super) bic: Vec<(usize, f64)>,
    /// The warning when the order was chosen by BIC.
    pub(super) warning: Option<String>,
}

/// Step 4 of the module docs: the order fixed by the caller, the largest clear singular-value
/// gap among the SVC-supported orders, or else the BIC minimiser over those orders' fits.
/// `us`/`ys` are the scaled channels.
pub(super) fn choose_order(
    search: &OrderSearch<'_>,
    us: &[Vec<f64>],
    ys: &[Vec<f64>],
    opts: &N4sidOptions,
) -> Result<OrderChoice> {
    let (m, p, len) = (us.len(), ys.len(), us[0].len());
    let (n_lo, n_hi, jcols, sub) = (search.lo, search.hi, search.jcols, &search.sub);
    if let Some(n) = search.fixed {
        let fit = fit_order(n, sub, us, ys, opts)?;
        return Ok(OrderChoice {
            fit,
            reason: format!("order {n} fixed by the caller"),
            svc: Vec::new(),
            bic: Vec::new(),
            warning: None,
        });
    }
    let sel = select_order(search.sv, search.cc, n_lo, n_hi, jcols, m, p);
    if sel.gap >= CLEAR_GAP {
        let fit = fit_order(sel.order, sub, us, ys, opts)?;
        return Ok(OrderChoice {
            fit,
            reason: sel.reason,
            svc: sel.svc,
            bic: Vec::new(),
            warning: None,
        });
    }
    // No clear gap: compare the candidate orders by BIC on their output-error fits.
    let mut order_bic = Vec::new();
    let mut best: Option<(f64, OrderFit)> = None;
    let mut failures = Vec::new();
    for n in n_lo..=sel.n_svc {
        match fit_order(n, sub, us, ys, opts) {
            Ok(f) => {
                let k = n * (m + p) + if opts.estimate_d { p * m } else { 0 };
                let bic = len as f64 * f.resid_logdet + k as f64 * (len as f64).ln();
                order_bic.push((n, bic));
                if best.as_ref().is_none_or(|(b, _)| bic < *b) {
                    best = Some((bic, f));
                }
            }
            Err(e) => failures.push(format!("n = {n}: {e}")),
        }
    }
    let Some((_, fit)) = best else {
        return Err(Error::Numerical(format!(
            "no candidate order could be fitted: {}",
            failures.join("; ")
        )));
    };
    let n = fit.n;
    let warning = format!(
        "no clear singular-value gap (largest σn/σn+1 = {:.2} < {CLEAR_GAP} among the \
         orders {n_lo}..={} supported by SVC): order {n} chosen by BIC on the \
         output-error fit; the data may not support a low-order model",
        sel.gap, sel.n_svc
    );
    let reason = format!(
        "order {n}: minimises BIC(n) = N·ln det Σ̂(n) + (n(m+p) + pm)·ln N of the \
         output-error residual over {n_lo}..={} (the orders supported by Bauer's SVC on \
         the canonical correlations, J = {jcols}); no clear singular-value gap (largest \
         σ{}/σ{} = {:.3})",
        sel.n_svc,
        sel.order,
        sel.order + 1,
        sel.gap
    );
    Ok(OrderChoice {
        fit,
        reason,
        svc: sel.svc,
        bic: order_bic,
        warning: Some(warning),
    })
}
