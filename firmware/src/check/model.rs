//! The flashed model's response and the uncertainty weight's magnitude, evaluated on target.
use super::C32;
use nalgebra::{Complex, Const, DimMin, SMatrix, SVector};

/// Frequency response of the discrete model (A, B, C, D) from `input` to `output` at the point
/// `z` (on the unit circle `z = e^{jωT}` for a frequency response):
/// `C (zI − A)⁻¹ B + D`, solving `(zI − A) x = B[:, input]` with nalgebra's fixed-size LU
/// decomposition with partial pivoting (`SMatrix<Complex<f32>, N, N>` on the stack; the pivot
/// is the largest `|re| + |im|` of the column).
///
/// Returns `None` when `zI − A` is singular to working precision (z at a pole: a pivot of
/// `|re| + |im|` at most `N·ε·max|(zI − A)ᵢⱼ|`), when `input`/`output` is out of range, or when
/// the result is not finite.
///
/// nalgebra replaced a hand-written complex Gaussian elimination (kept for the comparison in
/// `tests/qemu/src/eval_alt.rs`): fewer instructions at 2 and 4 states, the same at 6, errors of
/// the same order (README "Design-card crates on the target").
pub fn model_response<const N: usize, const M: usize, const P: usize>(
    a: &[[f32; N]; N],
    b: &[[f32; M]; N],
    c: &[[f32; N]; P],
    d: &[[f32; M]; P],
    z: C32,
    input: usize,
    output: usize,
) -> Option<C32>
where
    Const<N>: DimMin<Const<N>, Output = Const<N>>,
{
    let (Some(c_row), Some(d_row)) = (c.get(output), d.get(output)) else {
        return None;
    };
    let d_io = *d_row.get(input)?;
    let zc = Complex::new(z.re, z.im);
    let mut scale = 0.0f32;
    let m = SMatrix::<Complex<f32>, N, N>::from_fn(|i, j| {
        let aij = a.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0);
        let e = if i == j {
            Complex::new(zc.re - aij, zc.im)
        } else {
            Complex::new(-aij, 0.0)
        };
        scale = scale.max(e.re.abs() + e.im.abs());
        e
    });
    let mut x = SVector::<Complex<f32>, N>::from_fn(|i, _| {
        Complex::new(
            b.get(i).and_then(|r| r.get(input)).copied().unwrap_or(0.0),
            0.0,
        )
    });
    let lu = m.lu();
    let tiny = scale * f32::EPSILON * N as f32;
    if lu
        .u()
        .diagonal()
        .iter()
        .any(|p| !(p.re.abs() + p.im.abs() > tiny))
    {
        return None;
    }
    // Explicit shape parameters: inference of the right-hand side's shape fails inside this
    // const-generic function.
    if !lu.solve_mut::<Const<N>, Const<1>, _>(&mut x) {
        return None;
    }
    let mut g = C32::new(d_io, 0.0);
    for (xj, &cj) in x.iter().zip(c_row.iter()) {
        g = g + C32::new(xj.re, xj.im).scale(cj);
    }
    (g.re.is_finite() && g.im.is_finite()).then_some(g)
}

/// Evaluates a polynomial with real coefficients (descending powers) at `s` (Horner).
fn poly_at(p: &[f32], s: C32) -> C32 {
    p.iter()
        .fold(C32::default(), |acc, &k| acc * s + C32::new(k, 0.0))
}

/// `|W_m(jω)|` for `W_m(s) = num(s)/den(s)` (descending powers of s, s in rad/s) at
/// `w_rad_s`; `None` when the denominator vanishes there or the result is not finite.
pub fn weight_magnitude(num: &[f32], den: &[f32], w_rad_s: f32) -> Option<f32> {
    let s = C32::new(0.0, w_rad_s);
    let q = poly_at(num, s).checked_div(poly_at(den, s))?;
    let m = q.abs();
    m.is_finite().then_some(m)
}
