//! Step 2: the block Hankel data matrix [U_f; U_p; Y_p; Y_f] and its LQ factor, from the
//! correlation matrix (Cholesky) or a Householder QR.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::linalg::{dot, dots_shifted4};
use super::options::Factorization;
use crate::error::{Error, Result};
use faer::Mat;
use faer::Side;

/// Row ordering of the data matrix: for each row, (block index j in 0..2i, channel index in
/// w = [u; y]). Order [U_f; U_p; Y_p; Y_f].
pub(super) fn row_order(k: usize, m: usize, p: usize) -> Vec<(usize, usize)> {
    let mut rows = Vec::with_capacity(2 * k * (m + p));
    for j in k..2 * k {
        for a in 0..m {
            rows.push((j, a));
        }
    }
    for j in 0..k {
        for a in 0..m {
            rows.push((j, a));
        }
    }
    for j in 0..k {
        for a in m..m + p {
            rows.push((j, a));
        }
    }
    for j in k..2 * k {
        for a in m..m + p {
            rows.push((j, a));
        }
    }
    rows
}

/// Correlation matrix H·Hᵀ/J of the block Hankel matrix in the given row order, computed from
/// lagged cross-correlations of the channels plus the shift recursion
/// R(j+1, l+1) = R(j, l) − w(j)w(l)ᵀ + w(j+J)w(l+J)ᵀ.
pub(super) fn hankel_correlation(w: &[Vec<f64>], k: usize, rows: &[(usize, usize)]) -> Mat<f64> {
    let q = w.len();
    let nb = 2 * k;
    let n = w[0].len();
    let jcols = n - nb + 1;
    // s[(j*q + a), (l*q + b)] for block pairs with j <= l, unnormalised.
    let dim = nb * q;
    let mut s = Mat::<f64>::zeros(dim, dim);
    // First block row: lags l = 0..2i, the q·q·2i products of J terms (most of the work of
    // this step), four consecutive lags per pass over the data ([`dots_shifted4`]), the
    // passes split between two threads; each product is the same wherever it runs.
    let groups: Vec<(usize, usize, usize)> = (0..q)
        .flat_map(|a| (0..q).flat_map(move |b| (0..nb).step_by(4).map(move |l| (a, b, l))))
        .collect();
    let product = |&(a, b, l): &(usize, usize, usize)| -> [f64; 4] {
        if l + 4 <= nb {
            dots_shifted4(&w[a][..jcols], &w[b], l)
        } else {
            std::array::from_fn(|j| {
                if l + j < nb {
                    dot(&w[a][..jcols], &w[b][l + j..l + j + jcols])
                } else {
                    0.0
                }
            })
        }
    };
    // Below about a million multiply-adds a thread costs more than it saves.
    let split = if groups.len() * 4 * jcols < 1 << 20 {
        groups.len()
    } else {
        groups.len() / 2
    };
    let (head, tail) = groups.split_at(split);
    let values: Vec<[f64; 4]> = std::thread::scope(|scope| {
        let tail = (!tail.is_empty())
            .then(|| scope.spawn(|| tail.iter().map(product).collect::<Vec<_>>()));
        let mut values: Vec<[f64; 4]> = head.iter().map(product).collect();
        if let Some(tail) = tail {
            values.extend(
                tail.join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic)),
            );
        }
        values
    });
    for (&(a, b, l), v) in groups.iter().zip(values) {
        for (j, vj) in v.into_iter().enumerate().take(nb - l) {
            s[(a, (l + j) * q + b)] = vj;
        }
    }
    for j in 0..nb - 1 {
        for l in j..nb - 1 {
            for a in 0..q {
                for b in 0..q {
                    let prev = s[(j * q + a, l * q + b)];
                    s[((j + 1) * q + a, (l + 1) * q + b)] =
                        prev - w[a][j] * w[b][l] + w[a][j + jcols] * w[b][l + jcols];
                }
            }
        }
    }
    let inv = 1.0 / jcols as f64;
    let get = |(j, a): (usize, usize), (l, b): (usize, usize)| {
        if j <= l {
            s[(j * q + a, l * q + b)]
        } else {
            s[(l * q + b, j * q + a)]
        }
    };
    Mat::from_fn(rows.len(), rows.len(), |r, c| get(rows[r], rows[c]) * inv)
}

/// LQ factor by Householder QR of Hᵀ/√J (J × rows).
pub(super) fn lq_by_qr(w: &[Vec<f64>], k: usize, rows: &[(usize, usize)]) -> Result<Mat<f64>> {
    let n = w[0].len();
    let jcols = n - 2 * k + 1;
    let sc = 1.0 / (jcols as f64).sqrt();
    let ht = Mat::from_fn(jcols, rows.len(), |t, c| {
        let (j, a) = rows[c];
        w[a][t + j] * sc
    });
    let qr = ht.qr();
    let r = qr.thin_R();
    let l = r.transpose().to_owned();
    for j in 0..l.ncols() {
        for i in 0..l.nrows() {
            if !l[(i, j)].is_finite() {
                return Err(Error::Numerical(
                    "QR of the block Hankel matrix failed".into(),
                ));
            }
        }
    }
    Ok(l)
}

/// The lower-triangular LQ factor of the (scaled) block Hankel matrix of `w` = [u; y] with `k`
/// block rows, and the path used ("cholesky" or "qr"). [`Factorization::Auto`] takes the
/// Cholesky factor of the correlation matrix unless it is not positive definite or its
/// diagonal spans more than 1e7 (then Householder QR of the data matrix).
pub(super) fn lq_factor(
    w: &[Vec<f64>],
    k: usize,
    rows: &[(usize, usize)],
    factorization: Factorization,
) -> Result<(Mat<f64>, &'static str)> {
    let nrows = rows.len();
    Ok(match factorization {
        Factorization::Auto => {
            let r = hankel_correlation(w, k, rows);
            match r.llt(Side::Lower) {
                Ok(ch) => {
                    let l = ch.L().to_owned();
                    let d: Vec<f64> = (0..nrows).map(|i| l[(i, i)]).collect();
                    let dmax = d.iter().fold(0.0f64, |a, &b| a.max(b));
                    let dmin = d.iter().fold(f64::INFINITY, |a, &b| a.min(b));
                    if dmin > 1e-7 * dmax {
                        (l, "cholesky")
                    } else {
                        (lq_by_qr(w, k, rows)?, "qr")
                    }
                }
                Err(_) => (lq_by_qr(w, k, rows)?, "qr"),
            }
        }
        Factorization::Qr => (lq_by_qr(w, k, rows)?, "qr"),
    })
}

/// The persistent-excitation warning, when the input rows of the LQ factor `l` (k block rows,
/// m inputs) have a pivot ratio below 1e-6.
pub(super) fn excitation_warning(l: &Mat<f64>, k: usize, m: usize) -> Option<String> {
    let uf = k * m;
    let dins: Vec<f64> = (0..uf)
        .chain(uf..uf + k * m)
        .map(|i| l[(i, i)].abs())
        .collect();
    let dmax = dins.iter().fold(0.0f64, |a, &b| a.max(b));
    let dmin = dins.iter().fold(f64::INFINITY, |a, &b| a.min(b));
    (dmin < 1e-6 * dmax).then(|| {
        format!(
            "the input is not persistently exciting of order 2i = {} (input-row LQ pivot \
             ratio {:.1e}); the model may be poorly determined: use a broadband input or \
             fewer block rows",
            2 * k,
            dmin / dmax
        )
    })
}
