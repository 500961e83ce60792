//! The firmware ADMM against an f64 design built here (a second, dense implementation of the
//! condensed QP) and the KKT conditions of its solution; a constrained step stays on the rails.
use super::*;

const N: usize = 10;

/// x⁺ = A x + B u, y = C x: two lags in series (dc gain 1), sampled.
fn plant() -> ([[f64; 2]; 2], [f64; 2], [f64; 2]) {
    ([[0.9, 0.0], [0.08, 0.95]], [0.1, 0.0], [0.0, 0.625])
}

/// Dense f64 Gauss–Jordan inverse.
fn inverse(mut a: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
    let n = a.len();
    let mut inv: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
        .collect();
    for c in 0..n {
        let p = (c..n)
            .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
            .unwrap();
        a.swap(c, p);
        inv.swap(c, p);
        let d = a[c][c];
        for j in 0..n {
            a[c][j] /= d;
            inv[c][j] /= d;
        }
        for i in 0..n {
            if i != c {
                let m = a[i][c];
                for j in 0..n {
                    a[i][j] -= m * a[c][j];
                    inv[i][j] -= m * inv[c][j];
                }
            }
        }
    }
    inv
}

struct Dense {
    h: Vec<Vec<f64>>,
    gx: Vec<[f64; 2]>,
    gr: Vec<f64>,
}

fn design(q: f64, r_rate: f64, rho: f64, sigma: f64) -> (MpcQp<N, 2>, Dense) {
    let (a, b, c) = plant();
    // Markov parameters C A^k B and rows C A^{k+1}.
    let (mut ak_b, mut c_ak) = (b, c);
    let mut markov = [0.0; N];
    let mut phi = [[0.0; 2]; N];
    for k in 0..N {
        markov[k] = c[0] * ak_b[0] + c[1] * ak_b[1];
        ak_b = [
            a[0][0] * ak_b[0] + a[0][1] * ak_b[1],
            a[1][0] * ak_b[0] + a[1][1] * ak_b[1],
        ];
        c_ak = [
            c_ak[0] * a[0][0] + c_ak[1] * a[1][0],
            c_ak[0] * a[0][1] + c_ak[1] * a[1][1],
        ];
        phi[k] = c_ak;
    }
    let gam = |k: usize, j: usize| if j <= k { markov[k - j] } else { 0.0 };
    let dm = |i: usize, j: usize| {
        if i == j {
            1.0
        } else if j + 1 == i {
            -1.0
        } else {
            0.0
        }
    };
    let h: Vec<Vec<f64>> = (0..N)
        .map(|i| {
            (0..N)
                .map(|j| {
                    let gg: f64 = (0..N).map(|k| gam(k, i) * gam(k, j)).sum();
                    let dd: f64 = (0..N).map(|k| dm(k, i) * dm(k, j)).sum();
                    2.0 * (q * gg + r_rate * dd)
                })
                .collect()
        })
        .collect();
    let kk: Vec<Vec<f64>> = (0..N)
        .map(|i| {
            (0..N)
                .map(|j| {
                    let mtm = (if i == j { 1.0 } else { 0.0 })
                        + (0..N).map(|k| dm(k, i) * dm(k, j)).sum::<f64>();
                    h[i][j] + if i == j { sigma } else { 0.0 } + rho * mtm
                })
                .collect()
        })
        .collect();
    let k = inverse(kk);
    let gx: Vec<[f64; 2]> = (0..N)
        .map(|j| {
            let mut s = [0.0; 2];
            for kk in 0..N {
                s[0] += 2.0 * q * gam(kk, j) * phi[kk][0];
                s[1] += 2.0 * q * gam(kk, j) * phi[kk][1];
            }
            s
        })
        .collect();
    let gr: Vec<f64> = (0..N)
        .map(|j| 2.0 * q * (0..N).map(|kk| gam(kk, j)).sum::<f64>())
        .collect();
    let qp = MpcQp::<N, 2> {
        k: core::array::from_fn(|i| core::array::from_fn(|j| k[i][j] as f32)),
        gx: core::array::from_fn(|i| [gx[i][0] as f32, gx[i][1] as f32]),
        gr: core::array::from_fn(|i| gr[i] as f32),
        two_r_rate: (2.0 * r_rate) as f32,
        sigma: sigma as f32,
        rho: rho as f32,
        u_min: -1.5,
        u_max: 1.5,
        du_max: 0.2,
        iterations: 40,
    };
    (qp, Dense { h, gx, gr })
}

#[test]
fn admm_solution_meets_the_kkt_conditions_of_the_f64_qp() {
    let (qp, d) = design(1.0, 0.05, 1.0, 1e-6);
    let (x, r, u_prev) = ([0.3f32, -0.2], 2.0f32, 0.1f32);
    let f = qp.linear_term(&x, r, u_prev);
    // f against the dense f64 formula G_x·x − g_r·r − 2ρ_Δ·e₁·u_prev.
    for i in 0..N {
        let fi = d.gx[i][0] * 0.3
            - d.gx[i][1] * 0.2
            - d.gr[i] * 2.0
            - if i == 0 { 2.0 * 0.05 * 0.1 } else { 0.0 };
        assert!(
            (f[i] as f64 - fi).abs() <= 1e-5 * fi.abs().max(1.0),
            "f[{i}]"
        );
    }
    let mut w = MpcWarm::<N>::default();
    qp.solve(&mut w, &f, u_prev, 3000);
    let u: Vec<f64> = w.u.iter().map(|&v| v as f64).collect();
    let tol = 2e-3;
    let mut active = 0;
    for i in 0..N {
        assert!(u[i] >= -1.5 - tol && u[i] <= 1.5 + tol, "box {i}: {}", u[i]);
        let du = if i == 0 {
            u[0] - u_prev as f64
        } else {
            u[i] - u[i - 1]
        };
        assert!(du.abs() <= 0.2 + tol, "rate {i}: {du}");
        if w.l_rate[i].abs() > 1e-3 {
            assert!(
                (du.abs() - 0.2).abs() < tol,
                "rate {i} multiplier off the bound"
            );
            active += 1;
        }
        if w.l_box[i].abs() > 1e-3 {
            assert!(
                (u[i].abs() - 1.5).abs() < tol,
                "box {i} multiplier off the bound"
            );
            active += 1;
        }
    }
    assert!(active > 0);
    // Stationarity: H U + f + Mᵀλ = 0.
    let scale = f.iter().map(|v| v.abs() as f64).fold(0.0, f64::max);
    for j in 0..N {
        let hu: f64 = (0..N).map(|k| d.h[j][k] * u[k]).sum();
        let next = if j + 1 < N {
            w.l_rate[j + 1] as f64
        } else {
            0.0
        };
        let r = hu + f[j] as f64 + w.l_box[j] as f64 + w.l_rate[j] as f64 - next;
        assert!(r.abs() < 1e-3 * scale, "stationarity {j}: {r:.3e}");
    }
}

#[test]
fn constrained_step_stays_on_the_rails_and_tracks() {
    let (qp, _) = design(1.0, 0.05, 1.0, 1e-6);
    let (a, b, c) = plant();
    let mut w = MpcWarm::<N>::default();
    let (mut x, mut u_prev, mut y) = ([0.0f32; 2], 0.0f32, 0.0f32);
    for _ in 0..400 {
        let u = qp.step(&mut w, &x, 1.2, u_prev);
        assert!((-1.5..=1.5).contains(&u));
        assert!((u - u_prev).abs() <= 0.2 + 1e-6);
        x = [
            a[0][0] as f32 * x[0] + a[0][1] as f32 * x[1] + b[0] as f32 * u,
            a[1][0] as f32 * x[0] + a[1][1] as f32 * x[1] + b[1] as f32 * u,
        ];
        y = c[0] as f32 * x[0] + c[1] as f32 * x[1];
        u_prev = u;
    }
    assert!((y - 1.2).abs() < 0.02, "y = {y}");
}
