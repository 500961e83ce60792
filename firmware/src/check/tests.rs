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

/// `G(z) = c1/(z − p1) + c2/(z − p2) + d` in f64 (the modal form's closed form).
fn modal_response(p: [f64; 2], c: [f64; 2], d: f64, z: (f64, f64)) -> (f64, f64) {
    let mut g = (d, 0.0);
    for (pk, ck) in p.iter().zip(c.iter()) {
        let (dr, di) = (z.0 - pk, z.1);
        let n2 = dr * dr + di * di;
        g.0 += ck * dr / n2;
        g.1 -= ck * di / n2;
    }
    g
}

/// The nalgebra evaluation against the closed form of a two-pole modal model, given to it in a
/// dense realisation (A = T·diag(p)·T⁻¹, B = T·1, C = c·T⁻¹ with T = [[1, 2], [0.5, 3]],
/// det T = 2), at every bin of a 256-point period: relative error below 1e-5.
#[test]
fn model_response_matches_the_closed_form_of_a_dense_realisation() {
    let (p, cm, dd) = ([0.9f64, -0.3], [0.7f64, 1.3], 0.25f64);
    // T and T⁻¹ = [[3, −2], [−0.5, 1]] / 2 (exact in binary).
    let t = [[1.0f64, 2.0], [0.5, 3.0]];
    let ti = [[1.5f64, -1.0], [-0.25, 0.5]];
    let mut a = [[0.0f32; 2]; 2];
    for i in 0..2 {
        for j in 0..2 {
            a[i][j] = (t[i][0] * p[0] * ti[0][j] + t[i][1] * p[1] * ti[1][j]) as f32;
        }
    }
    let b = [[(t[0][0] + t[0][1]) as f32], [(t[1][0] + t[1][1]) as f32]];
    let c = [[
        (cm[0] * ti[0][0] + cm[1] * ti[1][0]) as f32,
        (cm[0] * ti[0][1] + cm[1] * ti[1][1]) as f32,
    ]];
    let d = [[dd as f32]];
    let mut worst = 0.0f64;
    for k in 0..128u32 {
        let th = 2.0 * std::f64::consts::PI * f64::from(k) / 256.0;
        let z = C32::unit_circle(k, 256);
        let g = model_response(&a, &b, &c, &d, z, 0, 0).expect("defined off the poles");
        let want = modal_response(p, cm, dd, (th.cos(), th.sin()));
        let err = (f64::from(g.re) - want.0).hypot(f64::from(g.im) - want.1) / want.0.hypot(want.1);
        worst = worst.max(err);
    }
    assert!(worst < 1e-5, "worst relative error {worst:e}");
}

/// At a pole `zI − A` is singular: `None` (the check's Undefined), as for an out-of-range
/// input or output.
#[test]
fn model_response_is_undefined_at_a_pole_and_for_bad_indices() {
    let a = [[0.5f32, 0.0], [0.0, -0.25]];
    let b = [[1.0f32], [1.0]];
    let c = [[1.0f32, 1.0]];
    let d = [[0.0f32]];
    assert_eq!(
        model_response(&a, &b, &c, &d, C32::new(0.5, 0.0), 0, 0),
        None
    );
    assert_eq!(
        model_response(&a, &b, &c, &d, C32::new(-0.25, 0.0), 0, 0),
        None
    );
    let z = C32::new(0.0, 1.0);
    assert!(model_response(&a, &b, &c, &d, z, 0, 0).is_some());
    assert_eq!(model_response(&a, &b, &c, &d, z, 1, 0), None);
    assert_eq!(model_response(&a, &b, &c, &d, z, 0, 1), None);
}

/// `unit_circle` against f64 cos/sin: the table path (power-of-two denominators, numerators
/// beyond one turn included) within 2.5e-7, the series path (other denominators) within the
/// f32 rounding, and den 1 (a whole number of turns) exactly 1.
#[test]
fn unit_circle_matches_f64_on_both_paths() {
    let mut worst = [0.0f64; 2];
    for (path, den) in [(0usize, 64u32), (0, 512), (0, 4096), (1, 1000), (1, 3)] {
        for num in (0..3 * den).step_by(1 + den as usize / 256) {
            let th = 2.0 * std::f64::consts::PI * f64::from(num) / f64::from(den);
            let z = C32::unit_circle(num, den);
            let e = (f64::from(z.re) - th.cos()).hypot(f64::from(z.im) - th.sin());
            worst[path] = worst[path].max(e);
        }
    }
    assert!(worst[0] < 2.5e-7, "table path {:e}", worst[0]);
    assert!(worst[1] < 1e-7, "series path {:e}", worst[1]);
    assert_eq!(C32::unit_circle(7, 1), C32::new(1.0, 0.0));
}

/// `failed_hz`: the failed and undefined frequencies, in order, nothing else.
#[test]
fn failed_hz_lists_failed_and_undefined_in_order() {
    let mut r = [CheckResult::EMPTY; 5];
    let verdicts = [
        Verdict::Pass,
        Verdict::Fail,
        Verdict::Skipped,
        Verdict::Undefined,
        Verdict::Unresolved,
    ];
    for (i, (ri, v)) in r.iter_mut().zip(verdicts).enumerate() {
        ri.hz = 10.0 * (i + 1) as f32;
        ri.verdict = v;
    }
    assert_eq!(failed_hz(&r).as_slice(), &[20.0, 40.0]);
    r[1].verdict = Verdict::Pass;
    r[3].verdict = Verdict::Pass;
    assert!(failed_hz(&r).is_empty());
    let all = [CheckResult::EMPTY; 3];
    assert_eq!(failed_hz(&all).len(), 3);
}
