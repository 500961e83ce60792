//! Monte Carlo study of closed-loop identification on an unstable plant (issue 13): is the
//! joint input-output method's residual FRF error bias or variance?
//!
//! Plant G(s) = 20/(s − 2) sampled exactly at 200 Hz (p = e^{2·ts}, g = 20 (p − 1)/2), P loop
//! u = r − y_m, y_m = x + v, AR(1) noise v (pole 0.9, driving σ 0.1), white unit reference: the
//! loop of host/tests/closed_loop_identification.rs. For each record length N and method, over
//! `SEEDS` noise seeds: the estimate Ĝ on 60 log-spaced frequencies 1–40 Hz; bias = RMS over
//! the grid of |mean Ĝ − G|/|G|, spread = RMS over grid and seeds of |Ĝ − mean Ĝ|/|G|, and the
//! mean per-seed RMS error (total² ≈ bias² + spread²).
//!
//! Run: `cargo run --release -p ferrosid --example closed_loop_unstable_study [SEEDS]`.
use ferrosid::closed_loop::{identify_closed_loop, ClosedLoopMethod, ClosedLoopOptions};
use ferrosid::n4sid::{ChannelSet, N4sidOptions, OrderSelection};
use ferrosid_sim::rng::Rng;
use num_complex::Complex64;
use std::f64::consts::PI;
use std::path::Path;

const TS: f64 = 0.005;

fn grid() -> Vec<f64> {
    (0..60).map(|k| 40f64.powf(k as f64 / 59.0)).collect()
}

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    let p = (2.0 * TS).exp();
    let g = 20.0 * (p - 1.0) / 2.0;
    let truth = |f: f64| g / (Complex64::from_polar(1.0, 2.0 * PI * f * TS) - p);
    let gr = grid();
    let gt: Vec<Complex64> = gr.iter().map(|f| truth(*f)).collect();
    println!("N | order | seeds | mean RMS error | bias | spread | unstable pole kept");
    for n in [5_000usize, 20_000, 80_000] {
        for order in [1usize, 2] {
            let mut ests: Vec<Vec<Complex64>> = Vec::new();
            let mut errs = Vec::new();
            let mut kept = 0;
            for seed in 0..seeds {
                let mut rng = Rng::new(1000 + seed);
                let (mut x, mut v) = (0.0f64, 0.0f64);
                let (mut r, mut u, mut y) = (Vec::new(), Vec::new(), Vec::new());
                for _ in 0..n {
                    v = 0.9 * v + 0.1 * rng.normal();
                    let rk = rng.normal();
                    let ym = x + v;
                    let uk = rk - ym;
                    r.push(rk);
                    u.push(uk);
                    y.push(ym);
                    x = p * x + g * uk;
                }
                let (un, yn) = (vec!["u".to_string()], vec!["y".to_string()]);
                let (us, ys, rs) = ([u.as_slice()], [y.as_slice()], [r.as_slice()]);
                let d = ChannelSet {
                    source: Path::new("study"),
                    ts: TS,
                    u: &us,
                    y: &ys,
                    u_names: &un,
                    y_names: &yn,
                };
                let res = identify_closed_loop(
                    &d,
                    &rs,
                    &ClosedLoopOptions {
                        method: ClosedLoopMethod::JointInputOutput,
                        n4sid: N4sidOptions {
                            order: OrderSelection::Fixed(order),
                            ..N4sidOptions::default()
                        },
                        stage1_order: None,
                    },
                );
                let Ok(res) = res else {
                    println!("  N {n} order {order} seed {seed}: {:?}", res.err());
                    continue;
                };
                let m = &res.plant.model;
                if m.poles().unwrap().iter().any(|z| z.norm() > 1.0) {
                    kept += 1;
                }
                let h = m.freq_responses_siso_hz(&gr).unwrap();
                let e: f64 = h
                    .iter()
                    .zip(&gt)
                    .map(|(a, b)| ((a - b).norm() / b.norm()).powi(2))
                    .sum::<f64>()
                    / gr.len() as f64;
                errs.push(e.sqrt());
                ests.push(h);
            }
            let k = ests.len() as f64;
            let mean: Vec<Complex64> = (0..gr.len())
                .map(|i| ests.iter().map(|h| h[i]).sum::<Complex64>() / k)
                .collect();
            let bias = (mean
                .iter()
                .zip(&gt)
                .map(|(a, b)| ((a - b).norm() / b.norm()).powi(2))
                .sum::<f64>()
                / gr.len() as f64)
                .sqrt();
            let spread = (ests
                .iter()
                .flat_map(|h| {
                    h.iter()
                        .zip(&mean)
                        .zip(&gt)
                        .map(|((a, m), t)| ((a - m).norm() / t.norm()).powi(2))
                })
                .sum::<f64>()
                / (gr.len() as f64 * k))
                .sqrt();
            let me = errs.iter().sum::<f64>() / errs.len() as f64;
            println!(
                "{n} | {order} | {} | {me:.4} | {bias:.4} | {spread:.4} | {kept}",
                ests.len()
            );
        }
    }
}
