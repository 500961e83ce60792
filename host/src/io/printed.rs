//! Rounding of time stamps as printed in a text log, and the test that rounded stamps still
//! describe a uniform sampling grid (the "printed rounding" rule of the [`super`] module docs).
//!
//! **Rounding of a column.** A stamp printed as `d.ddd…×10^e` carries `s` significant digits
//! and its last digit sits at place `p = e − s + 1`. Writers print a column in one of three
//! ways, and the rounding `r_k` of stamp `k` follows from the column as a whole:
//! * a fixed number of significant digits (`%.8e`, `%.9g`, MATLAB's `%.5g`; `%g` drops trailing
//!   zeros, so stamps may show fewer): `S` = the most significant digits of any stamp, and
//!   `r_k = ½·10^(e_k − S + 1)`;
//! * a fixed number of decimals (`%.6f`): `r_k = ½·10^(p_min)` with `p_min` the finest place
//!   printed in the column;
//! * the shortest text that reads back to the same double (Rust `{}`, Python `repr`): such
//!   columns show 16–17 significant digits somewhere, so `S > 15` marks them as exact (`r = 0`).
//!
//! `r_k` is the larger of the first two (each is at most the true rounding of its format), and
//! a stamp equal to zero is exact. Any stamp that is not a plain decimal (e.g. `inf`, hex) makes
//! the whole column exact (no rounding is credited).
//!
//! **Uniform grid within the rounding.** The stamps describe a uniform sampling when some
//! `(a, T)` satisfies `|t_k − a − k T| ≤ w_k` for every `k`, with
//! `w_k = min(r_k, MAX_PRINTED_ROUNDING_REL·T̄) + tol_rel·T̄ + 64 ε max(|t_k|, T̄)` and `T̄` the
//! mean interval. For a fixed `T` the feasible offsets form the interval
//! `[max_k(t_k − kT − w_k), min_k(t_k − kT + w_k)]`, whose width is a concave function of `T`;
//! a golden-section search over `T` decides feasibility (O(n) per step, 100 steps).

use super::MAX_PRINTED_ROUNDING_REL;

/// How one number was printed: significant digits and the decimal place of its last digit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Printed {
    /// Significant digits (0 for a zero value).
    sig: i32,
    /// Decimal exponent of the last printed digit (`12.345` → −3).
    last_place: i32,
}

impl Printed {
    /// Reads the printed form of a plain decimal (`[+-]digits[.digits][e[+-]digits]`); `None`
    /// for anything else.
    pub(crate) fn parse(text: &str) -> Option<Printed> {
        let s = text.trim();
        let s = s.strip_prefix(['+', '-']).unwrap_or(s);
        let (mantissa, exp) = match s.find(['e', 'E']) {
            Some(i) => (&s[..i], s[i + 1..].parse::<i32>().ok()?),
            None => (s, 0),
        };
        let (int, frac) = mantissa.split_once('.').unwrap_or((mantissa, ""));
        let digits_ok = |d: &str| d.bytes().all(|b| b.is_ascii_digit());
        if !(digits_ok(int) && digits_ok(frac)) || int.len() + frac.len() == 0 {
            return None;
        }
        let all: String = [int, frac].concat();
        let sig = all.trim_start_matches('0').len() as i32;
        let last_place = exp.checked_sub(i32::try_from(frac.len()).ok()?)?;
        Some(Printed { sig, last_place })
    }

    /// Decimal exponent of the leading significant digit (`None` for zero).
    fn lead_place(&self) -> Option<i32> {
        (self.sig > 0).then(|| self.last_place + self.sig - 1)
    }
}

/// Significant digits beyond which a column is taken as the exact decimal text of doubles.
const EXACT_SIG_DIGITS: i32 = 15;

/// Rounding `r_k` (s) of each stamp of a column (rules in the module docs), `scale` s per
/// unit. Empty when the column earns no rounding credit (not all plain decimals, or printed
/// exactly).
pub(crate) fn column_rounding(printed: &[Option<Printed>], scale: f64) -> Vec<f64> {
    let Some(cols) = printed.iter().copied().collect::<Option<Vec<Printed>>>() else {
        return Vec::new();
    };
    let max_sig = cols.iter().map(|p| p.sig).max().unwrap_or(0);
    if max_sig == 0 || max_sig > EXACT_SIG_DIGITS {
        return Vec::new();
    }
    let finest = cols.iter().map(|p| p.last_place).min().unwrap_or(0);
    let half_unit = |place: i32| 0.5 * 10f64.powi(place) * scale;
    cols.iter()
        .map(|p| match p.lead_place() {
            None => 0.0,
            Some(lead) => half_unit(lead - max_sig + 1).max(half_unit(finest)),
        })
        .collect()
}

/// Whether some uniform grid passes within each stamp's rounding (module docs); `mean` is the
/// mean interval (s), `rounding` from [`column_rounding`] (empty → `false`).
pub(crate) fn on_uniform_grid(t: &[f64], rounding: &[f64], mean: f64, tol_rel: f64) -> bool {
    let n = t.len();
    if rounding.len() != n || n < 2 || !(mean.is_finite() && mean > 0.0) {
        return false;
    }
    let w: Vec<f64> = t
        .iter()
        .zip(rounding)
        .map(|(&tk, &rk)| {
            rk.min(MAX_PRINTED_ROUNDING_REL * mean)
                + tol_rel * mean
                + 64.0 * f64::EPSILON * tk.abs().max(mean)
        })
        .collect();
    // Width of the feasible offset interval for interval T (concave in T).
    let width = |tt: f64| -> f64 {
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for (k, (&tk, &wk)) in t.iter().zip(&w).enumerate() {
            let c = tk - k as f64 * tt;
            lo = lo.max(c - wk);
            hi = hi.min(c + wk);
        }
        hi - lo
    };
    // Any feasible T lies within (w_0 + w_last)/(n-1) of the mean interval.
    let span = (w[0] + w[n - 1]) / (n - 1) as f64;
    let (mut a, mut b) = (mean - span, mean + span);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut f1, mut f2) = (width(x1), width(x2));
    for _ in 0..100 {
        if f1.max(f2) >= 0.0 {
            return true;
        }
        if f1 < f2 {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = width(x2);
        } else {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = width(x1);
        }
    }
    f1.max(f2) >= 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> Printed {
        Printed::parse(s).unwrap()
    }

    #[test]
    fn digits_and_last_place() {
        assert_eq!(
            p("12.345"),
            Printed {
                sig: 5,
                last_place: -3
            }
        );
        assert_eq!(
            p("-0.000125"),
            Printed {
                sig: 3,
                last_place: -6
            }
        );
        assert_eq!(
            p("1.5e-3"),
            Printed {
                sig: 2,
                last_place: -4
            }
        );
        assert_eq!(
            p("1000"),
            Printed {
                sig: 4,
                last_place: 0
            }
        );
        assert_eq!(
            p("0"),
            Printed {
                sig: 0,
                last_place: 0
            }
        );
        for bad in ["nan", "inf", "0x10", ".", "1e", "", "1.2.3"] {
            assert_eq!(Printed::parse(bad), None, "{bad}");
        }
    }

    #[test]
    fn column_formats() {
        // %.4e: 5 significant digits everywhere.
        let r = column_rounding(&[Some(p("1.0000e-04")), Some(p("1.3333e+00"))], 1.0);
        assert!(
            (r[0] - 5e-9).abs() < 1e-20 && (r[1] - 5e-5).abs() < 1e-16,
            "{r:?}"
        );
        // %g drops trailing zeros: "1" in a 5-digit column still carries 5 digits.
        let r = column_rounding(&[Some(p("1")), Some(p("1.2345"))], 1.0);
        assert!((r[0] - 5e-5).abs() < 1e-16, "{r:?}");
        // %.6f: the finest place bounds every stamp.
        let r = column_rounding(&[Some(p("0.000100")), Some(p("1000.000100"))], 1.0);
        assert!(r.iter().all(|&x| (x - 5e-7).abs() < 1e-18), "{r:?}");
        // Shortest repr of doubles (17 digits somewhere): exact.
        assert!(column_rounding(&[Some(p("0.1")), Some(p("0.30000000000000004"))], 1.0).is_empty());
        // One non-decimal stamp: no credit.
        assert!(column_rounding(&[Some(p("0.1")), None], 1.0).is_empty());
        // Zero is exact; the scale converts units to seconds.
        let r = column_rounding(&[Some(p("0")), Some(p("100"))], 1e-6);
        assert!(r[0] == 0.0 && (r[1] - 5e-7).abs() < 1e-18, "{r:?}");
    }

    #[test]
    fn grid_feasibility() {
        // 4 decimals of k/3: on a grid within ±5e-5 — feasible; a stamp 2e-4 off is not.
        let t: Vec<f64> = (0..50)
            .map(|k| (k as f64 / 3.0 * 1e4).round() / 1e4)
            .collect();
        let r = vec![5e-5; t.len()];
        let mean = (t[49] - t[0]) / 49.0;
        assert!(on_uniform_grid(&t, &r, mean, 1e-6));
        let mut bad = t.clone();
        bad[20] += 2e-4;
        assert!(!on_uniform_grid(&bad, &r, mean, 1e-6));
        // Without rounding credit nothing is accepted.
        assert!(!on_uniform_grid(&t, &[], mean, 1e-6));
    }
}
