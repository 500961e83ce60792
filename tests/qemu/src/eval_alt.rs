//! The model evaluation the firmware used before nalgebra (issue 16), kept here as the
//! baseline the `cratecmp` image measures `ferrosid_firmware::check::model_response`
//! (nalgebra's fixed-size LU) against: `C (zI − A)⁻¹ B + D` by hand-written complex Gaussian
//! elimination with partial pivoting (pivot by modulus, Smith's division). Same contract:
//! `None` for an out-of-range input/output, a (numerically) singular `zI − A` or a non-finite
//! result.
use ferrosid_firmware::check::C32;

/// `G(z)` from `input` to `output` by Gaussian elimination (see the module docs).
pub fn model_response_hand<const N: usize, const M: usize, const P: usize>(
    a: &[[f32; N]; N],
    b: &[[f32; M]; N],
    c: &[[f32; N]; P],
    d: &[[f32; M]; P],
    z: C32,
    input: usize,
    output: usize,
) -> Option<C32> {
    if input >= M || output >= P {
        return None;
    }
    let mut m = [[C32::default(); N]; N];
    let mut x = [C32::default(); N];
    let mut scale = 0.0f32;
    for i in 0..N {
        for j in 0..N {
            let diag = if i == j { z } else { C32::default() };
            m[i][j] = diag - C32::new(a[i][j], 0.0);
            scale = scale.max(m[i][j].abs());
        }
        x[i] = C32::new(b[i][input], 0.0);
    }
    let tiny = scale * f32::EPSILON * N as f32;
    for k in 0..N {
        // Pivot: largest |m[i][k]| for i >= k.
        let mut p = k;
        let mut best = m[k][k].abs();
        for (i, row) in m.iter().enumerate().skip(k + 1) {
            let v = row[k].abs();
            if v > best {
                best = v;
                p = i;
            }
        }
        if !(best > tiny) {
            return None;
        }
        swap_checked(&mut m, k, p)?;
        swap_checked(&mut x, k, p)?;
        let piv = m[k][k];
        let xk = x[k];
        let (top, bottom) = m.split_at_mut_checked(k + 1)?;
        let prow = top.last()?;
        for (row, xi) in bottom.iter_mut().zip(x.iter_mut().skip(k + 1)) {
            let f = row[k].checked_div(piv)?;
            for (a, &b) in row.iter_mut().zip(prow.iter()).skip(k) {
                *a = *a - f * b;
            }
            *xi = *xi - f * xk;
        }
    }
    // Back substitution.
    for k in (0..N).rev() {
        let mut s = x[k];
        for j in k + 1..N {
            s = s - m[k][j] * x[j];
        }
        x[k] = s.checked_div(m[k][k])?;
    }
    let mut g = C32::new(d[output][input], 0.0);
    for j in 0..N {
        g = g + x[j].scale(c[output][j]);
    }
    (g.re.is_finite() && g.im.is_finite()).then_some(g)
}

/// Swaps `s[k]` and `s[p]` for `k <= p` without a bounds-check panic path (`None` when out of
/// range; the pivot search guarantees `k <= p < len`).
fn swap_checked<T>(s: &mut [T], k: usize, p: usize) -> Option<()> {
    if p != k {
        let (lo, hi) = s.split_at_mut_checked(p)?;
        core::mem::swap(lo.get_mut(k)?, hi.first_mut()?);
    }
    Some(())
}
