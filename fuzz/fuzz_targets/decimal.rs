//! The firmware's decimal parser: never panics, and agrees with the standard library on
//! everything it accepts (within f32 rounding of a decimal with at most 9 significant digits).
#![no_main]
use ferrosid_firmware::decimal::parse_f32;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(s) = std::str::from_utf8(data) {
        if let Some(v) = parse_f32(s) {
            if let Ok(r) = s.trim().parse::<f64>() {
                if v.is_finite() && r.is_finite() && r.abs() < 1e30 && r.abs() > 1e-30 {
                    let rel = ((v as f64 - r) / r).abs();
                    assert!(rel < 1e-5, "parse_f32({s:?}) = {v}, std says {r}");
                }
            }
        }
    }
});
