//! Real FFT dispatch onto `microfft`, and a real-signal synthesis from a Hermitian spectrum.
//!
//! `microfft` provides one function per size (`rfft_64` .. `rfft_4096`) on fixed-size arrays.
//! [`rfft`] selects it from the const generic `N` (folded at compile time) and converts the
//! buffer with `try_from` (no `unwrap`). The crate's const checks restrict `N` to powers of two
//! in `64..=4096`, for which the conversion cannot fail; an unsupported `N` would give an empty
//! spectrum rather than a panic.

use microfft::Complex32;

/// Smallest supported transform / segment length.
pub const MIN_LEN: usize = 64;
/// Largest supported transform / segment length (needs microfft feature `size-4096`).
pub const MAX_LEN: usize = 4096;

/// `true` when `n` is a supported FFT length: a power of two in `64..=4096`.
pub const fn is_supported_len(n: usize) -> bool {
    n.is_power_of_two() && n >= MIN_LEN && n <= MAX_LEN
}

macro_rules! dispatch {
    ($buf:ident; $($n:literal => $f:ident),* $(,)?) => {
        match N {
            $(
                $n => match <&mut [f32; $n]>::try_from(&mut $buf[..]) {
                    Ok(a) => &mut microfft::real::$f(a)[..],
                    Err(_) => &mut [],
                },
            )*
            _ => &mut [],
        }
    };
}

/// In-place real FFT `X[k] = Σ_n x[n] e^{-j2πkn/N}` of `buf`.
///
/// Returns the `N/2` complex bins `k = 0..N/2-1` stored in `buf`, with microfft's packing: the
/// real DC value in `[0].re` and the real Nyquist value `X[N/2]` in `[0].im`. Unscaled.
#[inline]
pub fn rfft<const N: usize>(buf: &mut [f32; N]) -> &mut [Complex32] {
    dispatch!(buf;
        64 => rfft_64, 128 => rfft_128, 256 => rfft_256, 512 => rfft_512,
        1024 => rfft_1024, 2048 => rfft_2048, 4096 => rfft_4096)
}

/// Adds the line `X[k] = re + j·im` (and its mirror `X[N-k] = conj(X[k])`) to a spectrum held
/// in Hartley packing `g[k] = Re X[k] + Im X[k]`, `g[N-k] = Re X[k] - Im X[k]`, as consumed by
/// [`synthesize`]. `k` must be in `1..N/2`; other `k` are ignored.
#[inline]
pub fn add_line<const N: usize>(g: &mut [f32; N], k: usize, re: f32, im: f32) {
    if k == 0 || k >= N / 2 {
        return;
    }
    if let Some(v) = g.get_mut(k) {
        *v += re + im;
    }
    if let Some(v) = g.get_mut(N - k) {
        *v += re - im;
    }
}

/// Real signal from a Hermitian spectrum: `x[n] = (1/N) Σ_k X[k] e^{+j2πkn/N}`.
///
/// `g` holds the spectrum in Hartley packing (see [`add_line`]) and is destroyed (it is the FFT
/// workspace); the signal is written to `x`. Why it works: with `A = Re X` (even in `k`) and
/// `B = Im X` (odd), the forward FFT of the real sequence `g = A + B` is
/// `R[n] = Σ A cos(2πkn/N) - j Σ B sin(2πkn/N)`, and `N·x[n] = Σ A cos - Σ B sin
/// = Re R[n] + Im R[n]`; `R[N-n] = conj(R[n])` gives the second half. One real FFT of size `N`.
pub fn synthesize<const N: usize>(g: &mut [f32; N], x: &mut [f32; N]) {
    let inv_n = 1.0 / N as f32;
    let r = rfft(g);
    let Some(r0) = r.first().copied() else {
        return;
    };
    // DC and Nyquist are real and packed into r[0].
    if let Some(v) = x.get_mut(0) {
        *v = r0.re * inv_n;
    }
    if let Some(v) = x.get_mut(N / 2) {
        *v = r0.im * inv_n;
    }
    let (front, back) = x.split_at_mut(N / 2);
    // front[n] for n in 1..N/2, back[N/2 - n] = x[N - n].
    // `back` is x[N/2..N]; reversed, its element j-1 is x[N-j], paired with r[j] and x[j].
    for ((rn, xf), xb) in r
        .iter()
        .skip(1)
        .zip(front.iter_mut().skip(1))
        .zip(back.iter_mut().rev())
    {
        *xf = (rn.re + rn.im) * inv_n;
        *xb = (rn.re - rn.im) * inv_n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rfft_matches_direct_dft() {
        // Reference: direct f64 DFT. Tolerance 1e-5 of the spectrum's peak magnitude.
        let mut buf = [0.0f32; 256];
        for (n, v) in buf.iter_mut().enumerate() {
            *v = ((n * 37 % 101) as f32 - 50.0) / 50.0;
        }
        let x: Vec<f64> = buf.iter().map(|&v| v as f64).collect();
        let spec = rfft(&mut buf);
        assert_eq!(spec.len(), 128);
        for k in 0..=128usize {
            let (mut re, mut im) = (0.0f64, 0.0f64);
            for (n, &v) in x.iter().enumerate() {
                let a = -2.0 * std::f64::consts::PI * (k * n) as f64 / 256.0;
                re += v * a.cos();
                im += v * a.sin();
            }
            let (gr, gi) = match k {
                0 => (spec[0].re as f64, 0.0),
                128 => (spec[0].im as f64, 0.0),
                _ => (spec[k].re as f64, spec[k].im as f64),
            };
            assert!((gr - re).abs() < 1e-3 && (gi - im).abs() < 1e-3, "k={k}");
        }
    }

    /// Every supported size against a direct f64 DFT (catches a wrong microfft feature: with
    /// "size-2048", rfft_4096 indexes past its twiddle table and panics).
    #[test]
    fn rfft_every_size_matches_direct_dft() {
        fn check<const N: usize>() {
            let mut buf = [0.0f32; N];
            for (n, v) in buf.iter_mut().enumerate() {
                *v = ((n * 7919 % 1009) as f32 - 504.0) / 504.0;
            }
            let x: Vec<f64> = buf.iter().map(|&v| v as f64).collect();
            let spec = rfft(&mut buf);
            assert_eq!(spec.len(), N / 2);
            for k in [0usize, 1, 3, N / 4 + 1, N / 2 - 1, N / 2] {
                let (mut re, mut im) = (0.0f64, 0.0f64);
                for (n, &v) in x.iter().enumerate() {
                    let a = -2.0 * std::f64::consts::PI * ((k * n) % N) as f64 / N as f64;
                    re += v * a.cos();
                    im += v * a.sin();
                }
                let (gr, gi) = match k {
                    0 => (spec[0].re as f64, 0.0),
                    k if k == N / 2 => (spec[0].im as f64, 0.0),
                    _ => (spec[k].re as f64, spec[k].im as f64),
                };
                let tol = 1e-5 * N as f64;
                assert!(
                    (gr - re).abs() < tol && (gi - im).abs() < tol,
                    "N={N} k={k}"
                );
            }
        }
        check::<64>();
        check::<128>();
        check::<256>();
        check::<512>();
        check::<1024>();
        check::<2048>();
        check::<4096>();
    }

    #[test]
    fn synthesize_matches_direct_inverse() {
        // Reference: direct f64 sum of cosines. Tolerance 1e-6 absolute (amplitudes ~1).
        const N: usize = 128;
        let lines = [
            (1usize, 0.3f32, -0.7f32),
            (5, 1.0, 0.0),
            (17, -0.2, 0.4),
            (63, 0.0, 1.0),
        ];
        let mut g = [0.0f32; N];
        for &(k, re, im) in &lines {
            add_line(&mut g, k, re * N as f32 / 2.0, im * N as f32 / 2.0);
        }
        let mut x = [0.0f32; N];
        synthesize(&mut g, &mut x);
        for (n, &v) in x.iter().enumerate() {
            // X[k] = (N/2)(re + j im) ⇒ x[n] = re cos(θ) - im sin(θ), θ = 2πkn/N.
            let e: f64 = lines
                .iter()
                .map(|&(k, re, im)| {
                    let t = 2.0 * std::f64::consts::PI * (k * n) as f64 / N as f64;
                    re as f64 * t.cos() - im as f64 * t.sin()
                })
                .sum();
            assert!((v as f64 - e).abs() < 1e-6, "n={n}: {v} vs {e}");
        }
    }
}
