//! The `state_limit` effect: a level that saturates inside the plant, realised on the modal
//! linear part as a clamp of its slowest stable real mode ([`limited_mode`], [`state_clamp`]).
use super::modal::ModalModel;

/// The mode a state limit holds: the slowest stable real mode of the linear part (the largest
/// real pole in (0, 1 − 1e-6); integrators and their stand-ins excluded). Behind an integrator
/// (a position output) it is the body's velocity; without one, the slowest body's speed.
pub fn limited_mode(lin: &ModalModel) -> Option<usize> {
    (0..lin.real.len())
        .filter(|&i| lin.real[i] > 0.0 && lin.real[i] < 1.0 - 1e-6)
        .max_by(|&i, &j| lin.real[i].total_cmp(&lin.real[j]))
}

/// A state limit on the real mode x[k+1] = p·x[k] + w[k] (the modal form's states have unit
/// input gain): the state is held within ±`limit`/(1 − p), the level a constant input of
/// ±`limit` settles it at, by replacing the input with the one that holds it there while it
/// would pass the level (the input every mode then sees). With p = 0 this is an input
/// saturation at `limit`; the clamp never winds up (the held state leaves the level as soon
/// as the input pulls it back).
pub fn state_clamp(w: &[f64], p: f64, limit: f64) -> Vec<f64> {
    let level = limit / (1.0 - p);
    let mut x = 0.0;
    w.iter()
        .map(|&wk| {
            let held = wk.min(level - p * x).max(-level - p * x);
            x = p * x + held;
            held
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A velocity-limited carriage (m·v' = u − c·v, |v| ≤ v_max, exact ZOH step of the
    /// velocity, clamped after each step) against [`state_clamp`] on its velocity mode with the
    /// limit c·v_max in input units: the same velocities (the modal state is v·c/(1 − a));
    /// with p = 0 the clamp is an input saturation.
    #[test]
    fn state_clamp_is_a_velocity_limit_and_saturation_at_p_zero() {
        let (m, c, ts, vmax): (f64, f64, f64, f64) = (2.5, 15.0, 1e-3, 0.001);
        let a = (-c / m * ts).exp();
        let mut rng = crate::gap::rng::Rng::new(3);
        let u: Vec<f64> = (0..4000).map(|_| 0.2 * rng.normal()).collect();
        let mut v: f64 = 0.0;
        let mut direct = Vec::new();
        for &uk in &u {
            v = (a * v + (1.0 - a) * uk / c).clamp(-vmax, vmax);
            direct.push(v);
        }
        assert!(
            direct.iter().any(|v| v.abs() >= vmax),
            "limit never reached"
        );
        let w = state_clamp(&u, a, c * vmax);
        let mut x = 0.0;
        for (k, &wk) in w.iter().enumerate() {
            x = a * x + wk;
            let vk = x * (1.0 - a) / c;
            assert!(
                (vk - direct[k]).abs() <= 1e-12 * vmax,
                "k {k}: {vk} vs {}",
                direct[k]
            );
        }
        let sat = state_clamp(&u, 0.0, 0.1);
        for (s, &uk) in sat.iter().zip(&u) {
            assert_eq!(*s, uk.clamp(-0.1, 0.1));
        }
    }
}
