//! `frf` and `identify` on arbitrary short signals: the bytes are read as (u, y) f64 pairs
//! (up to 512 samples, any values including 1e±300), sample time from the first byte.
#![no_main]
use ferrosid::cli::frf::{estimate, EtfeArgs};
use ferrosid::n4sid::{n4sid, N4sidOptions};
use ferrosid::{Channel, Log};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if data.len() < 1 + 16 * 8 {
        return;
    }
    let ts = [1e-3, 1e-300, 1.0, 1e300][(data[0] % 4) as usize];
    let mut u = Vec::new();
    let mut y = Vec::new();
    for c in data[1..].chunks_exact(16).take(512) {
        let a = f64::from_le_bytes(c[..8].try_into().unwrap());
        let b = f64::from_le_bytes(c[8..].try_into().unwrap());
        if !(a.is_finite() && b.is_finite()) {
            return;
        }
        u.push(a);
        y.push(b);
    }
    let log = Log {
        path: "fuzz.csv".into(),
        ts,
        inputs: vec![Channel {
            name: "u".into(),
            data: u,
        }],
        outputs: vec![Channel {
            name: "y".into(),
            data: y,
        }],
        warnings: Vec::new(),
    };
    let etfe = EtfeArgs {
        nperseg: "auto".into(),
        overlap: None,
        window: ferrosid::cli::frf::WindowArg::Hann,
        detrend: ferrosid::cli::frf::DetrendArg::Constant,
        period: None,
        skip_periods: 0,
        gate: 0.85,
    };
    if let Ok(r) = estimate(std::slice::from_ref(&log), &etfe) {
        for e in &r.estimates {
            assert!(e.coherence.iter().all(|c| (0.0..=1.0).contains(c) || c.is_nan()));
        }
    }
    let opts = N4sidOptions {
        block_rows: 4,
        ..N4sidOptions::default()
    };
    let _ = n4sid(&log, &opts);
});
