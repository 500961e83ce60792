//! Step 8: noise model. Kalman gain from the oblique-projection states and the steady-state
//! filter Riccati equation solved by doubling.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::linalg::{dot, lstsq};
use super::order::OrderFit;
use crate::error::{Error, Result};
use crate::lti::eigenvalues;
use faer::linalg::solvers::Solve;
use faer::{Mat, MatRef, Side};

/// The innovation form's noise model (scaled units).
pub(super) struct Innovation {
    /// Kalman gain K, n×p.
    pub(super) gain: Mat<f64>,
    /// Innovation covariance, p×p.
    pub(super) cov: Mat<f64>,
}

/// Step 8 for the chosen fit (scaled units): the Kalman gain K and the innovation covariance
/// from the oblique-projection states (see the module docs), or the reason there are none
/// (past data rank deficient, no stabilising Riccati solution: [`kalman_filter_gain`]
/// refuses an A − KC that is not stable). `l` is the LQ factor, `fit` gives Γ, A, B, C, D,
/// `w` = [u; y] the scaled channels (m inputs), `k` the block rows.
pub(super) fn innovation_model(
    l: &Mat<f64>,
    fit: &OrderFit,
    w: &[Vec<f64>],
    k: usize,
    m: usize,
) -> Result<Innovation> {
    let (gamma, a, b, c, d) = (&fit.gamma, &fit.a, &fit.b, &fit.c, &fit.d);
    let p = w.len() - m;
    let q = m + p;
    let (uf, wp, yf) = (k * m, k * q, k * p);
    let n = a.nrows();
    let len = w[0].len();
    let l22 = l.as_ref().submatrix(uf, uf, wp, wp);
    let l32 = l.as_ref().submatrix(uf + wp, uf, yf, wp);
    let dmax = (0..wp).map(|i| l22[(i, i)].abs()).fold(0.0, f64::max);
    let dmin = (0..wp)
        .map(|i| l22[(i, i)].abs())
        .fold(f64::INFINITY, f64::min);
    if !(dmin > 1e-8 * dmax) {
        return Err(Error::Numerical(
            "past data are rank deficient (noise-free data?)".into(),
        ));
    }
    // X = L32 L22⁻¹  ⇔  L22ᵀ Xᵀ = L32ᵀ.
    let mut xt = l32.transpose().to_owned();
    faer::linalg::triangular_solve::solve_upper_triangular_in_place(
        l22.transpose(),
        xt.as_mut(),
        faer::Par::Seq,
    );
    let proj = xt.transpose().to_owned(); // yf × wp
                                          // Γ⁺ by least squares: F = Γ⁺·proj (n × wp).
    let f = lstsq(gamma.as_ref(), proj.as_ref(), "Γ⁺")?;
    // x̂(k + s) = F·w_p(s) for s in 0..count: F split per channel times that channel's
    // Hankel view (k × columns, element (j, s) = w[a][s + j]) — one GEMM per channel, on
    // blocks of STATE_BLOCK columns (a block overlaps the next by one column, x̂(t+1)), each
    // folded into the residual sums before the next is computed: the state sequence is never
    // stored whole (8 × 100k doubles on the peer log, 1,600 fresh pages), and each column is
    // the same GEMM of the same views as over the whole sequence.
    let count = len - k + 1;
    // The rows are padded with zero rows to a multiple of 8: the GEMM kernel works on whole
    // 8-row panels of the destination and of the left factor and computes on the padding
    // below row n as well, and the padding of a `Mat` is not initialised; freed integers left
    // there (line numbers, indices) read as subnormal numbers, each of which costs a microcode
    // assist: measured 170 ms instead of 10 ms for this product on the peer log.
    let rows8 = n.next_multiple_of(8);
    let fas: Vec<Mat<f64>> = (0..w.len())
        .map(|a_| {
            Mat::from_fn(rows8, k, |i, j| {
                let col = if a_ < m {
                    j * m + a_
                } else {
                    k * m + j * p + (a_ - m)
                };
                if i < n {
                    f[(i, col)]
                } else {
                    0.0
                }
            })
        })
        .collect();
    // Residuals for t = k .. len−2 (x̂(t+1) needed): e = y − C x̂ − D u, ŵ = x̂⁺ − A x̂ − B u,
    // accumulated into Σŵŵᵀ, Σŵeᵀ, Σeeᵀ without storing them.
    let nres = count - 1;
    let rm = |x: &Mat<f64>| -> Vec<f64> {
        (0..x.nrows() * x.ncols())
            .map(|k| x[(k / x.ncols(), k % x.ncols())])
            .collect()
    };
    let model = RowMajor {
        a: rm(a),
        b: rm(b),
        c: rm(c),
        d: rm(d),
        n,
        m,
        p,
    };
    let mut sums = ResidualSums {
        q: vec![0.0; n * n],
        s: vec![0.0; n * p],
        r: vec![0.0; p * p],
    };
    let mut states = Mat::<f64>::zeros(rows8, STATE_BLOCK.min(nres + 1));
    let mut s0 = 0;
    while s0 < nres {
        let cols = (nres - s0).min(STATE_BLOCK - 1) + 1;
        states.fill(0.0);
        for (fa, wa) in fas.iter().zip(w) {
            let hankel =
                MatRef::from_column_major_slice_with_stride(&wa[s0..s0 + cols + k - 1], k, cols, 1);
            faer::linalg::matmul::matmul(
                states.as_mut().subrows_mut(0, n).subcols_mut(0, cols),
                faer::Accum::Add,
                fa.as_ref().subrows(0, n),
                hankel,
                1.0,
                faer::Par::Seq,
            );
        }
        let block = StateBlock {
            states: &states,
            s0,
            count: cols - 1,
            w,
            k,
        };
        if !residual_sums_siso(&block, &model, &mut sums) {
            residual_sums(&block, &model, &mut sums);
        }
        s0 += cols - 1;
    }
    let mut qww = Mat::<f64>::zeros(n, n);
    let mut sww = Mat::<f64>::zeros(n, p);
    let mut see = Mat::<f64>::zeros(p, p);
    for i in 0..n {
        for j in 0..n {
            qww[(i, j)] = sums.q[i * n + j];
        }
        for j in 0..p {
            sww[(i, j)] = sums.s[i * p + j];
        }
    }
    for i in 0..p {
        for j in 0..p {
            see[(i, j)] = sums.r[i * p + j];
        }
    }
    let inv = 1.0 / nres as f64;
    let q = Mat::from_fn(n, n, |i, j| qww[(i, j)] * inv);
    let s = Mat::from_fn(n, p, |i, j| sww[(i, j)] * inv);
    let r = Mat::from_fn(p, p, |i, j| see[(i, j)] * inv);
    let kf = kalman_filter_gain(a.as_ref(), c.as_ref(), q.as_ref(), s.as_ref(), r.as_ref())?;
    Ok(Innovation {
        gain: kf.gain,
        cov: kf.innovation_cov,
    })
}

/// A, B, C, D in row-major vectors with the sizes n, m, p.
struct RowMajor {
    a: Vec<f64>,
    b: Vec<f64>,
    c: Vec<f64>,
    d: Vec<f64>,
    n: usize,
    m: usize,
    p: usize,
}

/// Σŵŵᵀ (n×n), Σŵeᵀ (n×p) and Σeeᵀ (p×p), row-major.
struct ResidualSums {
    q: Vec<f64>,
    s: Vec<f64>,
    r: Vec<f64>,
}

/// Columns of the state sequence: column c of `states` (its first n rows) is x̂(k + s0 + c),
/// for c in 0..=count (the residuals of s = s0..s0 + count need x̂ one step further).
struct StateBlock<'a> {
    states: &'a Mat<f64>,
    s0: usize,
    count: usize,
    /// The scaled channels [u; y] and the block rows k (x̂(k + s) pairs with time k + s).
    w: &'a [Vec<f64>],
    k: usize,
}

/// Columns per block of the state sequence in [`kalman_gain`] (8 padded rows: 128 KiB).
const STATE_BLOCK: usize = 2048;

/// Adds to `sums` the residual sums over the block of the state sequence `blk` and the
/// scaled channels `w` = [u; y]: for t = k + s, e = y(t) − C x̂ − D u(t) and
/// ŵ = x̂(t+1) − A x̂ − B u(t), each row product summed by [`small_dot`]; blocks folded in
/// the order of s give the sums of one pass over the whole sequence.
fn residual_sums(blk: &StateBlock<'_>, model: &RowMajor, sums: &mut ResidualSums) {
    let (n, m, p) = (model.n, model.m, model.p);
    let (ar, br, cr, dr) = (&model.a, &model.b, &model.c, &model.d);
    let (qacc, sacc, racc) = (&mut sums.q, &mut sums.s, &mut sums.r);
    let (states, w, k) = (blk.states, blk.w, blk.k);
    let mut e = vec![0.0; p];
    let mut wv = vec![0.0; n];
    let mut ut = vec![0.0; m];
    for s_ in 0..blk.count {
        let t = k + blk.s0 + s_;
        let xs = &states.col_as_slice(s_)[..n];
        let xs1 = &states.col_as_slice(s_ + 1)[..n];
        for (j, v) in ut.iter_mut().enumerate() {
            *v = w[j][t];
        }
        for i in 0..p {
            e[i] = w[m + i][t]
                - small_dot(&cr[i * n..(i + 1) * n], xs)
                - small_dot(&dr[i * m..(i + 1) * m], &ut);
        }
        for i in 0..n {
            wv[i] = xs1[i]
                - small_dot(&ar[i * n..(i + 1) * n], xs)
                - small_dot(&br[i * m..(i + 1) * m], &ut);
        }
        for i in 0..n {
            for j in 0..n {
                qacc[i * n + j] += wv[i] * wv[j];
            }
            for j in 0..p {
                sacc[i * p + j] += wv[i] * e[j];
            }
        }
        for i in 0..p {
            for j in 0..p {
                racc[i * p + j] += e[i] * e[j];
            }
        }
    }
}

/// [`residual_sums`] for a SISO model of order 1..=7, with the sizes fixed at compile time:
/// the same operations in the same order (so the same bits), without the loop overhead of
/// the general sizes. `false` (nothing added) for other sizes.
fn residual_sums_siso(blk: &StateBlock<'_>, model: &RowMajor, sums: &mut ResidualSums) -> bool {
    if (model.m, model.p) != (1, 1) || blk.w.len() != 2 {
        return false;
    }
    match model.n {
        1 => residual_sums_fixed::<1>(blk, model, sums),
        2 => residual_sums_fixed::<2>(blk, model, sums),
        3 => residual_sums_fixed::<3>(blk, model, sums),
        4 => residual_sums_fixed::<4>(blk, model, sums),
        5 => residual_sums_fixed::<5>(blk, model, sums),
        6 => residual_sums_fixed::<6>(blk, model, sums),
        7 => residual_sums_fixed::<7>(blk, model, sums),
        _ => false,
    }
}

/// [`residual_sums_siso`] for order `N` (below the 8 lanes of [`dot`], so every row product
/// is the in-order sum from 0.0 of [`small_dot`]).
fn residual_sums_fixed<const N: usize>(
    blk: &StateBlock<'_>,
    model: &RowMajor,
    sums: &mut ResidualSums,
) -> bool {
    let (Some((a, _)), Ok(b), Ok(c), &[d]) = (
        model.a.as_chunks::<N>().0.split_first_chunk::<N>(),
        <[f64; N]>::try_from(model.b.as_slice()),
        <[f64; N]>::try_from(model.c.as_slice()),
        model.d.as_slice(),
    ) else {
        return false;
    };
    let (states, s0, count, w, k) = (blk.states, blk.s0, blk.count, blk.w, blk.k);
    if states.nrows() < N
        || states.ncols() < count + 1
        || w[0].len() < k + s0 + count
        || sums.q.len() != N * N
        || sums.s.len() != N
        || sums.r.len() != 1
    {
        return false;
    }
    let (u, y) = (&w[0][k + s0..k + s0 + count], &w[1][k + s0..k + s0 + count]);
    let mut q: [[f64; N]; N] = std::array::from_fn(|i| std::array::from_fn(|j| sums.q[i * N + j]));
    let mut sv: [f64; N] = std::array::from_fn(|i| sums.s[i]);
    let mut r = sums.r[0];
    let col = |s_: usize| -> [f64; N] {
        <[f64; N]>::try_from(&states.col_as_slice(s_)[..N]).expect("N states per column")
    };
    let mut x1 = col(0);
    for (s_, (&ut, &yt)) in u.iter().zip(y).enumerate() {
        let x = x1;
        x1 = col(s_ + 1);
        let mut cx = 0.0;
        for j in 0..N {
            cx += c[j] * x[j];
        }
        let e = yt - cx - (0.0 + d * ut);
        let mut wv = [0.0; N];
        for i in 0..N {
            let mut ax = 0.0;
            for j in 0..N {
                ax += a[i][j] * x[j];
            }
            wv[i] = x1[i] - ax - (0.0 + b[i] * ut);
        }
        for i in 0..N {
            for j in 0..N {
                q[i][j] += wv[i] * wv[j];
            }
            sv[i] += wv[i] * e;
        }
        r += e * e;
    }
    sums.q = q.iter().flatten().copied().collect();
    sums.s = sv.to_vec();
    sums.r = vec![r];
    true
}

/// [`dot`] for the short vectors of the residual loop, inlined: [`dot`] sums vectors shorter
/// than its 8 lanes in order from 0.0, and so does this, so the result is the same to the bit;
/// longer vectors go to [`dot`].
#[inline(always)]
fn small_dot(a: &[f64], b: &[f64]) -> f64 {
    if a.len() >= 8 {
        return dot(a, b);
    }
    let mut s = 0.0;
    for (x, y) in a.iter().zip(b) {
        s += x * y;
    }
    s
}

/// Steady-state Kalman filter (innovation form) of x⁺ = Ax + w, y = Cx + v with
/// E[wwᵀ] = Q (n×n), E[wvᵀ] = S (n×p), E[vvᵀ] = R (p×p, positive definite).
#[derive(Debug, Clone)]
pub struct KalmanFilter {
    /// Stabilising solution P (n×n) of the filter Riccati equation
    /// P = APAᵀ + Q − (APCᵀ + S)(CPCᵀ + R)⁻¹(APCᵀ + S)ᵀ.
    pub p: Mat<f64>,
    /// Gain K = (APCᵀ + S)(CPCᵀ + R)⁻¹ (n×p) of the predictor x⁺ = Ax + K(y − Cx).
    pub gain: Mat<f64>,
    /// Innovation covariance CPCᵀ + R (p×p).
    pub innovation_cov: Mat<f64>,
}

/// Solves the filter DARE by the structure-preserving doubling algorithm (Chu, Fan & Lin
/// 2005) after removing the cross term (Ā = A − SR⁻¹C, Q̄ = Q − SR⁻¹Sᵀ, with Q̄'s negative
/// eigenvalues, which only estimation error produces, clipped to 0). Converges quadratically;
/// errors if R is not positive definite, if the iteration does not converge in 100 steps, or
/// if A − KC is not stable.
pub fn kalman_filter_gain(
    a: MatRef<'_, f64>,
    c: MatRef<'_, f64>,
    q: MatRef<'_, f64>,
    s: MatRef<'_, f64>,
    r: MatRef<'_, f64>,
) -> Result<KalmanFilter> {
    let n = a.nrows();
    let p = c.nrows();
    let shapes_ok = a.ncols() == n
        && c.ncols() == n
        && q.nrows() == n
        && q.ncols() == n
        && s.nrows() == n
        && s.ncols() == p
        && r.nrows() == p
        && r.ncols() == p;
    if !shapes_ok {
        return Err(Error::InvalidArgument(format!(
            "kalman_filter_gain: shapes must be A {n}x{n}, C {p}x{n}, Q {n}x{n}, S {n}x{p},              R {p}x{p}"
        )));
    }
    let sym =
        |m: &Mat<f64>| Mat::from_fn(m.nrows(), m.ncols(), |i, j| 0.5 * (m[(i, j)] + m[(j, i)]));
    let r = sym(&r.to_owned());
    let r_llt = r.llt(Side::Lower).map_err(|_| {
        Error::Numerical("measurement noise covariance R is not positive definite".into())
    })?;
    // R⁻¹C and R⁻¹Sᵀ.
    let rinv_c = r_llt.solve(c);
    let rinv_st = r_llt.solve(s.transpose());
    let abar = a - s * &rinv_c;
    let qbar = sym(&(q - s * &rinv_st));
    // Clip Q̄ to the positive semidefinite cone.
    let eig = qbar
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| Error::Numerical(format!("eigendecomposition of Q failed: {e:?}")))?;
    let (uq, sq) = (eig.U(), eig.S().column_vector());
    let qbar = Mat::from_fn(n, n, |i, j| {
        (0..n)
            .map(|k| uq[(i, k)] * sq[k].max(0.0) * uq[(j, k)])
            .sum::<f64>()
    });
    // Dual control-form data: A_k = Āᵀ, G_k = CᵀR⁻¹C, H_k = Q̄; H_k → P.
    let id = Mat::<f64>::identity(n, n);
    let mut ak = abar.transpose().to_owned();
    let mut gk = sym(&(c.transpose() * &rinv_c));
    let mut hk = qbar;
    let mut converged = false;
    for _ in 0..100 {
        let wmat = &id + &gk * &hk;
        let lu = wmat.partial_piv_lu();
        let w_a = lu.solve(&ak); // W⁻¹A_k
        let w_g = lu.solve(&gk); // W⁻¹G_k
        let a_next = &ak * &w_a;
        let g_next = sym(&(&gk + &ak * &w_g * ak.transpose()));
        let h_next = sym(&(&hk + ak.transpose() * &hk * &w_a));
        let diff = crate::lti::norm1((&h_next - &hk).as_ref());
        let scale = crate::lti::norm1(h_next.as_ref()).max(f64::MIN_POSITIVE);
        let finite = (0..n).all(|i| (0..n).all(|j| h_next[(i, j)].is_finite()));
        if !finite {
            return Err(Error::Numerical(
                "Riccati doubling iteration diverged".into(),
            ));
        }
        ak = a_next;
        gk = g_next;
        hk = h_next;
        if diff <= 1e-13 * scale {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(Error::Numerical(
            "Riccati doubling iteration did not converge (is (A, C) detectable?)".into(),
        ));
    }
    let pmat = hk;
    let re = sym(&(&(c * &pmat) * c.transpose() + &r));
    let apct_s = &(a * &pmat) * c.transpose() + s;
    // K = (APCᵀ + S) Re⁻¹  ⇔  Re Kᵀ = (APCᵀ + S)ᵀ.
    let kt = crate::lti::solve_square(re.as_ref(), apct_s.transpose(), "innovation covariance")?;
    let gain = kt.transpose().to_owned();
    let closed = a - &gain * c;
    if !eigenvalues(closed.as_ref())?.iter().all(|z| z.norm() < 1.0) {
        return Err(Error::Numerical(
            "Kalman predictor A − KC is not stable (no stabilising Riccati solution)".into(),
        ));
    }
    Ok(KalmanFilter {
        p: pmat,
        gain,
        innovation_cov: re,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fixed-size SISO residual sums equal the general loop to the bit, for every order it
    /// takes; other sizes are refused (and left to the general loop).
    #[test]
    fn fixed_siso_sums_equal_general_loop_bit_for_bit() {
        let mut uniform = crate::n4sid::linalg::test_uniform(0x5851_f42d_4c95_7f2d);
        let mut next = || uniform() - 0.5;
        let (k, len) = (5, 3000);
        let w: Vec<Vec<f64>> = (0..2).map(|_| (0..len).map(|_| next()).collect()).collect();
        for n in 1..=8usize {
            let count = len - k + 1;
            // Padded to 8 rows as in `kalman_gain`; the rows below n must not be used.
            let states = Mat::from_fn(n.next_multiple_of(8), count, |_, _| next());
            let model = RowMajor {
                a: (0..n * n).map(|_| next()).collect(),
                b: (0..n).map(|_| next()).collect(),
                c: (0..n).map(|_| next()).collect(),
                d: vec![next()],
                n,
                m: 1,
                p: 1,
            };
            let empty = || ResidualSums {
                q: vec![0.0; n * n],
                s: vec![0.0; n],
                r: vec![0.0],
            };
            let whole = StateBlock {
                states: &states,
                s0: 0,
                count: count - 1,
                w: &w,
                k,
            };
            let mut general = empty();
            residual_sums(&whole, &model, &mut general);
            // The same sums folded over blocks (the last one partial), as `kalman_gain` does.
            let mut blocked = empty();
            let mut s0 = 0;
            while s0 < count - 1 {
                let cols = (count - 1 - s0).min(999) + 1;
                let part = Mat::from_fn(states.nrows(), cols, |i, j| states[(i, s0 + j)]);
                let blk = StateBlock {
                    states: &part,
                    s0,
                    count: cols - 1,
                    w: &w,
                    k,
                };
                residual_sums(&blk, &model, &mut blocked);
                s0 += cols - 1;
            }
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&blocked.q), bits(&general.q), "blocked Q, order {n}");
            assert_eq!(bits(&blocked.s), bits(&general.s), "blocked S, order {n}");
            assert_eq!(bits(&blocked.r), bits(&general.r), "blocked R, order {n}");
            let mut fixed = empty();
            match residual_sums_siso(&whole, &model, &mut fixed).then_some(fixed) {
                Some(fixed) => {
                    assert_eq!(bits(&fixed.q), bits(&general.q), "Q, order {n}");
                    assert_eq!(bits(&fixed.s), bits(&general.s), "S, order {n}");
                    assert_eq!(bits(&fixed.r), bits(&general.r), "R, order {n}");
                }
                None => assert_eq!(n, 8, "order {n} refused"),
            }
        }
    }
}
