//! Dense helpers of the subspace steps: inner product, thin SVD, pivoted least squares.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use crate::error::{Error, Result};
use faer::linalg::solvers::SolveLstsq;
use faer::{Mat, MatRef};

/// 8-lane dot product: lane `l` sums the products of the elements `8i + l` in order, the
/// lanes are added as `(0+4) + (1+5) + ((2+6) + (3+7))`, then the remainder in order
/// (vectorisable without reassociation). With AVX2 (detected at run time, [`Avx`]) lanes 0–3
/// and 4–7 are two 256-bit registers: the same multiplications and additions in the same
/// order (no fused multiply-add), so the same bits, in about a third of the instructions.
#[inline]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if let Some(avx) = Avx::new() {
        return avx.run(
            #[inline(always)]
            || dot_avx(avx, a, b),
        );
    }
    dot_lanes(a, b)
}

/// [`dot`] on the target's baseline instructions (the reference of the AVX2 path).
fn dot_lanes(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 8];
    let ca = a.chunks_exact(8);
    let cb = b.chunks_exact(8);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut s = (acc[0] + acc[4]) + (acc[1] + acc[5]) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// The AVX2 instruction set, when the processor has it (faer's `pulp` detection and safe
/// wrappers, no `unsafe` here). Kernels written with it use separate multiplies and adds
/// ([`Avx::mul`], [`Avx::add`]), the roundings of the scalar code; [`Avx::run`] compiles a
/// kernel (and what it calls, all `#[inline(always)]`) for AVX2.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(crate) struct Avx(faer::traits::pulp::x86::V3);

#[cfg(target_arch = "x86_64")]
pub(crate) type F64x4 = faer::traits::pulp::f64x4;

#[cfg(target_arch = "x86_64")]
impl Avx {
    #[inline]
    pub(crate) fn new() -> Option<Self> {
        faer::traits::pulp::x86::V3::try_new().map(Avx)
    }

    #[inline(always)]
    pub(crate) fn run<R>(self, f: impl FnOnce() -> R) -> R {
        self.0.vectorize(f)
    }

    /// Four doubles from `x[at..at + 4]`.
    #[inline(always)]
    pub(crate) fn load(self, x: &[f64], at: usize) -> F64x4 {
        let v: [f64; 4] = x[at..at + 4].try_into().expect("4 lanes");
        faer::traits::pulp::cast(v)
    }

    #[inline(always)]
    pub(crate) fn splat(self, v: f64) -> F64x4 {
        use faer::traits::pulp::Simd;
        self.0.splat_f64s(v)
    }

    #[inline(always)]
    pub(crate) fn add(self, a: F64x4, b: F64x4) -> F64x4 {
        use faer::traits::pulp::Simd;
        self.0.add_f64s(a, b)
    }

    #[inline(always)]
    pub(crate) fn mul(self, a: F64x4, b: F64x4) -> F64x4 {
        use faer::traits::pulp::Simd;
        self.0.mul_f64s(a, b)
    }

    #[inline(always)]
    pub(crate) fn lanes(self, a: F64x4) -> [f64; 4] {
        faer::traits::pulp::cast(a)
    }
}

/// Runs `f` compiled for AVX2 when the processor has it, else as is: plain loops inside `f`
/// (and in the `#[inline(always)]` functions it calls) are then vectorised 4 wide instead of
/// 2. Only the instructions differ: Rust never reassociates or fuses floating-point
/// operations, so both compilations give the same bits.
#[inline(always)]
pub(crate) fn with_avx<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if let Some(avx) = Avx::new() {
        return avx.run(f);
    }
    f()
}

/// `[dot(a, &b[l0 + j..]) for j in 0..4]`: four dot products of `a` with windows of `b` that
/// start one sample apart (`b` must hold `l0 + 3 + a.len()` samples), each the same sum in
/// the same order as [`dot`] (the same bits); with AVX2 one pass loads `a` once for the four.
pub(crate) fn dots_shifted4(a: &[f64], b: &[f64], l0: usize) -> [f64; 4] {
    let n = a.len();
    assert!(b.len() >= l0 + 3 + n, "dots_shifted4: window past the end");
    #[cfg(target_arch = "x86_64")]
    if let Some(avx) = Avx::new() {
        return avx.run(
            #[inline(always)]
            || dots_shifted4_avx(avx, a, &b[l0..l0 + 3 + n]),
        );
    }
    std::array::from_fn(|j| dot_lanes(a, &b[l0 + j..l0 + j + n]))
}

/// [`dots_shifted4`] on AVX2 (`b` starts at the first window and holds `a.len() + 3`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn dots_shifted4_avx(avx: Avx, a: &[f64], b: &[f64]) -> [f64; 4] {
    let (ca, blocks) = (a.as_chunks::<8>().0, a.len() / 8);
    let zero = avx.splat(0.0);
    let (mut lo, mut hi) = ([zero; 4], [zero; 4]);
    for (i, x) in ca.iter().enumerate() {
        // The 11 samples of `b` the four windows of this block reach.
        let y: &[f64; 11] = b[8 * i..8 * i + 11]
            .try_into()
            .expect("b holds a.len() + 3");
        let (xl, xh) = (avx.load(x, 0), avx.load(x, 4));
        for j in 0..4 {
            lo[j] = avx.add(lo[j], avx.mul(xl, avx.load(y, j)));
            hi[j] = avx.add(hi[j], avx.mul(xh, avx.load(y, j + 4)));
        }
    }
    std::array::from_fn(|j| {
        let v = avx.lanes(avx.add(lo[j], hi[j]));
        let mut s = (v[0] + v[1]) + (v[2] + v[3]);
        for (x, y) in a[8 * blocks..].iter().zip(&b[8 * blocks + j..]) {
            s += x * y;
        }
        s
    })
}

/// [`dot_lanes`] with lanes 0–3 and 4–7 in two registers.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn dot_avx(avx: Avx, a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let (ca, cb) = (a.as_chunks::<8>().0, b.as_chunks::<8>().0);
    let blocks = ca.len();
    let (mut lo, mut hi) = (avx.splat(0.0), avx.splat(0.0));
    for (x, y) in ca.iter().zip(cb) {
        lo = avx.add(lo, avx.mul(avx.load(x, 0), avx.load(y, 0)));
        hi = avx.add(hi, avx.mul(avx.load(x, 4), avx.load(y, 4)));
    }
    // v = [acc0 + acc4, acc1 + acc5, acc2 + acc6, acc3 + acc7].
    let v = avx.lanes(avx.add(lo, hi));
    let mut s = (v[0] + v[1]) + (v[2] + v[3]);
    for (x, y) in a[8 * blocks..].iter().zip(&b[8 * blocks..]) {
        s += x * y;
    }
    s
}

pub(super) struct Svd {
    pub(super) u: Mat<f64>,
    pub(super) s: Vec<f64>,
    pub(super) v: Mat<f64>,
}

pub(super) fn thin_svd(m: MatRef<'_, f64>, what: &str) -> Result<Svd> {
    let svd = m
        .thin_svd()
        .map_err(|e| Error::Numerical(format!("SVD of {what} did not converge: {e:?}")))?;
    let s: Vec<f64> = svd.S().column_vector().iter().copied().collect();
    Ok(Svd {
        u: svd.U().to_owned(),
        s,
        v: svd.V().to_owned(),
    })
}

/// Least squares min ‖A x − B‖ by column-pivoted QR; errors when A is rank deficient to
/// working precision.
pub(super) fn lstsq(a: MatRef<'_, f64>, b: MatRef<'_, f64>, what: &str) -> Result<Mat<f64>> {
    let qr = a.col_piv_qr();
    let r = qr.R();
    let d = a.ncols().min(a.nrows());
    if d == 0 {
        return Ok(Mat::zeros(a.ncols(), b.ncols()));
    }
    let r0 = r[(0, 0)].abs();
    let rmin = (0..d)
        .map(|i| r[(i, i)].abs())
        .fold(f64::INFINITY, f64::min);
    if !(rmin > 1e-13 * r0) || a.nrows() < a.ncols() {
        return Err(Error::Numerical(format!(
            "{what}: regressors are rank deficient (pivot ratio {:.1e})",
            rmin / r0
        )));
    }
    let x = qr.solve_lstsq(b);
    for j in 0..x.ncols() {
        for i in 0..x.nrows() {
            if !x[(i, j)].is_finite() {
                return Err(Error::Numerical(format!("{what}: solution not finite")));
            }
        }
    }
    Ok(x)
}

/// Upper-triangular factor R (c × c, c = `cols.len()`) of the Householder QR of the tall
/// matrix whose columns are `cols` (all of one length), so that AᵀA = RᵀR, computed one block
/// of rows at a time: each block is folded into the running R by the Householder reflections
/// of the stacked matrix [R; block] (LAPACK's triangular-pentagonal QR, `tpqrt`), which keeps a
/// block in cache and never stores Q. Backward stable like any Householder QR; the signs of
/// R's rows may differ from another QR of the same matrix.
pub(super) fn tall_qr_r(cols: &[&[f64]]) -> Mat<f64> {
    with_avx(
        #[inline(always)]
        || tall_qr_r_body(cols),
    )
}

/// [`tall_qr_r`]'s work (compiled twice by [`with_avx`]).
#[inline(always)]
fn tall_qr_r_body(cols: &[&[f64]]) -> Mat<f64> {
    const BLOCK: usize = 256;
    let c = cols.len();
    let rows = cols.first().map_or(0, |x| x.len());
    let mut r = Mat::<f64>::zeros(c, c);
    // The block, column-major, and its Householder vectors' tails (in place).
    let mut blk = vec![0.0f64; BLOCK * c];
    let mut start = 0;
    while start < rows {
        let b = BLOCK.min(rows - start);
        for (j, col) in cols.iter().enumerate() {
            blk[j * BLOCK..j * BLOCK + b].copy_from_slice(&col[start..start + b]);
        }
        for j in 0..c {
            let (head, tail) = blk.split_at_mut((j + 1) * BLOCK);
            let x = &mut head[j * BLOCK..j * BLOCK + b];
            let alpha = r[(j, j)];
            let xx = dot(x, x);
            if xx == 0.0 {
                continue; // H = I: nothing below the diagonal to annihilate
            }
            let norm = alpha.hypot(xx.sqrt());
            let beta = if alpha >= 0.0 { -norm } else { norm };
            // v = [1; x/(α − β)], τ = (β − α)/β; H = I − τ v vᵀ maps [α; x] to [β; 0].
            let scale = 1.0 / (alpha - beta);
            x.iter_mut().for_each(|v| *v *= scale);
            let tau = (beta - alpha) / beta;
            r[(j, j)] = beta;
            for k in j + 1..c {
                let y = &mut tail[(k - j - 1) * BLOCK..(k - j - 1) * BLOCK + b];
                let w = tau * (r[(j, k)] + dot(x, y));
                r[(j, k)] -= w;
                y.iter_mut()
                    .zip(x.iter())
                    .for_each(|(yv, xv)| *yv -= w * xv);
            }
        }
        start += b;
    }
    r
}

/// Least squares min ‖A θ − y‖ for a tall A given by its columns, through the R factor of
/// [A y] ([`tall_qr_r`]): R₁₁θ = r₁₂ solved by [`lstsq`] on the small triangle, whose
/// column-pivoted QR has the same diagonal (rank test) as that of A. Returns θ and R₁₁
/// (AᵀA = R₁₁ᵀR₁₁).
pub(super) fn tall_lstsq(a: &[&[f64]], y: &[f64], what: &str) -> Result<(Mat<f64>, Mat<f64>)> {
    let c = a.len();
    if y.len() < c || a.iter().any(|col| col.len() != y.len()) {
        return Err(Error::Numerical(format!(
            "{what}: regressors are rank deficient ({} rows for {c} unknowns)",
            y.len()
        )));
    }
    let mut cols: Vec<&[f64]> = a.to_vec();
    cols.push(y);
    let r = tall_qr_r(&cols);
    let r11 = r.as_ref().submatrix(0, 0, c, c).to_owned();
    let r12 = r.as_ref().submatrix(0, c, c, 1);
    let theta = lstsq(r11.as_ref(), r12, what)?;
    Ok((theta, r11))
}

/// Uniform numbers in [0, 1) from the workspace's one generator (the firmware's SplitMix64,
/// `ferrosid_firmware::rng`, a dev-dependency), deterministic for the tests' noise and data.
#[cfg(test)]
pub(crate) fn test_uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut rng = ferrosid_firmware::rng::SplitMix64::new(seed);
    move || rng.next_f64()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`dot`] on the dispatched path equals the plain loop to the bit, for lengths around the
    /// lane count and long ones, values of mixed sign and scale.
    #[test]
    fn dot_paths_agree_bit_for_bit() {
        let mut rng = ferrosid_firmware::rng::SplitMix64::new(0x9e37_79b9_7f4a_7c15);
        let mut next = || {
            let s = rng.next_u64();
            ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 10f64.powi((s % 7) as i32 - 3)
        };
        for n in (0..40).chain([255, 256, 257, 1000, 100_003]) {
            let a: Vec<f64> = (0..n).map(|_| next()).collect();
            let b: Vec<f64> = (0..n + 3).map(|_| next()).collect();
            let want = dot_lanes(&a, &b);
            assert_eq!(dot(&a, &b).to_bits(), want.to_bits(), "length {n}");
        }
    }

    /// The four shifted dot products equal [`dot`] of each window to the bit.
    #[test]
    fn shifted_dots_equal_single_dots_bit_for_bit() {
        let mut uniform = test_uniform(5);
        for n in [0usize, 1, 7, 8, 9, 31, 1000, 4099] {
            let a: Vec<f64> = (0..n).map(|_| uniform() - 0.5).collect();
            let b: Vec<f64> = (0..n + 12).map(|_| 3.0 * uniform() - 1.0).collect();
            for l0 in [0, 1, 5, 9] {
                let got = dots_shifted4(&a, &b, l0);
                for (j, g) in got.iter().enumerate() {
                    let want = dot_lanes(&a, &b[l0 + j..l0 + j + n]);
                    assert_eq!(g.to_bits(), want.to_bits(), "n {n}, lag {}", l0 + j);
                }
            }
        }
    }

    /// Columns of a badly scaled, nearly collinear tall matrix and a noisy right-hand side.
    fn problem(rows: usize) -> (Vec<Vec<f64>>, Vec<f64>) {
        let mut uniform = test_uniform(99);
        let mut next = || uniform() - 0.5;
        let base: Vec<f64> = (0..rows).map(|_| next()).collect();
        let cols: Vec<Vec<f64>> = (0..6)
            .map(|j| {
                let g = 10f64.powi(j as i32 - 3);
                base.iter()
                    .enumerate()
                    .map(|(t, v)| g * (v + 1e-3 * ((t * (j + 1)) as f64).sin() + 0.3 * next()))
                    .collect()
            })
            .collect();
        let y = (0..rows)
            .map(|t| cols.iter().map(|c| c[t]).sum::<f64>() + 0.01 * next())
            .collect();
        (cols, y)
    }

    /// RᵀR equals AᵀA (to 1e-12 of the diagonal scale) and the solution agrees with faer's
    /// column-pivoted QR least squares ([`lstsq`] on the full matrix, the former path), for
    /// row counts that are and are not multiples of the block.
    #[test]
    fn tall_least_squares_equals_the_pivoted_qr_solution() {
        for rows in [7, 256, 1000, 20_001] {
            let (cols, y) = problem(rows);
            let views: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
            let (theta, r11) = tall_lstsq(&views, &y, "test").expect("tall");
            let c = views.len();
            let gram = r11.transpose() * &r11;
            for i in 0..c {
                for j in 0..c {
                    let direct = dot(views[i], views[j]);
                    let scale = (dot(views[i], views[i]) * dot(views[j], views[j])).sqrt();
                    assert!(
                        (gram[(i, j)] - direct).abs() <= 1e-12 * scale,
                        "rows {rows}: G[{i}][{j}] {} vs {direct}",
                        gram[(i, j)]
                    );
                }
            }
            let a = Mat::from_fn(rows, c, |t, j| cols[j][t]);
            let b = Mat::from_fn(rows, 1, |t, _| y[t]);
            let old = lstsq(a.as_ref(), b.as_ref(), "test").expect("pivoted");
            // Same fitted values (A·θ) to 1e-12 of ‖y‖, hence the same residual; the
            // coefficients of this deliberately ill-conditioned matrix agree to 1e-6.
            let diff = &a * (&theta - &old);
            let dn = diff.col(0).iter().map(|v| v * v).sum::<f64>().sqrt();
            let yn = dot(&y, &y).sqrt();
            assert!(
                dn <= 1e-12 * yn,
                "rows {rows}: ‖A(θ − θ_old)‖ = {dn:e}, ‖y‖ = {yn:e}"
            );
            for k in 0..c {
                assert!(
                    (theta[(k, 0)] - old[(k, 0)]).abs() <= 1e-6 * old[(k, 0)].abs(),
                    "rows {rows}: θ[{k}] {} vs {}",
                    theta[(k, 0)],
                    old[(k, 0)]
                );
            }
        }
    }

    /// [`tall_qr_r`] on the AVX2 path (when the processor has it) equals the baseline
    /// compilation of the same loops to the bit.
    #[test]
    fn tall_qr_paths_agree_bit_for_bit() {
        for rows in [7, 256, 1000, 20_001] {
            let (cols, y) = problem(rows);
            let mut views: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
            views.push(&y);
            let (got, want) = (tall_qr_r(&views), tall_qr_r_body(&views));
            for i in 0..views.len() {
                for j in 0..views.len() {
                    assert_eq!(
                        got[(i, j)].to_bits(),
                        want[(i, j)].to_bits(),
                        "rows {rows} R[{i}][{j}]"
                    );
                }
            }
        }
    }

    /// A rank-deficient matrix is refused as by the pivoted QR.
    #[test]
    fn tall_least_squares_refuses_collinear_columns() {
        let a: Vec<f64> = (0..500).map(|t| (t as f64 * 0.1).sin()).collect();
        let b: Vec<f64> = a.iter().map(|v| 2.0 * v).collect();
        let y: Vec<f64> = (0..500).map(|t| t as f64).collect();
        let err = tall_lstsq(&[&a, &b], &y, "collinear").expect_err("rank deficient");
        assert!(err.to_string().contains("rank deficient"), "{err}");
    }
}
