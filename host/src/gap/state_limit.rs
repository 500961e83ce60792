//! The `state_limit` and `current_limit` effects: a level that saturates inside the plant,
//! realised on the modal linear part as a clamp of its slowest stable real mode
//! ([`limited_mode`]) — of its level ([`state_clamp`]) or of its rate ([`rate_clamp`]).
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

/// A current limit on the body mode x[k+1] = p·x[k] + w[k]: the input may exceed the one that
/// holds the present state, (1 − p)·x, by at most ±`limit`, so the mode's change per sample,
/// x[k+1] − x[k] = w − (1 − p)·x, is bounded: an acceleration (torque) limit. A voltage-driven
/// motor's current follows voltage − back-EMF (≈ the input that holds the present speed when
/// the armature is fast), so its current limit I_max is this clamp with `limit` = R·I_max.
/// With p = 0 the mode is the previous input, and the clamp a slew-rate limit of `limit` per
/// sample (the candidate is not fitted without a limitable mode: see the grid in `fit`).
pub fn rate_clamp(w: &[f64], p: f64, limit: f64) -> Vec<f64> {
    let mut x = 0.0;
    w.iter()
        .map(|&wk| {
            let hold = (1.0 - p) * x;
            let held = wk.min(hold + limit).max(hold - limit);
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
        let mut rng = crate::gap::simulator::rng::Rng::new(3);
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

    /// A sampled current-limited motor (the drive sets i = clamp((V − K·ω)/R, ±I_max) from the
    /// sampled speed and holds it; exact step of J·ω' = K·i − b·ω) against [`rate_clamp`] on
    /// its modal form with `limit` = R·I_max. The clamp holds the excess over the input that
    /// holds the speed, which includes the drag b·R/K·ω besides the back-EMF K·ω, so the two
    /// agree to O(b·R/K²): the largest speed error, relative to the peak speed, is below 5 %
    /// at b·R/K² = 0.01 and shrinks about tenfold at 0.001. Without the limit reached the
    /// clamp is the identity; with p = 0 it is a slew-rate limit.
    #[test]
    fn rate_clamp_is_a_current_limit_of_a_fast_armature_motor() {
        let (k, r, j, ts, imax): (f64, f64, f64, f64, f64) = (0.05, 1.0, 1e-5, 1e-3, 1.0);
        let mut rng = crate::gap::simulator::rng::Rng::new(7);
        let v: Vec<f64> = (0..6000).map(|_| 4.0 * rng.normal()).collect();
        let err = |drag: f64| -> f64 {
            let b = drag * k * k / r;
            let a = (-b * ts / j).exp();
            let p = a - (1.0 - a) * k * k / (b * r);
            let g = (1.0 - a) * k / (b * r);
            let mut w_direct = 0.0f64;
            let mut clamped = 0usize;
            let mut direct = Vec::new();
            for &vk in &v {
                let i_free = (vk - k * w_direct) / r;
                clamped += usize::from(i_free.abs() > imax);
                let i = i_free.clamp(-imax, imax);
                w_direct = a * w_direct + (1.0 - a) * k * i / b;
                direct.push(w_direct);
            }
            assert!(clamped > 300, "limit reached {clamped} times");
            let w = rate_clamp(&v, p, r * imax);
            let (mut x, mut worst, mut peak) = (0.0, 0.0f64, 0.0f64);
            for (kk, &wk) in w.iter().enumerate() {
                x = p * x + wk;
                worst = worst.max((g * x - direct[kk]).abs());
                peak = peak.max(direct[kk].abs());
            }
            worst / peak
        };
        let (e2, e3) = (err(1e-2), err(1e-3));
        eprintln!("relative speed error {e2} (b·R/K² = 0.01), {e3} (0.001)");
        assert!(e2 < 0.05, "b·R/K² = 0.01: relative speed error {e2}");
        assert!(e3 < 0.2 * e2, "b·R/K² = 0.001: {e3} vs {e2}");
        // Identity below the limit, a slew-rate limit at p = 0.
        let small: Vec<f64> = v.iter().map(|x| 1e-3 * x).collect();
        assert_eq!(rate_clamp(&small, 0.9, 1.0), small);
        let mut prev = 0.0;
        for (s, &uk) in rate_clamp(&v, 0.0, 0.5).iter().zip(&v) {
            assert_eq!(*s, uk.clamp(prev - 0.5, prev + 0.5));
            prev = *s;
        }
    }
}
