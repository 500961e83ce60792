//! `decimal::parse_f32` against std's correctly rounded `str::parse::<f32>` (independent
//! reference): within 1 ulp on fixed and random decimal strings, the same accept/reject
//! decision on malformed text, and no panic on arbitrary bytes.
use ferrosid_firmware::decimal::parse_f32;
use ferrosid_firmware::rng::SplitMix64;

/// Distance in units in the last place between two finite f32 of the same sign (or zeros).
fn ulps(a: f32, b: f32) -> u32 {
    if a == b {
        return 0;
    }
    assert_eq!(a.is_sign_negative(), b.is_sign_negative(), "{a} vs {b}");
    a.to_bits().abs_diff(b.to_bits())
}

fn check(s: &str) {
    let want: f32 = s
        .parse()
        .unwrap_or_else(|e| panic!("reference rejects {s:?}: {e}"));
    let got = parse_f32(s).unwrap_or_else(|| panic!("rejected {s:?}"));
    assert!(ulps(got, want) <= 1, "{s:?}: {got:e} vs {want:e}");
}

#[test]
fn configuration_values_parse_within_one_ulp() {
    for s in [
        "0",
        "-0",
        "+0.0",
        "1",
        "-1",
        "1.3",
        "0.0001",
        "0.0031415927",
        "2.467401",
        "1e-3",
        "1e-7",
        "1E-7",
        "0.001",
        "1.0",
        ".5",
        "5.",
        "-2.5e+2",
        "3.4028234e38",
        "1.17549435e-38",
        "1e-45",
        "123456789012345678901234567890",
        "0.000000000000000000000000000000123",
        "9999999999999999999",
        "99999999999999999999.5",
        "16777217",
        "0.1",
        "0.2",
        "0.3",
    ] {
        check(s);
    }
}

#[test]
fn random_decimals_parse_within_one_ulp() {
    // Seeded SplitMix64: mantissas of 1..=20 digits with the point anywhere, exponents ±40.
    let mut rng = SplitMix64::new(0x5EED);
    let mut next = move || rng.next_u64();
    let mut checked = 0;
    for _ in 0..20_000 {
        let nd = 1 + (next() % 20) as usize;
        let mut digits: String = (0..nd)
            .map(|_| char::from(b'0' + (next() % 10) as u8))
            .collect();
        let point = (next() % (nd as u64 + 1)) as usize;
        digits.insert(point, '.');
        if digits == "." {
            continue;
        }
        let e = (next() % 81) as i64 - 40;
        let s = if next() % 2 == 0 {
            format!("{digits}e{e}")
        } else {
            digits.clone()
        };
        let want: f32 = s.parse().unwrap();
        if !want.is_finite() {
            assert_eq!(parse_f32(&s), None, "{s:?} overflows f32");
            continue;
        }
        check(&s);
        checked += 1;
    }
    assert!(checked > 19_000, "{checked}");
}

#[test]
fn malformed_text_and_overflow_are_rejected() {
    for s in [
        "", "-", "+", ".", "e5", "1e", "1e+", "1.2.3", "nan", "NaN", "inf", "-inf", "1,5", " 1",
        "1 ", "0x10", "1e1000", "1e39", "-1e39", "abc", "1e5x", "--1", "1e--1",
    ] {
        assert_eq!(parse_f32(s), None, "{s:?} must be rejected");
    }
}

#[test]
fn arbitrary_bytes_never_panic() {
    let alphabet = b"0123456789.eE+-x ";
    let mut rng = SplitMix64::new(7);
    for _ in 0..50_000 {
        let x = rng.next_u64();
        let len = (x % 12) as usize;
        let s: String = (0..len)
            .map(|k| char::from(alphabet[((x >> (4 * k)) % alphabet.len() as u64) as usize]))
            .collect();
        let ours = parse_f32(&s);
        // Whatever we accept, std accepts too and agrees to 1 ulp.
        if let Some(v) = ours {
            let want: f32 = s
                .parse()
                .unwrap_or_else(|e| panic!("{s:?} accepted, std: {e}"));
            assert!(ulps(v, want) <= 1, "{s:?}");
        }
    }
}
