//! ferrosid's side of the peer benchmark (bench/peers/run.sh): times N4SID and Welch H1 with
//! coherence in-process on a CSV log and writes the results as JSON for bench/peers/compare.py.
//!
//! `cargo run --release -p ferrosid --example peer_bench -- LOG.csv OUT.json [REPEATS]`
//!
//! * N4SID: i = 20 block rows, order fixed to 3 (the same job as SLICOT's
//!   `n4sid(dat, 3, 's', 20)` in Octave), D, x0 and the Kalman gain estimated (defaults); and
//!   the same with automatic order selection, and with D fixed to zero (the true plant's
//!   structure: a ZOH-sampled strictly proper plant has D = 0).
//! * Welch: nperseg 1024, Hann, 50 % overlap, constant detrend — H1 and coherence from one pass
//!   over the data (`Welch::etfe`).
//!
//! Each timing is the best of REPEATS (default 5) wall-clock runs, excluding file reading and
//! process start-up.
use ferrosid::io::{read_csv, CsvOptions};
use ferrosid::lti::StateSpaceData;
use ferrosid::n4sid::{n4sid_slices, N4sidOptions, OrderSelection};
use ferrosid::spectral::Welch;
use serde::Serialize;
use std::time::Instant;

#[derive(Serialize)]
struct WelchOut {
    nperseg: usize,
    freq_hz: Vec<f64>,
    h_re: Vec<f64>,
    h_im: Vec<f64>,
    coherence: Vec<f64>,
}

#[derive(Serialize)]
struct Out {
    tool: &'static str,
    repeats: usize,
    samples: usize,
    n4sid_order3_seconds: f64,
    n4sid_auto_seconds: f64,
    n4sid_no_d_seconds: f64,
    auto_order: usize,
    welch_seconds: f64,
    model: StateSpaceData,
    model_auto: StateSpaceData,
    model_no_d: StateSpaceData,
    welch: WelchOut,
}

fn best_of<T>(repeats: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let t = Instant::now();
    let mut last = f();
    let mut best = t.elapsed().as_secs_f64();
    for _ in 1..repeats {
        let t = Instant::now();
        last = f();
        best = best.min(t.elapsed().as_secs_f64());
    }
    (best, last)
}

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: peer_bench LOG.csv OUT.json [REPEATS]".into());
    }
    let repeats: usize = args.get(3).map_or(Ok(5), |r| r.parse())?;
    let log = read_csv(std::path::Path::new(&args[1]), &CsvOptions::default())?;
    let (u, y, ts) = (log.u(), log.y(), log.ts);

    let fixed = N4sidOptions {
        block_rows: 20,
        order: OrderSelection::Fixed(3),
        ..N4sidOptions::default()
    };
    let (t3, r3) = best_of(repeats, || n4sid_slices(ts, &[u], &[y], &fixed));
    let r3 = r3?;
    let auto = N4sidOptions {
        block_rows: 20,
        ..N4sidOptions::default()
    };
    let (ta, ra) = best_of(repeats, || n4sid_slices(ts, &[u], &[y], &auto));
    let ra = ra?;
    let no_d = N4sidOptions {
        estimate_d: false,
        ..fixed.clone()
    };
    let (tn, rn) = best_of(repeats, || n4sid_slices(ts, &[u], &[y], &no_d));
    let rn = rn?;
    let welch = Welch::new(1024);
    let (tw, e) = best_of(repeats * 4, || welch.etfe(u, y, 1.0 / ts));
    let e = e?;
    let out = Out {
        tool: "ferrosid",
        repeats,
        samples: u.len(),
        n4sid_order3_seconds: t3,
        n4sid_auto_seconds: ta,
        n4sid_no_d_seconds: tn,
        auto_order: ra.order,
        welch_seconds: tw,
        model: StateSpaceData::from(&r3.model),
        model_auto: StateSpaceData::from(&ra.model),
        model_no_d: StateSpaceData::from(&rn.model),
        welch: WelchOut {
            nperseg: e.nperseg,
            freq_hz: e.freq_hz.clone(),
            h_re: e.h.iter().map(|z| z.re).collect(),
            h_im: e.h.iter().map(|z| z.im).collect(),
            coherence: e.coherence.clone(),
        },
    };
    std::fs::write(&args[2], serde_json::to_string(&out)?)?;
    eprintln!(
        "ferrosid: n4sid(3) {:.4} s, n4sid(auto -> {}) {:.4} s, welch {:.5} s",
        t3, ra.order, ta, tw
    );
    Ok(())
}
