//! The alternatives the `cratecmp` image measures against the firmware's hand-written
//! `ferrosid_firmware::check::model_response` (complex Gaussian elimination, partial pivoting
//! by modulus, Smith's division): `C (zI − A)⁻¹ B + D` with nalgebra 0.35's fixed-size no_std
//! matrices (`default-features = false, features = ["libm"]`), by its LU
//! ([`model_response_nalgebra`]) and by its Householder QR ([`model_response_qr`]). Same
//! contract as the firmware's: `None` for an out-of-range input/output, a (numerically)
//! singular `zI − A` or a non-finite result.
use ferrosid_firmware::check::C32;
use nalgebra::{Complex, Const, DimMin, SMatrix, SVector};

/// `G(z)` from `input` to `output` with nalgebra's fixed-size complex LU with partial pivoting
/// (pivot: the largest `|re| + |im|`), one solve; `None` for a pivot of `|re| + |im|` at most
/// `N·ε·max|(zI − A)ᵢⱼ|` (z at a pole), an out-of-range input/output or a non-finite result.
// `!(x > tiny)` is deliberate: it rejects NaN, as in the firmware's check.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn model_response_nalgebra<const N: usize, const M: usize, const P: usize>(
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
    let mut scale = 0.0f32;
    let m = SMatrix::<Complex<f32>, N, N>::from_fn(|i, j| {
        let aij = a.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0);
        let e = if i == j {
            Complex::new(z.re - aij, z.im)
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

/// `G(z)` by nalgebra's Householder QR (no pivoting): the variant without data-dependent row
/// indices, measured for its panic paths (the LU's permutation swaps keep bounds checks).
pub fn model_response_qr<const N: usize, const M: usize, const P: usize>(
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
    let m = SMatrix::<Complex<f32>, N, N>::from_fn(|i, j| {
        let aij = a.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0);
        if i == j {
            Complex::new(z.re - aij, z.im)
        } else {
            Complex::new(-aij, 0.0)
        }
    });
    let mut x = SVector::<Complex<f32>, N>::from_fn(|i, _| {
        Complex::new(
            b.get(i).and_then(|r| r.get(input)).copied().unwrap_or(0.0),
            0.0,
        )
    });
    let qr = m.qr();
    if !qr.solve_mut::<Const<N>, Const<1>, _>(&mut x) {
        return None;
    }
    let mut g = C32::new(d_io, 0.0);
    for (xj, &cj) in x.iter().zip(c_row.iter()) {
        g = g + C32::new(xj.re, xj.im).scale(cj);
    }
    (g.re.is_finite() && g.im.is_finite()).then_some(g)
}
