//! The bounded pieces of work that turn one completed segment into spectral sums.
//!
//! # Data layout
//! A segment bank holds `N` sample pairs `[u[i], y[i]]` (so `push` stores one pair), read as
//! `N/2` [`Quad`]s `[u[2n], y[2n], u[2n+1], y[2n+1]]`, i.e. the complex numbers
//! `z_u[n] = u[2n] + j·u[2n+1]` and `z_y[n]` likewise (real parts in lanes 0, 1, imaginary
//! parts in lanes 2, 3), which is the packing of a real FFT of `N` points into a complex FFT of
//! `M = N/2` points. Every kernel moves both channels at once (one load per quad, shared
//! twiddles and loop overhead).
//!
//! # Transform
//! * Radix-4 decimation in frequency, in place, in stages of length `L = M, M/4, …`; a
//!   butterfly is two radix-2 DIF stages fused, so the output is in **bit-reversed** order (as
//!   after `log2 M` radix-2 DIF stages): bin `k` of `Z` sits at position `rev(k)`. When
//!   `log2 M` is odd a final radix-2 stage (unit twiddles) completes it; that stage is fused
//!   into the recombination (it pairs positions `2g, 2g+1`, whose mirrors are again such a
//!   pair), saving a pass over the data. The first stage also removes the segment mean and
//!   applies the window as it loads its inputs.
//! * Recombination to the real spectrum, `2X[k] = E - j·W_N^k·O` with
//!   `E = Z[k] + conj Z[M-k]`, `O = Z[k] - conj Z[M-k]`, and `2X[M-k] = conj(E + j·W_N^k·O)`.
//!   In bit-reversed order the pairs `(k, M-k)` are mirror positions inside each octave block
//!   `[2^l, 2^(l+1))`: `p = 2^l + i` and `q = 2^(l+1) - 1 - i`. So the recombination walks
//!   forward and backward through each block, and the products `|2U|², |2Y|², conj(2U)·2Y` are
//!   added to the accumulators *stored in the same bit-reversed order* (no reordering pass).
//!
//! Every kernel takes a range of work items so that the caller can split a segment's work into
//! slices of bounded cost. Nothing here indexes out of range: all accesses are through
//! iterators or checked `get`, and a (never reached) empty range means no work.

use super::tables::Tables;

/// Two complex values, one per channel: `[Re z_u, Re z_y, Im z_u, Im z_y]`.
pub(super) type Quad = [f32; 4];
/// Two `f32` values.
pub(super) type Pair = [f32; 2];

/// Views a bank of `N` pairs (`2N` values) as `N/2` quads.
#[inline(always)]
pub(super) fn quads(bank: &[Pair]) -> &[Quad] {
    bank.as_flattened().as_chunks::<4>().0
}

/// Mutable view of a bank as quads.
#[inline(always)]
pub(super) fn quads_mut(bank: &mut [Pair]) -> &mut [Quad] {
    bank.as_flattened_mut().as_chunks_mut::<4>().0
}

/// `z·(c - j·s)`, i.e. `z·e^{-jθ}` for `(c, s) = (cos θ, sin θ)`.
#[inline(always)]
fn rot(zr: f32, zi: f32, c: f32, s: f32) -> (f32, f32) {
    (zr * c + zi * s, zi * c - zr * s)
}

/// The sums and differences of a radix-4 DIF butterfly for channel `ch` (0 or 1) as
/// (re, im) pairs: `t0 = x0 + x2`, `t1 = x1 + x3`, `t2 = x0 - x2`, `t3 = x1 - x3`.
#[inline(always)]
fn dif_terms(x: &[Quad; 4], ch: usize) -> [(f32, f32); 4] {
    let [x0, x1, x2, x3] = x;
    [
        (x0[ch] + x2[ch], x0[ch + 2] + x2[ch + 2]),
        (x1[ch] + x3[ch], x1[ch + 2] + x3[ch + 2]),
        (x0[ch] - x2[ch], x0[ch + 2] - x2[ch + 2]),
        (x1[ch] - x3[ch], x1[ch + 2] - x3[ch + 2]),
    ]
}

/// Radix-4 DIF butterfly on both channels with twiddles `[cos θ, sin θ, cos 2θ, …]`:
/// `y0 = t0 + t1`, `y1 = (t0 - t1)W²`, `y2 = (t2 - j t3)W`, `y3 = (t2 + j t3)W³`, where
/// `t0 = x0 + x2`, `t1 = x1 + x3`, `t2 = x0 - x2`, `t3 = x1 - x3`, `W = e^{-jθ}`.
#[inline(always)]
fn radix4(x: [Quad; 4], w: &[f32; 6]) -> [Quad; 4] {
    let [c1, s1, c2, s2, c3, s3] = *w;
    let mut y = [[0.0f32; 4]; 4];
    for ch in [0, 1] {
        let [(t0r, t0i), (t1r, t1i), (t2r, t2i), (t3r, t3i)] = dif_terms(&x, ch);
        y[0][ch] = t0r + t1r;
        y[0][ch + 2] = t0i + t1i;
        (y[1][ch], y[1][ch + 2]) = rot(t0r - t1r, t0i - t1i, c2, s2);
        (y[2][ch], y[2][ch + 2]) = rot(t2r + t3i, t2i - t3r, c1, s1);
        (y[3][ch], y[3][ch + 2]) = rot(t2r - t3i, t2i + t3r, c3, s3);
    }
    y
}

/// Radix-4 DIF butterfly with unit twiddles (the stage of length 4).
#[inline(always)]
fn radix4_unit(x: [Quad; 4]) -> [Quad; 4] {
    let mut y = [[0.0f32; 4]; 4];
    for ch in [0, 1] {
        let [(t0r, t0i), (t1r, t1i), (t2r, t2i), (t3r, t3i)] = dif_terms(&x, ch);
        y[0][ch] = t0r + t1r;
        y[0][ch + 2] = t0i + t1i;
        y[1][ch] = t0r - t1r;
        y[1][ch + 2] = t0i - t1i;
        y[2][ch] = t2r + t3i;
        y[2][ch + 2] = t2i - t3r;
        y[3][ch] = t2r - t3i;
        y[3][ch + 2] = t2i + t3r;
    }
    y
}

/// Splits `s` into four quarters of length `q` (`None` if it is shorter than `4q`).
#[inline(always)]
fn quarters<T>(s: &mut [T], q: usize) -> Option<[&mut [T]; 4]> {
    let (a, rest) = s.split_at_mut_checked(q)?;
    let (b, rest) = rest.split_at_mut_checked(q)?;
    let (c, d) = rest.split_at_mut_checked(q)?;
    Some([a, b, c, d])
}

/// The `k`-th quad of each quarter `a`..`d` of a butterfly and its twiddles `tw[k]` (`None`
/// when any of them is past its end).
#[inline(always)]
fn butterfly_at<'s, 't>(
    a: &'s mut [Quad],
    b: &'s mut [Quad],
    c: &'s mut [Quad],
    d: &'s mut [Quad],
    tw: &'t [[f32; 6]],
    k: usize,
) -> Option<([&'s mut Quad; 4], &'t [f32; 6])> {
    let (Some(a), Some(b), Some(c), Some(d), Some(t)) = (
        a.get_mut(k),
        b.get_mut(k),
        c.get_mut(k),
        d.get_mut(k),
        tw.get(k),
    ) else {
        return None;
    };
    Some(([a, b, c, d], t))
}

/// Subtracts the channel means `mu` and applies the window pair `w` to one quad.
#[inline(always)]
fn prepare(x: &Quad, w: &Pair, mu: &Pair) -> Quad {
    [
        (x[0] - mu[0]) * w[0],
        (x[1] - mu[1]) * w[0],
        (x[2] - mu[0]) * w[1],
        (x[3] - mu[1]) * w[1],
    ]
}

/// Subtracts the channel means `mu` from one quad (rectangular window).
#[inline(always)]
fn centre(x: &Quad, mu: &Pair) -> Quad {
    [x[0] - mu[0], x[1] - mu[1], x[2] - mu[0], x[3] - mu[1]]
}

/// Butterflies `start..start + count` of the first stage (length `M = z.len()`, one group):
/// the inputs are centred by `mu` and windowed by `window` (pairs `[w[2n], w[2n+1]]`, `M` of
/// them; `None` = rectangular) as they are loaded.
pub(super) fn first_stage(
    z: &mut [Quad],
    window: Option<&[Pair]>,
    mu: Pair,
    tw: &[[f32; 6]],
    start: usize,
    count: usize,
) {
    let q = z.len() / 4;
    let end = (start + count).min(q);
    let Some([a, b, c, d]) = quarters(z, q) else {
        return;
    };
    let (Some(a), Some(b), Some(c), Some(d), Some(tw)) = (
        a.get_mut(start..end),
        b.get_mut(start..end),
        c.get_mut(start..end),
        d.get_mut(start..end),
        tw.get(start..end),
    ) else {
        return;
    };
    match window {
        Some(win) => {
            let Some(win) = win.get(..4 * q) else {
                return;
            };
            let (wa, rest) = win.split_at(q);
            let (wb, rest) = rest.split_at(q);
            let (wc, wd) = rest.split_at(q);
            let (Some(wa), Some(wb), Some(wc), Some(wd)) = (
                wa.get(start..end),
                wb.get(start..end),
                wc.get(start..end),
                wd.get(start..end),
            ) else {
                return;
            };
            for k in 0..end - start.min(end) {
                let Some(([a, b, c, d], t)) = butterfly_at(a, b, c, d, tw, k) else {
                    return;
                };
                let (Some(w0), Some(w1), Some(w2), Some(w3)) =
                    (wa.get(k), wb.get(k), wc.get(k), wd.get(k))
                else {
                    return;
                };
                let x = [
                    prepare(a, w0, &mu),
                    prepare(b, w1, &mu),
                    prepare(c, w2, &mu),
                    prepare(d, w3, &mu),
                ];
                [*a, *b, *c, *d] = radix4(x, t);
            }
        }
        None => {
            for k in 0..end - start.min(end) {
                let Some(([a, b, c, d], t)) = butterfly_at(a, b, c, d, tw, k) else {
                    return;
                };
                let x = [
                    centre(a, &mu),
                    centre(b, &mu),
                    centre(c, &mu),
                    centre(d, &mu),
                ];
                [*a, *b, *c, *d] = radix4(x, t);
            }
        }
    }
}

/// Butterflies `start..start + count` (numbered group by group) of a radix-4 stage of length
/// `l >= 16` with twiddles `tw` (`l/4` entries).
pub(super) fn radix4_stage(z: &mut [Quad], l: usize, tw: &[[f32; 6]], start: usize, count: usize) {
    let q = l / 4;
    if q == 0 {
        return;
    }
    let mut t = start;
    let end = start + count;
    while t < end {
        let (g, n) = (t / q, t % q);
        let run = (q - n).min(end - t);
        let Some(group) = z.get_mut(g * l..g * l + l) else {
            return;
        };
        let Some([a, b, c, d]) = quarters(group, q) else {
            return;
        };
        let (Some(a), Some(b), Some(c), Some(d), Some(tw)) = (
            a.get_mut(n..n + run),
            b.get_mut(n..n + run),
            c.get_mut(n..n + run),
            d.get_mut(n..n + run),
            tw.get(n..n + run),
        ) else {
            return;
        };
        for k in 0..run {
            let Some(([a, b, c, d], w)) = butterfly_at(a, b, c, d, tw, k) else {
                return;
            };
            [*a, *b, *c, *d] = radix4([*a, *b, *c, *d], w);
        }
        t += run;
    }
}

/// Groups `start..start + count` of the radix-4 stage of length 8: two butterflies per group
/// (`n = 0` with unit twiddles, `n = 1` with `tw[1]`), without an inner loop.
pub(super) fn radix4_stage8(z: &mut [Quad], tw: &[[f32; 6]], start: usize, count: usize) {
    let (groups, _) = z.as_chunks_mut::<8>();
    let (Some(groups), Some(w)) = (groups.get_mut(start..start + count), tw.get(1)) else {
        return;
    };
    // Two passes over the groups, the unit-twiddle butterflies (even quads) then the twiddled
    // ones (odd quads): each pass keeps one butterfly (16 values) and the twiddles in registers.
    // Both butterflies of a group in one loop body need 32 values plus the twiddles, more than
    // the 32 FPU registers, and spilled about 40 values per group.
    for g in groups.iter_mut() {
        let [a0, _, b0, _, c0, _, d0, _] = g;
        [*a0, *b0, *c0, *d0] = radix4_unit([*a0, *b0, *c0, *d0]);
    }
    for g in groups.iter_mut() {
        let [_, a1, _, b1, _, c1, _, d1] = g;
        [*a1, *b1, *c1, *d1] = radix4([*a1, *b1, *c1, *d1], w);
    }
}

/// Butterflies `start..start + count` of the radix-4 stage of length 4 (unit twiddles).
pub(super) fn unit4_stage(z: &mut [Quad], start: usize, count: usize) {
    let (groups, _) = z.as_chunks_mut::<4>();
    let Some(groups) = groups.get_mut(start..start + count) else {
        return;
    };
    for g in groups {
        *g = radix4_unit(*g);
    }
}

/// Adds the products of one bin's doubled spectra `x = [2U, 2Y]` to its sums
/// `[Σ|2U|², Σ|2Y|², Σ Re conj(2U)·2Y, Σ Im conj(2U)·2Y]`.
///
/// Each product is added to the sum on its own (`(acc + a·a) + b·b`, not `acc + (a·a + b·b)`):
/// on the Cortex-M4F that is two multiply-accumulates (`VMLA`/`VMLS`, which round the product
/// and then the sum, like a multiply and an add) instead of a multiply, a multiply-accumulate
/// and an add, 4 instructions less per bin. Every term is still rounded once.
#[inline(always)]
fn add_products(acc: &mut Quad, x: &Quad) {
    let [ur, yr, ui, yi] = *x;
    acc[0] = acc[0] + ur * ur + ui * ui;
    acc[1] = acc[1] + yr * yr + yi * yi;
    acc[2] = acc[2] + ur * yr + ui * yi;
    acc[3] = acc[3] + ur * yi - ui * yr;
}

/// Recombination of the mirror pair `zk = Z[k]`, `zc = Z[M-k]` with `(c, s)` of `2πk/N`:
/// returns `(2X[k], 2X[M-k])` for both channels.
#[inline(always)]
fn recombine(zk: &Quad, zc: &Quad, w: &Pair) -> (Quad, Quad) {
    let [c, s] = *w;
    let (mut xk, mut xm) = ([0.0f32; 4], [0.0f32; 4]);
    for ch in [0, 1] {
        let (er, ei) = (zk[ch] + zc[ch], zk[ch + 2] - zc[ch + 2]);
        let (or, oi) = (zk[ch] - zc[ch], zk[ch + 2] + zc[ch + 2]);
        let (tr, ti) = rot(or, oi, c, s);
        xk[ch] = er + ti;
        xk[ch + 2] = ei - tr;
        xm[ch] = er - ti;
        xm[ch + 2] = -(ei + tr);
    }
    (xk, xm)
}

/// Pairs `start..start + count` of the recombination (pair `t` of level `l`, block
/// `b = 2^l`: `t = b/2 - 1 + i`, positions `p = b + i`, `q = 2b - 1 - i`); `tw` is
/// [`Tables::COMBINE`] as pairs. Adds the products of bins `rev(p)`, `rev(q)` to `acc[p]`,
/// `acc[q]`.
pub(super) fn combine(z: &[Quad], acc: &mut [Quad], tw: &[Pair], start: usize, count: usize) {
    let mut t = start;
    let end = start + count;
    while t < end {
        let level = usize::BITS - (t + 1).leading_zeros();
        let b = 1usize << level;
        let half = b / 2;
        let i = t + 1 - half;
        let run = (half - i).min(end - t);
        let (Some(zf), Some(zs), Some(tw)) = (
            z.get(b + i..b + i + run),
            z.get(2 * b - i - run..2 * b - i),
            tw.get(t..t + run),
        ) else {
            return;
        };
        let Some((lo, hi)) = acc.split_at_mut_checked(b + half) else {
            return;
        };
        let (Some(af), Some(ab)) = (
            lo.get_mut(b + i..b + i + run),
            hi.get_mut(half - i - run..half - i),
        ) else {
            return;
        };
        let fwd = zf.iter().zip(tw).zip(af.iter_mut());
        let bwd = zs.iter().rev().zip(ab.iter_mut().rev());
        for (((zk, w), ak), (zc, ac)) in fwd.zip(bwd) {
            let (xk, xm) = recombine(zk, zc, w);
            add_products(ak, &xk);
            add_products(ac, &xm);
        }
        t += run;
    }
}

/// The radix-2 butterfly with unit twiddle on both channels: `(a + b, a - b)`.
#[inline(always)]
fn radix2(a: &Quad, b: &Quad) -> (Quad, Quad) {
    (
        [a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]],
        [a[0] - b[0], a[1] - b[1], a[2] - b[2], a[3] - b[3]],
    )
}

/// The recombination fused with the final radix-2 stage (when `log2 M` is odd, `z` holds the
/// output of the last radix-4 stage and the radix-2 butterflies pair positions `2g, 2g+1`).
/// The mirror of a radix-2 pair `(p, p+1)` (`p` even, level `>= 2`) is the radix-2 pair
/// `(q-1, q)`, so item `j >= 1` loads those four quads once, does both butterflies and
/// recombines the pairs `t = 2j - 1` (`p`, `q`) and `t + 1` (`p+1`, `q-1`). Item 0 is level 1:
/// positions 2 and 3, one butterfly and pair `t = 0`. Items `start..start + count`; `M/4` in
/// all.
pub(super) fn combine_radix2(
    z: &[Quad],
    acc: &mut [Quad],
    tw: &[Pair],
    start: usize,
    count: usize,
) {
    let end = start + count;
    let mut j = start;
    if j == 0 && j < end {
        if let (Some(y2), Some(y3), Some(w), [_, _, a2, a3, ..]) =
            (z.get(2), z.get(3), tw.first(), &mut *acc)
        {
            let (z2, z3) = radix2(y2, y3);
            let (xk, xm) = recombine(&z2, &z3, w);
            add_products(a2, &xk);
            add_products(a3, &xm);
        }
        j = 1;
    }
    while j < end {
        let t = 2 * j - 1;
        let level = usize::BITS - (t + 1).leading_zeros();
        let b = 1usize << level;
        let half = b / 2;
        let i = t + 1 - half;
        let run = ((half - i) / 2).min(end - j);
        if run == 0 {
            return;
        }
        let (Some(zf), Some(zs), Some(tw)) = (
            z.get(b + i..b + i + 2 * run),
            z.get(2 * b - i - 2 * run..2 * b - i),
            tw.get(t..t + 2 * run),
        ) else {
            return;
        };
        let Some((lo, hi)) = acc.split_at_mut_checked(b + half) else {
            return;
        };
        let (Some(af), Some(ab)) = (
            lo.get_mut(b + i..b + i + 2 * run),
            hi.get_mut(half - i - 2 * run..half - i),
        ) else {
            return;
        };
        let fwd = zf
            .as_chunks::<2>()
            .0
            .iter()
            .zip(tw.as_chunks::<2>().0)
            .zip(af.as_chunks_mut::<2>().0);
        let bwd = zs
            .as_chunks::<2>()
            .0
            .iter()
            .rev()
            .zip(ab.as_chunks_mut::<2>().0.iter_mut().rev());
        for ((([yp, yp1], [w0, w1]), [ap, ap1]), ([yq1, yq], [aq1, aq])) in fwd.zip(bwd) {
            let (zp, zp1) = radix2(yp, yp1);
            let (zq1, zq) = radix2(yq1, yq);
            let (xk, xm) = recombine(&zp, &zq, w0);
            add_products(ap, &xk);
            add_products(aq, &xm);
            let (xk, xm) = recombine(&zp1, &zq1, w1);
            add_products(ap1, &xk);
            add_products(aq1, &xm);
        }
        j += run;
    }
}

/// Item index of recombination pair `t` for [`combine_radix2`] (`t` itself for [`combine`]).
#[inline]
pub(super) const fn fused_item(t: usize) -> usize {
    t.div_ceil(2)
}

/// The bins without a mirror partner: position 0 holds `Z[0]`, giving DC `2X[0] = 2(Re + Im)`
/// and Nyquist `2X[N/2] = 2(Re - Im)` (both real); position 1 holds `Z[M/2]`, giving
/// `2X[N/4] = 2·conj Z[M/2]`. DC's sums take `[Σ|2U|², Σ|2Y|², Σ 2U·2Y, Σ Nyquist 2U·2Y]` (the
/// imaginary cross part of DC is 0, so its slot holds the real Nyquist cross sum); `nyq` takes
/// the Nyquist auto sums.
///
/// With `radix2_first` (`log2 M` odd, final stage fused), positions 0 and 1 still hold the
/// last radix-4 stage's output and their radix-2 butterfly is done here first.
pub(super) fn edge_bins(z: &[Quad], acc: &mut [Quad], nyq: &mut Pair, radix2_first: bool) {
    let (Some(y0), Some(y1)) = (z.first(), z.get(1)) else {
        return;
    };
    let (z0, z1) = if radix2_first {
        radix2(y0, y1)
    } else {
        (*y0, *y1)
    };
    let [a0, a1, ..] = acc else {
        return;
    };
    let (du, dy) = (2.0 * (z0[0] + z0[2]), 2.0 * (z0[1] + z0[3]));
    let (nu, ny) = (2.0 * (z0[0] - z0[2]), 2.0 * (z0[1] - z0[3]));
    a0[0] += du * du;
    a0[1] += dy * dy;
    a0[2] += du * dy;
    a0[3] += nu * ny;
    nyq[0] += nu * nu;
    nyq[1] += ny * ny;
    let x = [2.0 * z1[0], 2.0 * z1[1], -2.0 * z1[2], -2.0 * z1[3]];
    add_products(a1, &x);
}

/// Sample `i` (`< N`) of a bank as `(u, y)`.
#[inline(always)]
pub(super) fn sample<const N: usize>(bank: &[Pair; N], i: usize) -> (f32, f32) {
    let [u, y] = bank[i & (N - 1)];
    (u, y)
}

/// Stores sample `i` (`< N`) of a bank.
#[inline(always)]
pub(super) fn set_sample<const N: usize>(bank: &mut [Pair; N], i: usize, u: f32, y: f32) {
    bank[i & (N - 1)] = [u, y];
}

/// Adds `x - r` for samples `start..end` of `bank` to `sum` in index order, aligned pairs of
/// samples at a time (so the result does not depend on how the range is split into calls: a
/// pair is split only at the range's own odd ends, the same for every segment). `r` is the
/// bank's first sample: summing deviations from it keeps the sums small for signals with an
/// offset, and so the mean accurate.
#[inline(never)]
pub(super) fn sum_range<const N: usize>(
    bank: &[Pair; N],
    start: usize,
    end: usize,
    r: Pair,
    sum: &mut Pair,
) {
    let (mut a, end) = (start, end.min(N));
    if a < end && a % 2 == 1 {
        add_sample(sample(bank, a), r, sum);
        a += 1;
    }
    let whole = (end - a.min(end)) / 2;
    if let Some(qs) = quads(bank).get(a / 2..a / 2 + whole) {
        sum_quads(qs, r, sum);
    }
    a += 2 * whole;
    if a < end {
        add_sample(sample(bank, a), r, sum);
    }
}

/// Adds the deviations from `r` of the two samples of each quad to `sum`, a pair at a time:
/// `sum += (x[2n] + x[2n+1]) - 2r` (one rounding of the pair's sum, then of the deviation).
#[inline(always)]
fn sum_quads(qs: &[Quad], r: Pair, sum: &mut Pair) {
    let r2 = [2.0 * r[0], 2.0 * r[1]];
    for x in qs {
        sum[0] += (x[0] + x[2]) - r2[0];
        sum[1] += (x[1] + x[3]) - r2[1];
    }
}

#[inline(always)]
fn add_sample((u, y): (f32, f32), r: Pair, sum: &mut Pair) {
    sum[0] += u - r[0];
    sum[1] += y - r[1];
}

/// First sample `(u, y)` of a bank, the reference of [`sum_range`].
#[inline(always)]
pub(super) fn first_sample<const N: usize>(bank: &[Pair; N]) -> Pair {
    let (u, y) = sample(bank, 0);
    [u, y]
}

/// Copies samples `start + hop..end + hop` of `old` to `start..end` of `new` (the overlap that
/// the next segment shares) and adds their deviations from `new`'s first sample
/// (`old[hop]`, see [`sum_range`]) to `sum` in index order.
#[inline(never)]
pub(super) fn copy_range<const N: usize>(
    old: &[Pair; N],
    new: &mut [Pair; N],
    hop: usize,
    start: usize,
    end: usize,
    sum: &mut Pair,
) {
    let (u0, y0) = sample(old, hop);
    let r = [u0, y0];
    let mut a = start;
    if hop.is_multiple_of(2) {
        if a < end && a % 2 == 1 {
            copy_one(old, new, hop, a, r, sum);
            a += 1;
        }
        let whole = (end - a.min(end)) / 2;
        let (src, dst) = (quads(old), quads_mut(new));
        let from = (a + hop) / 2;
        if let (Some(s), Some(d)) = (
            src.get(from..from + whole),
            dst.get_mut(a / 2..a / 2 + whole),
        ) {
            let r2 = [2.0 * r[0], 2.0 * r[1]];
            for (x, d) in s.iter().zip(d) {
                *d = *x;
                sum[0] += (x[0] + x[2]) - r2[0];
                sum[1] += (x[1] + x[3]) - r2[1];
            }
        }
        a += 2 * whole;
    }
    while a < end {
        copy_one(old, new, hop, a, r, sum);
        a += 1;
    }
}

/// Copies samples `start + hop..end + hop` of `old` to `start..end` of `new`, four pairs
/// (eight words) per move, without sums (see [`super::schedule::copy_sums`]).
#[inline(never)]
pub(super) fn copy_block<const N: usize>(
    old: &[Pair; N],
    new: &mut [Pair; N],
    hop: usize,
    start: usize,
    end: usize,
) {
    let end = end.min(N.saturating_sub(hop));
    if let (Some(src), Some(dst)) = (old.get(start + hop..end + hop), new.get_mut(start..end)) {
        let (sc, sr) = src.as_chunks::<4>();
        let (dc, dr) = dst.as_chunks_mut::<4>();
        for (s, d) in sc.iter().zip(dc) {
            *d = *s;
        }
        for (s, d) in sr.iter().zip(dr) {
            *d = *s;
        }
    }
}

#[inline(always)]
fn copy_one<const N: usize>(
    old: &[Pair; N],
    new: &mut [Pair; N],
    hop: usize,
    i: usize,
    r: Pair,
    sum: &mut Pair,
) {
    let (u, y) = sample(old, i + hop);
    set_sample(new, i, u, y);
    add_sample((u, y), r, sum);
}

/// The twiddles of radix-4 stage `s` as sixes.
#[inline(always)]
pub(super) fn stage_twiddles<const N: usize>(s: u32) -> &'static [[f32; 6]] {
    let table: &'static [f32; N] = &Tables::<N>::FFT;
    let (sixes, _) = table.as_chunks::<6>();
    sixes.get(Tables::<N>::stage_offset(s)..).unwrap_or(&[])
}

/// The recombination twiddles as pairs.
#[inline(always)]
pub(super) fn combine_twiddles<const N: usize>() -> &'static [Pair] {
    let table: &'static [f32; N] = &Tables::<N>::COMBINE;
    table.as_chunks::<2>().0
}
