//! The controllers beyond PID are implemented twice on purpose (issue 14): in f32 `no_std` in
//! the firmware (`ferrosid_firmware::control::{PidNotchLaw, StateSpaceLaw}`) and in f64 on the
//! host (`ferrosid::synth::sim::DiscreteLaw`, which computes the pipeline's saturated-step
//! receipts). This test runs both on the same error sequences, step by step, with the rails
//! hit for long stretches (so the anti-windup acts), and bounds the difference.
//!
//! The firmware's notches are the biquads of `Notch::biquad` (Tustin prewarped at the centre,
//! direct form I); the host's are `Notch::in_domain` (a balanced state-space realisation of
//! the same Tustin map): the comparison also checks that the two forms are one filter.
//!
//! Tolerance: |u_f32 − u_f64| <= 2e-4 of the rail at every step. The f32 coefficients and
//! arithmetic carry relative errors ~1e-7 that the integrating parts accumulate over the 6000
//! steps (the controller's near-integrator pole 0.999 has a DC gain of 1000), measured at
//! 1.8e-6 (pid-notch) and 7.3e-5 (state space) of the rail here; the conditional integration switches on a comparison, and a sample within
//! ~1e-6 of the rail could switch differently — the sequences here never come that close.
use ferrosid::lti::{StateSpace, TransferFunction};
use ferrosid::robust::pid::{Pid, Rolloff};
use ferrosid::synth::loopshape::Notch;
use ferrosid::synth::sim::{anti_windup_gain, DiscreteLaw, SsFilter};
use ferrosid_firmware::control as fw;

const TS: f64 = 1e-3;
const STEPS: usize = 6000;
const LIMIT: f64 = 1.0;
const TOL: f64 = 2e-4;

/// A square wave of ±3 with a slow ramp and a 50 Hz ripple: long stretches at either rail.
fn error_at(k: usize) -> f64 {
    let t = k as f64 * TS;
    let sq = if (k / 700) % 2 == 0 { 3.0 } else { -2.0 };
    sq * (0.2 + 0.8 * (t / 6.0)) + 0.3 * (2.0 * std::f64::consts::PI * 50.0 * t).sin()
}

fn notches() -> Vec<Notch> {
    vec![
        Notch {
            centre_hz: 50.3,
            zeta_num: 0.01,
            zeta_den: 0.43,
        },
        Notch {
            centre_hz: 120.0,
            zeta_num: 0.05,
            zeta_den: 0.3,
        },
    ]
}

fn poly_mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

fn run_pid_notch(anti_windup: bool) -> f64 {
    let pid = Pid {
        kp: 0.08,
        ki: 1.5,
        kd: 0.0008,
        tau_f: 4e-4,
        rolloff: Some(Rolloff {
            corner_hz: 32.0,
            zeta: 0.7,
        }),
    };
    let dp = pid.discretize(TS, Some(8.0)).unwrap();
    let mut nss = StateSpace::identity(1, TS).unwrap();
    let mut sections = [fw::Biquad {
        b: [1.0, 0.0, 0.0],
        a: [1.0, 0.0, 0.0],
    }; 2];
    for (n, s) in notches().iter().zip(sections.iter_mut()) {
        nss = n.in_domain(Some(TS)).unwrap().series(&nss).unwrap();
        let (b, a) = n.biquad(TS).unwrap();
        *s = fw::Biquad {
            b: b.map(|v| v as f32),
            a: a.map(|v| v as f32),
        };
    }
    let mut host = DiscreteLaw::PidThenFilter {
        pid: dp.clone(),
        state: Default::default(),
        filter: SsFilter::new(&nss).unwrap(),
        anti_windup,
    };
    let law = fw::PidNotchLaw::new(&fw::PidNotchConfig {
        pid: fw::PidConfig {
            kp: dp.kp as f32,
            ki_d: dp.ki_d as f32,
            a_d: dp.a_d as f32,
            b_d: dp.b_d as f32,
            rolloff: dp.rolloff.map(|r| fw::Biquad {
                b: r.b.map(|v| v as f32),
                a: r.a.map(|v| v as f32),
            }),
        },
        cascade: fw::BiquadCascade { sections },
        u_min: -LIMIT as f32,
        u_max: LIMIT as f32,
        anti_windup,
    })
    .unwrap();
    let mut st = fw::PidNotchState::new();
    let (mut worst, mut at_rail) = (0.0f64, 0usize);
    for k in 0..STEPS {
        let e = error_at(k);
        let u64_ = host.step(e, LIMIT).clamp(-LIMIT, LIMIT);
        let u32_ = f64::from(law.step(&mut st, e as f32, 0.0).u);
        if u64_.abs() >= LIMIT {
            at_rail += 1;
        }
        worst = worst.max((u32_ - u64_).abs());
        assert!(
            (u32_ - u64_).abs() <= TOL * LIMIT,
            "step {k}: f32 {u32_} vs f64 {u64_}"
        );
    }
    assert!(
        at_rail > STEPS / 10,
        "the sequence must saturate ({at_rail} samples)"
    );
    worst
}

#[test]
fn pid_notch_f32_matches_the_host_law_with_and_without_anti_windup() {
    let a = run_pid_notch(true);
    let b = run_pid_notch(false);
    eprintln!("pid-notch: max |Δu| {a:.3e} (anti-windup), {b:.3e} (none), rail {LIMIT}");
}

/// A 3rd-order controller with a near-integrator (pole 0.999) and a resonant pair, balanced.
fn controller() -> StateSpace {
    let num = poly_mul(&[0.05, -0.045], &[1.0, -1.6, 0.8]);
    let den = poly_mul(&[1.0, -0.999], &[1.0, -1.2, 0.5]);
    let tf = TransferFunction::new(num, den, TS).unwrap();
    ferrosid::robust::norms::balance(&tf.to_state_space().unwrap()).unwrap()
}

#[test]
fn state_space_f32_matches_the_host_law_and_the_gain_stabilises_a_minus_lc() {
    let k = controller();
    let l = anti_windup_gain(&k).unwrap();
    let n = k.n_states();
    assert_eq!(n, 3);
    // A − L C has spectral radius < 1 (the observer form's stability), checked independently
    // by powering: the largest entry of (A − LC)^2000 is small (its 2000th root estimates the
    // spectral radius; A itself has the pole 0.999, whose 2000th power is 0.135).
    let alc = faer::Mat::from_fn(n, n, |i, j| k.a[(i, j)] - l[i] * k.c[(0, j)]);
    let mut p = faer::Mat::<f64>::identity(n, n);
    for _ in 0..2000 {
        p = &alc * &p;
    }
    let pn = (0..n)
        .flat_map(|i| (0..n).map(move |j| (i, j)))
        .map(|(i, j)| p[(i, j)].abs())
        .fold(0.0, f64::max);
    eprintln!("spectral radius of A − LC ≈ {:.5}", pn.powf(1.0 / 2000.0));
    assert!(pn < 1e-2, "(A − LC)^2000 max entry {pn}");
    let mut host =
        DiscreteLaw::StateSpace(SsFilter::new(&k).unwrap().with_anti_windup(&l).unwrap());
    let mut host_plain = DiscreteLaw::StateSpace(SsFilter::new(&k).unwrap());
    let f = |v: f64| v as f32;
    let law = fw::StateSpaceLaw::<3>::new(&fw::StateSpaceConfig {
        a: std::array::from_fn(|i| std::array::from_fn(|j| f(k.a[(i, j)]))),
        b: std::array::from_fn(|i| f(k.b[(i, 0)])),
        c: std::array::from_fn(|j| f(k.c[(0, j)])),
        d: f(k.d[(0, 0)]),
        l: std::array::from_fn(|i| f(l[i])),
        u_min: -LIMIT as f32,
        u_max: LIMIT as f32,
    })
    .unwrap();
    let mut st = fw::StateSpaceState::new();
    let (mut worst, mut at_rail, mut plain_max, mut aw_max) = (0.0f64, 0usize, 0.0f64, 0.0f64);
    for kk in 0..STEPS {
        let e = error_at(kk);
        let v = host.step(e, LIMIT);
        let u64_ = v.clamp(-LIMIT, LIMIT);
        let o = law.step(&mut st, e as f32, 0.0);
        if v.abs() >= LIMIT {
            at_rail += 1;
        }
        aw_max = aw_max.max(v.abs());
        plain_max = plain_max.max(host_plain.step(e, LIMIT).abs());
        let d = (f64::from(o.u) - u64_).abs();
        worst = worst.max(d);
        assert!(d <= TOL * LIMIT, "step {kk}: f32 {} vs f64 {u64_}", o.u);
        assert!((f64::from(o.u_unclamped) - v).abs() <= 1e-3 * v.abs().max(1.0));
    }
    assert!(
        at_rail > STEPS / 4,
        "the sequence must saturate ({at_rail} samples)"
    );
    // Without the gain the demand winds up beyond the rail; with it, it stays closer.
    eprintln!(
        "state space: max |Δu| {worst:.3e}; demand |v| reaches {plain_max:.3} without \
         anti-windup, {aw_max:.3} with it (rail {LIMIT}); L = {l:?}"
    );
    assert!(
        plain_max > 2.0 * LIMIT && aw_max < 0.8 * plain_max,
        "{plain_max} {aw_max}"
    );
}
