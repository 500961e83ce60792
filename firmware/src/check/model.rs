//! The flashed model's response and the uncertainty weight's magnitude, evaluated on target.
use super::C32;

/// Frequency response of the discrete model (A, B, C, D) from `input` to `output` at the point
/// `z` (on the unit circle `z = e^{jωT}` for a frequency response):
/// `C (zI − A)⁻¹ B + D`, solving `(zI − A) x = B[:, input]` by Gaussian elimination with
/// partial pivoting (complex `f32`, `N×N` on the stack).
///
/// Returns `None` when `zI − A` is singular to working precision (z at a pole), when
/// `input`/`output` is out of range, or when the result is not finite.
///
/// nalgebra's fixed-size complex LU was measured in its place (issue 16, the `cratecmp` QEMU
/// image, docs/firmware.md "Design-card crates on the target"): fewer instructions at 2 and 4 states,
/// the same errors, but its row-permutation swaps keep bounds checks — 13 branches to panic
/// entry points over 2, 4 and 6 states where this code has none — so it is not used.
pub fn model_response<const N: usize, const M: usize, const P: usize>(
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
