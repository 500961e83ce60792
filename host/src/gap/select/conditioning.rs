//! Invariance and conditioning of the fits (issue 9: results moved with the input units and
//! with 3e-9 relative differences between file formats).
use super::cases::{make_case, run, settings, y_rms, Case};
use super::*;
use crate::gap::simulator::plant::{simulate, Plant};
use crate::gap::simulator::rng::Rng;

fn axis_case() -> Case {
    let ax = Plant::axis();
    let ns = 0.01 * y_rms(&ax, 2.0, 20.0);
    let e = Effect::CoulombFriction { level: 1.0 };
    make_case(ax, 2.0, 20.0, 16384, 31, &|u, k| {
        simulate(&ax, Some(&e), u, &settings(ns, k)).unwrap()
    })
}

/// The same case with every input sample mapped by `fu` and every output sample by `fy`
/// (the linear starts scaled to match: residues and feedthrough by the output/input
/// ratio `gain`, the offset by `fy`).
fn mapped(c: &Case, fu: &dyn Fn(f64) -> f64, fy: &dyn Fn(f64) -> f64, gain: f64) -> Case {
    let u: Vec<Vec<f64>> =
        c.td.u
            .iter()
            .map(|l| l.iter().map(|&v| fu(v)).collect())
            .collect();
    let y: Vec<Vec<f64>> =
        c.td.base
            .y
            .iter()
            .map(|l| l.iter().map(|&v| fy(v)).collect())
            .collect();
    let starts = c
        .starts
        .iter()
        .map(|s| {
            let mut s = s.clone();
            s.residues.iter_mut().for_each(|r| *r *= gain);
            s.d *= gain;
            s.offset = fy(s.offset);
            s
        })
        .collect();
    Case {
        td: TrainData::new(c.td.ts, u, y, c.td.base.warmup).unwrap(),
        starts,
        poles: c.poles.clone(),
        structure: c.structure.clone(),
        vu: c.vu.iter().map(|&v| fu(v)).collect(),
        vy: c.vy.iter().map(|&v| fy(v)).collect(),
        warmup: c.warmup,
    }
}

fn params(s: &Selection) -> Vec<(String, f64)> {
    s.selected
        .iter()
        .flat_map(|x| {
            x.effect
                .params()
                .into_iter()
                .map(move |(n, v)| (format!("{}.{n}", x.effect.kind()), v))
        })
        .collect()
}

/// Rescaling the input (V → N, ×7.3) and the output (mm → m, ×1e-3) maps the fitted
/// friction level by the input factor and changes nothing else (1e-6 relative).
#[test]
fn friction_fit_is_invariant_to_input_and_output_units() {
    let c = axis_case();
    let a = run(&c);
    let (ku, ky) = (7.3, 1e-3);
    let b = run(&mapped(&c, &|v| v * ku, &|v| v * ky, ky / ku));
    let (pa, pb) = (params(&a), params(&b));
    assert_eq!(pa.len(), pb.len(), "{pa:?} vs {pb:?}");
    assert!(!pa.is_empty());
    for ((n, va), (_, vb)) in pa.iter().zip(&pb) {
        let want = va * ku; // friction levels are in input units
        assert!(
            (vb - want).abs() <= 1e-6 * want.abs(),
            "{n}: {vb} vs {want}"
        );
    }
    assert!((a.selected[0].gap_after - b.selected[0].gap_after).abs() < 1e-6);
}

/// Perturbing every sample by 1e-9 relative (a 9-digit CSV against a .mat file) moves
/// every fitted parameter by at most 1e-6 relative.
#[test]
fn fits_are_well_conditioned() {
    let c = axis_case();
    let a = run(&c);
    let mut rng = Rng::new(77);
    let jitter: Vec<f64> = (0..4 * 16384)
        .map(|_| 1e-9 * (2.0 * rng.uniform() - 1.0))
        .collect();
    let k = std::cell::Cell::new(0usize);
    let bump = |v: f64| {
        let i = k.get();
        k.set(i + 1);
        v * (1.0 + jitter[i % jitter.len()])
    };
    let b = run(&mapped(&c, &bump, &bump, 1.0));
    let (pa, pb) = (params(&a), params(&b));
    assert_eq!(pa.len(), pb.len(), "{pa:?} vs {pb:?}");
    for ((n, va), (_, vb)) in pa.iter().zip(&pb) {
        assert!((vb - va).abs() <= 1e-6 * va.abs(), "{n}: {vb} vs {va}");
    }
}
