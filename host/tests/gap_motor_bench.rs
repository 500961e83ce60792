//! `ferrosid gap` on the real motor bench (../shared/data/motor-bench, see its README.md): the
//! nominal model is ferrosid's own order-4 N4SID model of the Type A multisine log (q-axis
//! current reference `iq_refx` → motor speed `omega_max`), the training log is Type A and the
//! validation log the Type B multisine (another phase realisation). The effect of the real
//! bench is not known, so only robust facts are pinned:
//! * gap_after <= gap_linear <= gap_before, and every band lies within 0..fs/2;
//! * the worst band lies in the excited band 11..250 Hz (the multiplicative error uses coherent
//!   bins only) and coherence drops below the excited band;
//! * an independent lower bound on gap_linear from the data alone: in periodic steady state a
//!   linear model has no output at the multisine's non-excited lines, so its residual holds at
//!   least the measured output's power there (period-averaged over periods 2..20, naive DFT
//!   written here).
//!
//! The data are read in place from ../shared/data; when absent the test prints a notice and
//! returns.
mod cli_support;
use crate::shared_data::shared_data;
use cli_support::{ferrosid, s, scratch};
use ferrosid::io::{read_mat, MatOptions};
use serde_json::Value;

/// Samples per multisine period in the motor-bench files.
const PERIOD: usize = 2500;

/// NRMSE floor of any linear model on `(u, y)`: sqrt of the period-averaged output's power on
/// the lines where the input has no power (DC excluded), over the output's variance.
fn non_excited_floor(u: &[f64], y: &[f64]) -> f64 {
    let periods = y.len() / PERIOD;
    assert!(periods >= 3);
    let avg = |x: &[f64]| -> Vec<f64> {
        let mut a = vec![0.0; PERIOD];
        for p in 1..periods {
            for (k, v) in a.iter_mut().enumerate() {
                *v += x[p * PERIOD + k] / (periods - 1) as f64;
            }
        }
        a
    };
    let (ua, ya) = (avg(u), avg(y));
    // Naive DFT power per line 1..PERIOD/2.
    let power = |x: &[f64], k: usize| -> f64 {
        let (mut re, mut im) = (0.0, 0.0);
        for (n, v) in x.iter().enumerate() {
            let ph = -2.0 * std::f64::consts::PI * ((k * n) % PERIOD) as f64 / PERIOD as f64;
            re += v * ph.cos();
            im += v * ph.sin();
        }
        re * re + im * im
    };
    let lines: Vec<(f64, f64)> = (1..PERIOD / 2)
        .map(|k| (power(&ua, k), power(&ya, k)))
        .collect();
    let umax = lines.iter().fold(0.0f64, |m, l| m.max(l.0));
    // One-sided: each line k counts twice in Parseval (k and N-k).
    let p_ne: f64 = lines
        .iter()
        .filter(|l| l.0 < 1e-6 * umax)
        .map(|l| 2.0 * l.1)
        .sum::<f64>()
        / (PERIOD as f64 * PERIOD as f64);
    let s = &y[PERIOD..periods * PERIOD];
    let mean = s.iter().sum::<f64>() / s.len() as f64;
    let var = s.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / s.len() as f64;
    (p_ne / var).sqrt()
}

#[test]
fn motor_bench_gap_against_an_identified_linear_model() {
    let (Some(a), Some(b)) = (
        shared_data("motor-bench/MultisineTypeA.mat", "the motor-bench gap test"),
        shared_data("motor-bench/MultisineTypeB.mat", "the motor-bench gap test"),
    ) else {
        return;
    };
    let dir = scratch("gap-motor-bench");
    let model = dir.join("motor_a_order4.json");
    let chan = ["--input", "iq_refx", "--output", "omega_max"];
    let mut id = vec!["identify", s(&a), "--order", "4", "--out", s(&model)];
    id.extend_from_slice(&chan);
    let r = ferrosid(&id);
    assert!(r.code == 0 || r.code == 1, "identify failed: {}", r.stderr);
    let mut gap = vec![
        "gap",
        "--sim",
        s(&model),
        "--real",
        s(&a),
        "--validate",
        s(&b),
        "--json",
    ];
    gap.extend_from_slice(&chan);
    let r = ferrosid(&gap);
    assert_eq!(r.code, 0, "gap failed: {}", r.stderr);
    let v: Value = serde_json::from_str(&r.stdout).expect("--json output parses");
    let g = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} in the report"));
    let (before, linear, after) = (g("gap_before"), g("gap_linear"), g("gap_after"));
    println!(
        "motor bench: verdict {}, gaps {before:.4} -> {linear:.4} -> {after:.4}",
        v["verdict"]
    );
    println!("where: {}", v["where"]);
    for e in v["effects"].as_array().expect("effects") {
        println!(
            "  {} val NRMSE {:.4} params {}",
            e["effect"], e["gap_after"], e["params"]
        );
    }
    assert!(after <= linear * (1.0 + 1e-12), "{after} > {linear}");
    assert!(linear <= before * 1.01, "{linear} > {before}");
    // Issue 10: no absurd value in a report. A candidate whose fit went to its no-effect limit
    // (a dead zone of width 3e-35, a saturation limit of 1e13 on this data) is flagged
    // `vanished`, and the text prints that instead of the extremes; a resonance keeps a damping
    // of at least 1e-4.
    let lin_train = v["linear"]["train_nrmse"]
        .as_f64()
        .expect("linear train NRMSE");
    let mut vanished = 0;
    for e in v["effects"].as_array().expect("effects") {
        let same = (e["train_nrmse"].as_f64().unwrap() - lin_train).abs() <= 1e-6 * lin_train
            && (e["gap_after"].as_f64().unwrap() - linear).abs() <= 1e-6 * linear;
        assert_eq!(e["vanished"].as_bool(), Some(same), "{e}");
        vanished += usize::from(same);
        if e["effect"] == "resonance" {
            assert!(e["params"]["damping"].as_f64().unwrap() >= 1e-4, "{e}");
        }
    }
    let mut text = gap.clone();
    text.retain(|a| *a != "--json");
    let t = ferrosid(&text);
    assert_eq!(t.code, 0, "{}", t.stderr);
    assert_eq!(
        t.stdout
            .matches("vanished (fit at its no-effect limit")
            .count(),
        vanished,
        "{}",
        t.stdout
    );
    let fs = 2500.0;
    let pairs = |x: &Value| -> Vec<[f64; 2]> {
        x.as_array()
            .expect("band list")
            .iter()
            .map(|p| {
                [
                    p[0].as_f64().expect("band lo"),
                    p[1].as_f64().expect("band hi"),
                ]
            })
            .collect()
    };
    let w = &v["where"];
    for [lo, hi] in pairs(&w["bands_hz"])
        .into_iter()
        .chain(pairs(&w["coherence_drops_hz"]))
    {
        assert!(
            0.0 <= lo && lo <= hi && hi <= fs / 2.0 + 1e-9,
            "band {lo}..{hi}"
        );
    }
    let worst = w["worst_hz"].as_f64().expect("worst_hz");
    assert!((11.0..=250.0).contains(&worst), "worst at {worst} Hz");
    let drops = pairs(&w["coherence_drops_hz"]);
    assert!(
        drops.iter().any(|d| d[0] < 5.0 && d[1] > 5.0),
        "coherence drop below the 11 Hz band edge: {drops:?}"
    );

    // Independent floor from the validation data alone.
    let opts = MatOptions {
        inputs: vec!["iq_refx".into()],
        outputs: vec!["omega_max".into()],
        ..MatOptions::default()
    };
    let log = read_mat(&b, &opts).expect("Type B log");
    let floor = non_excited_floor(log.u(), log.y());
    println!("non-excited-line NRMSE floor of any linear model: {floor:.4}");
    assert!(floor > 0.0);
    // 10 % slack: the NRMSE is taken over the whole log after the warm-up, not whole periods.
    assert!(
        linear >= 0.9 * floor,
        "gap_linear {linear} below the linear floor {floor}"
    );

    // The tool's own evidence agrees with that independent bound on the validation log, and
    // the verdict is honest: `none` only when the linear model is within twice the noise
    // floor (which a periodic excitation gives from the period-to-period scatter).
    let nf = &v["noise_floor"];
    assert_eq!(nf["method"], "periodic_scatter");
    assert_eq!(nf["period_samples"], PERIOD as u64);
    let noise = nf["nrmse"].as_f64().unwrap();
    println!("noise floor {noise:.4}, evidence {}", v["evidence"]);
    let logs = v["evidence"]["nonlinear_distortion"]["logs"]
        .as_array()
        .expect("distortion per periodic log");
    let vb = logs
        .iter()
        .find(|l| l["log"].as_str().unwrap().ends_with("MultisineTypeB.mat"))
        .expect("the validation log is periodic");
    let bound = vb["nrmse_bound"].as_f64().unwrap();
    assert!(
        (0.7..=1.3).contains(&(bound / floor)),
        "tool's non-excited-line bound {bound} vs independent {floor}"
    );
    assert_eq!(vb["significant"], true);
    if v["verdict"] == "none" {
        assert!(
            linear <= 2.0 * noise,
            "none with {linear} against floor {noise}"
        );
    }
    if linear > 2.0 * noise {
        assert_ne!(v["verdict"], "none");
    }
}
