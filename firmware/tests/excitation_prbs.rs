//! PRBS: period exactly 2^n - 1 (brute force for n = 5..=20; for all n = 5..=31 by proving
//! the implemented state-transition matrix has multiplicative order 2^n - 1), the cited tap table
//! is primitive, balance, and the spectrum of one period against the closed form of an
//! m-sequence with hold.

use ferrosid_firmware::excitation::Prbs;
use ferrosid_firmware::{Error, Excitation};

#[test]
fn period_is_exactly_2_pow_n_minus_1_for_n_5_to_20() {
    for n in 5u8..=20 {
        let mut p = Prbs::new(n, 1, 1.0, 1).unwrap();
        let start = p.state();
        let full = (1u64 << n) - 1;
        let mut steps = 0u64;
        loop {
            p.next_chip();
            steps += 1;
            assert_ne!(p.state(), 0, "n={n}: lock-up state reached");
            assert!(p.state() < (1 << n), "n={n}: state left the register");
            if p.state() == start || steps > full {
                break;
            }
        }
        assert_eq!(steps, full, "n={n}");
        assert_eq!(u64::from(p.period_chips()), full);
    }
}

/// Prime factors of m (trial division; m < 2^31).
fn prime_factors(mut m: u64) -> Vec<u64> {
    let mut f = Vec::new();
    let mut d = 2;
    while d * d <= m {
        if m.is_multiple_of(d) {
            f.push(d);
            while m.is_multiple_of(d) {
                m /= d;
            }
        }
        d += 1;
    }
    if m > 1 {
        f.push(m);
    }
    f
}

/// GF(2) n×n matrix as columns (bit i of col j = entry (i, j)).
#[derive(Clone, PartialEq, Debug)]
struct Gf2Mat(Vec<u32>);

impl Gf2Mat {
    fn identity(n: usize) -> Self {
        Gf2Mat((0..n).map(|i| 1u32 << i).collect())
    }
    fn apply(&self, v: u32) -> u32 {
        self.0
            .iter()
            .enumerate()
            .filter(|(i, _)| v >> i & 1 == 1)
            .fold(0, |acc, (_, c)| acc ^ c)
    }
    fn mul(&self, b: &Gf2Mat) -> Gf2Mat {
        Gf2Mat(b.0.iter().map(|&c| self.apply(c)).collect())
    }
    fn pow(&self, mut e: u64) -> Gf2Mat {
        let mut base = self.clone();
        let mut acc = Gf2Mat::identity(self.0.len());
        while e > 0 {
            if e & 1 == 1 {
                acc = acc.mul(&base);
            }
            base = base.mul(&base);
            e >>= 1;
        }
        acc
    }
}

#[test]
fn implemented_register_has_order_2_pow_n_minus_1_for_n_5_to_31() {
    // The LFSR step is linear over GF(2): read its matrix off the implementation (one step
    // from each unit state), then check M^(2^n-1) = I and M^((2^n-1)/q) != I for every prime
    // q | 2^n - 1. Hence every non-zero state has period exactly 2^n - 1 — for n = 31 too,
    // without stepping 2^31 times.
    for n in 5u8..=31 {
        let cols: Vec<u32> = (0..n)
            .map(|i| {
                let mut p = Prbs::new(n, 1 << i, 1.0, 1).unwrap();
                p.next_chip();
                p.state()
            })
            .collect();
        let m = Gf2Mat(cols);
        let order = (1u64 << n) - 1;
        let id = Gf2Mat::identity(n as usize);
        assert_eq!(m.pow(order), id, "n={n}: M^(2^n-1) != I");
        for q in prime_factors(order) {
            assert_ne!(m.pow(order / q), id, "n={n}: order divides (2^n-1)/{q}");
        }
    }
}

/// x^e mod p over GF(2), p of degree n <= 31 given as a bit mask including x^n.
fn polmod_pow_x(e: u64, p: u64, n: u32) -> u64 {
    let mulmod = |a: u64, b: u64| {
        let mut r = 0u64;
        for i in 0..n {
            if b >> i & 1 == 1 {
                r ^= a << i;
            }
        }
        for i in (n..2 * n).rev() {
            if r >> i & 1 == 1 {
                r ^= p << (i - n);
            }
        }
        r
    };
    let (mut acc, mut base, mut e) = (1u64, 2u64 % p, e);
    while e > 0 {
        if e & 1 == 1 {
            acc = mulmod(acc, base);
        }
        base = mulmod(base, base);
        e >>= 1;
    }
    acc
}

#[test]
fn taps_are_primitive() {
    // The cited XAPP052 table: x^n + Σ x^t + 1 must be primitive (x has order 2^n - 1).
    for n in 5u8..=31 {
        let taps = ferrosid_firmware::excitation::prbs_taps(n).unwrap();
        let mut p = 1u64; // constant term
        for &t in taps {
            p |= 1 << t;
        }
        let order = (1u64 << n) - 1;
        assert_eq!(polmod_pow_x(order, p, n as u32), 1, "n={n}");
        for q in prime_factors(order) {
            assert_ne!(polmod_pow_x(order / q, p, n as u32), 1, "n={n}, q={q}");
        }
    }
}

#[test]
fn balance_one_more_plus_than_minus_per_period() {
    for n in 5u8..=16 {
        let a = 0.25f32;
        let mut p = Prbs::new(n, 0b10101 & ((1 << n) - 1), a, 1).unwrap();
        let period = p.period_samples() as usize;
        let plus = (0..period).filter(|_| p.next_sample() == a).count();
        assert_eq!(plus, 1 << (n - 1), "n={n}");
        assert_eq!(period - plus, (1 << (n - 1)) - 1);
    }
}

fn dft_power(x: &[f64]) -> Vec<f64> {
    let l = x.len();
    (0..l)
        .map(|k| {
            let (mut re, mut im) = (0.0, 0.0);
            for (n, &v) in x.iter().enumerate() {
                let a = -2.0 * std::f64::consts::PI * ((k * n) % l) as f64 / l as f64;
                re += v * a.cos();
                im += v * a.sin();
            }
            re * re + im * im
        })
        .collect()
}

#[test]
fn spectrum_of_one_period_is_flat_with_hold_nulls() {
    // m-sequence of period P, levels ±a: |X[k]|² = (P+1)a² (k ≠ 0), |X[0]|² = a².
    // Hold h: X_h[k] = X[k mod P]·D(k), |D(k)| = |sin(πk/P) / sin(πk/(Ph))|, so |X_h|² is zero
    // at every non-zero multiple of P (the chip-rate nulls).
    let (n, a) = (7u8, 0.5f64);
    let pp = 127usize;
    for hold in [1u32, 3] {
        let mut g = Prbs::new(n, 77, a as f32, hold).unwrap();
        let len = g.period_samples() as usize;
        assert_eq!(len, pp * hold as usize);
        let x: Vec<f64> = (0..len).map(|_| g.next_sample() as f64).collect();
        let pw = dft_power(&x);
        let h = hold as f64;
        let peak = pw.iter().cloned().fold(0.0, f64::max);
        for (k, &p) in pw.iter().enumerate() {
            let base = if k % pp == 0 {
                a * a
            } else {
                (pp as f64 + 1.0) * a * a
            };
            let d2 = if k == 0 {
                h * h
            } else {
                let num = (std::f64::consts::PI * k as f64 / pp as f64).sin();
                let den = (std::f64::consts::PI * k as f64 / (pp as f64 * h)).sin();
                (num / den).powi(2)
            };
            let expect = base * d2;
            if k % pp == 0 && k != 0 {
                assert!(
                    p / peak < 1e-10,
                    "hold={hold} k={k}: null at {:.1} dB",
                    10.0 * (p / peak).log10()
                );
            } else {
                assert!(
                    (p - expect).abs() <= 1e-9 * peak,
                    "hold={hold} k={k}: {p} vs {expect}"
                );
            }
        }
    }
}

#[test]
fn invalid_arguments_are_rejected() {
    assert_eq!(
        Prbs::new(4, 1, 1.0, 1).err(),
        Some(Error::InvalidRegisterLength { bits: 4 })
    );
    assert_eq!(
        Prbs::new(32, 1, 1.0, 1).err(),
        Some(Error::InvalidRegisterLength { bits: 32 })
    );
    assert_eq!(
        Prbs::new(0, 1, 1.0, 1).err(),
        Some(Error::InvalidRegisterLength { bits: 0 })
    );
    assert_eq!(Prbs::new(5, 0, 1.0, 1).err(), Some(Error::InvalidSeed));
    assert_eq!(Prbs::new(5, 32, 1.0, 1).err(), Some(Error::InvalidSeed));
    assert!(Prbs::new(5, 31, 1.0, 1).is_ok());
    assert!(Prbs::new(31, 0x7FFF_FFFF, 1.0, 1).is_ok());
    assert_eq!(
        Prbs::new(31, 0x8000_0000, 1.0, 1).err(),
        Some(Error::InvalidSeed)
    );
    for a in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        assert_eq!(Prbs::new(9, 1, a, 1).err(), Some(Error::InvalidAmplitude));
    }
    assert_eq!(Prbs::new(9, 1, 1.0, 0).err(), Some(Error::InvalidHold));
    let p = Prbs::new(31, 1, 1.0, u32::MAX).unwrap();
    assert_eq!(p.period_samples(), ((1u64 << 31) - 1) * u64::from(u32::MAX));
}

#[test]
fn reset_repeats_the_sequence() {
    let mut p = Prbs::new(11, 123, 2.0, 2).unwrap();
    let a: Vec<f32> = (0..500).map(|_| p.next_sample()).collect();
    p.reset();
    let b: Vec<f32> = (0..500).map(|_| p.next_sample()).collect();
    assert_eq!(a, b);
}
