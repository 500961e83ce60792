//! The nested-effect test of the gap diagnosis (stiction over Coulomb friction): the effective
//! sample count of a residual against the closed-form integrated autocorrelation time of an
//! AR(1) sequence, τ = (1 + φ)/(1 − φ).
use ferrosid::gap::diagnose::effective_samples;
use ferrosid_sim::rng::Rng;

fn ar1(n: usize, phi: f64, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    let mut x = 0.0;
    (0..n)
        .map(|_| {
            x = phi * x + rng.normal();
            x
        })
        .collect()
}

#[test]
fn white_noise_counts_every_sample() {
    let n = 20_000;
    let ne = effective_samples(&ar1(n, 0.0, 3));
    // τ = 1; the truncated positive-sequence sum adds O(1/sqrt(N)) per lag pair kept.
    assert!(
        (ne / n as f64 - 1.0).abs() < 0.1,
        "N_eff {ne} for {n} white samples"
    );
}

#[test]
fn ar1_sequence_counts_n_over_tau() {
    let n = 50_000;
    for (phi, seed) in [(0.5, 5u64), (0.9, 7), (0.97, 11)] {
        let tau = (1.0 + phi) / (1.0 - phi);
        let ne = effective_samples(&ar1(n, phi, seed));
        let expect = n as f64 / tau;
        // Estimation error of τ from 50k samples: a few % for φ = 0.5, ~15 % for φ = 0.97.
        assert!(
            (ne / expect - 1.0).abs() < 0.2,
            "phi {phi}: N_eff {ne:.0}, closed form {expect:.0}"
        );
    }
}

#[test]
fn degenerate_residuals_give_at_least_one_sample() {
    assert_eq!(effective_samples(&[]), 1.0);
    assert_eq!(effective_samples(&[2.0, 2.0, 2.0, 2.0, 2.0]), 1.0);
    assert!(effective_samples(&[1.0, -1.0]) >= 1.0);
}
