use super::*;
use crate::Welch;

const BINS: [u16; 3] = [2, 5, 9];
const HZ: [f32; 3] = [7.8125, 19.53125, 35.15625];

fn cfg() -> CheckConfig<'static, 3> {
    CheckConfig {
        fs_hz: 1000.0,
        n: 256,
        bins: &BINS,
        hz: &HZ,
        gate: 0.9,
        min_checked: 2,
    }
}

#[test]
fn config_rejects_each_bad_field() {
    assert_eq!(cfg().validate(), Ok(()));
    let bad = |f: &dyn Fn(&mut CheckConfig<'static, 3>)| {
        let mut c = cfg();
        f(&mut c);
        c.validate().unwrap_err()
    };
    assert_eq!(bad(&|c| c.fs_hz = f32::NAN), CheckError::SampleRate);
    assert_eq!(bad(&|c| c.fs_hz = 0.0), CheckError::SampleRate);
    assert_eq!(bad(&|c| c.gate = 1.0), CheckError::Gate);
    assert_eq!(bad(&|c| c.gate = f32::NAN), CheckError::Gate);
    assert_eq!(bad(&|c| c.min_checked = 0), CheckError::MinChecked);
    assert_eq!(bad(&|c| c.min_checked = 4), CheckError::MinChecked);
    static NYQ: [u16; 3] = [2, 5, 128];
    static DESC: [u16; 3] = [2, 9, 5];
    static ZERO: [u16; 3] = [0, 5, 9];
    assert_eq!(bad(&|c| c.bins = &NYQ), CheckError::Bin { index: 2 });
    assert_eq!(bad(&|c| c.bins = &DESC), CheckError::Bin { index: 2 });
    assert_eq!(bad(&|c| c.bins = &ZERO), CheckError::Bin { index: 0 });
    let msg = format!("{}", CheckError::Bin { index: 2 });
    assert!(msg.contains("bin[2]") && msg.contains("N/2"), "{msg}");
    assert_eq!(CheckError::Gate.field(), "coherence_gate");
    let mut e = ClosedLoopEstimator::<256>::unconfigured();
    assert_eq!(e.configure(-1.0), Err(CheckError::SampleRate));
    assert_eq!(e.configure(f32::INFINITY), Err(CheckError::SampleRate));
}

/// `evaluate` with an H1 measurement gives exactly what `check_bin` gives bin by bin (the
/// open-loop path of the image is unchanged by the move).
#[test]
fn evaluate_equals_check_bin() {
    let a = [[0.9f32, 0.1], [-0.2, 0.7]];
    let b = [[0.0f32], [0.05]];
    let c = [[1.0f32, 0.0]];
    let d = [[0.0f32]];
    let model = Model {
        a: &a,
        b: &b,
        c: &c,
        d: &d,
    };
    let weight = Weight {
        num: &[0.5, 0.1],
        den: &[1.0, 100.0],
    };
    let meas = |k: usize| Measured {
        coherence: 0.8 + 0.02 * k as f32,
        sigma: h1_random_error(0.8 + 0.02 * k as f32, 8),
        g: Some(C32::new(0.1 * k as f32, -0.05)),
    };
    let cf = cfg();
    let got = evaluate(&cf, &model, &weight, meas);
    for (r, (&bin, &hz)) in got.iter().zip(BINS.iter().zip(HZ.iter())) {
        let k = usize::from(bin);
        let z = C32::unit_circle(u32::from(bin), 256);
        let w = (2.0 * core::f64::consts::PI * k as f64 * 1000.0 / 256.0) as f32;
        let want = check_bin(
            bin,
            hz,
            meas(k).coherence,
            8,
            0.9,
            meas(k).g,
            model_response(&a, &b, &c, &d, z, 0, 0),
            weight_magnitude(&[0.5, 0.1], &[1.0, 100.0], w),
        );
        // Debug text: NaN fields (rel_error of a skipped bin) compare equal this way.
        assert_eq!(format!("{r:?}"), format!("{want:?}"));
    }
}

/// A linear discrete loop with output noise: plant y[n] = p·y[n−1] + g·u[n−1] + v[n]
/// (G(z) = g z⁻¹/(1 − p z⁻¹)), controller u = k_p (r − y). The estimator's S_ry/S_ru matches
/// G at every excited line within 3√2σ of its own error bound and 8 %, while the open-loop H1 of (u, y) on the same data is off
/// by more than 20 % at the low lines (it tends to −1/k_p where the noise dominates).
#[test]
fn closed_loop_ratio_recovers_the_plant_where_h1_is_biased() {
    const N: usize = 256;
    let (p, g, kp) = (0.95f64, 0.05f64, 4.0f64);
    let lines = [1usize, 2, 3, 5, 8, 13];
    let mut rng = crate::rng::SplitMix64::new(7);
    let mut est = ClosedLoopEstimator::<N>::unconfigured();
    est.configure(1000.0).unwrap();
    let mut h1 = Welch::<N>::new(ClosedLoopEstimator::<N>::welch_config(1000.0)).unwrap();
    let (mut x, mut u_prev) = (0.0f64, 0.0f64);
    let periods = 800;
    for n in 0..(periods + 2) * N {
        let t = (n % N) as f64;
        let r: f64 = lines
            .iter()
            .map(|&l| {
                0.1 * (2.0 * core::f64::consts::PI * (l as f64 * t / N as f64 + 0.37 * l as f64))
                    .cos()
            })
            .sum();
        x = p * x + g * u_prev;
        let v = 0.6 * (f64::from(rng.next_u32()) / 4_294_967_296.0 - 0.5) * 3.464;
        let y = x + v;
        let u = kp * (r - y);
        if n >= 2 * N {
            est.push(r as f32, u as f32, y as f32);
            h1.push(u as f32, y as f32);
        }
        u_prev = u;
    }
    est.flush();
    h1.flush();
    assert_eq!(est.averages(), periods as u32);
    let mut worst_naive = 0.0f64;
    for &l in &lines {
        let th = 2.0 * core::f64::consts::PI * l as f64 / N as f64;
        let (c, s) = (th.cos(), th.sin());
        // G = g e^{-jθ} / (1 − p e^{-jθ})
        let (nr, ni) = (g * c, -g * s);
        let (dr, di) = (1.0 - p * c, p * s);
        let d2 = dr * dr + di * di;
        let gt = C32::new(
            ((nr * dr + ni * di) / d2) as f32,
            ((ni * dr - nr * di) / d2) as f32,
        );
        let ge = est.estimate(l).unwrap();
        let err = (ge - gt).abs() / gt.abs();
        let m = est.measured(l);
        // Within the estimate's own error bound: σ bounds the magnitude's and the phase's
        // normalised errors, so the complex relative error is Rayleigh-like with scale σ;
        // 3√2·σ is exceeded with probability e^{-9} ≈ 1e-4 per line. And below 8 %.
        assert!(
            err <= 3.0 * core::f32::consts::SQRT_2 * m.sigma && err < 0.08,
            "line {l}: {ge:?} vs {gt:?} ({err}, σ {})",
            m.sigma
        );
        let (a, b) = h1.h1(l).unwrap();
        let naive = (C32::new(a, b) - gt).abs() / gt.abs();
        worst_naive = worst_naive.max(naive as f64);
        assert!(m.coherence > 0.3 && m.sigma < 0.1, "{m:?}");
    }
    // The naive estimate is biased far beyond its own random error at the low lines.
    assert!(
        worst_naive > 0.3,
        "naive H1 unexpectedly unbiased: {worst_naive}"
    );
}
