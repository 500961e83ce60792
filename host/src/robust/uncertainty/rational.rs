//! The W_m fit as a positive rational function of ω², solved by a primal log-barrier
//! interior-point method, then spectral factorisation.
//!
//! # Formulation
//! With x = (ω/ω_c)² (ω_c: geometric centre of the measured band, for scaling) every stable,
//! minimum-phase W_m of order n has |W_m(jω)|² = P(x)/Q(x), where P and Q are real polynomials
//! of degree n in x, non-negative on x >= 0, and conversely every such pair with Q > 0 on
//! x >= 0 and P > 0 there is the squared magnitude of one (spectral factorisation below). Q is
//! normalised monic (the ratio is scale-free). In the coefficients θ = (p_0..p_n, q_0..q_{n−1}):
//!
//! ```text
//! minimise   F(θ) = Σ_i w̄_i [ln P(x_i) − ln Q(x_i)]          (= 2·J + const, w̄ = w/Σw)
//! subject to P(x_i) − l_m(ω_i)²·Q(x_i) >= 0   at every measured bin   (linear in θ)
//!            P(x_g) >= 0, Q(x_g) >= 0          on a grid of x_g covering three decades of ω
//!                                              beyond the band each side, at x = 0 and as
//!                                              x → ∞ (p_n >= 0)                  (linear in θ)
//! ```
//!
//! The feasible set is a polyhedron. F is a difference of concave functions (ln P concave, −ln Q
//! convex), smooth on the interior. It is minimised by the barrier method:
//! φ_μ(θ) = F(θ) − (μ/m)·Σ_c ln c(θ) over the m constraint values c(θ) = a_cᵀθ + b_c, for μ
//! falling from 1e-2 to 1e-9 by ×0.1 (so the barrier adds at most about μ to F at the end),
//! each by damped Newton steps with a backtracking (Armijo) line search that keeps every
//! constraint strictly satisfied. The Newton matrix is the exact Hessian when it is positive
//! definite and otherwise drops the concave ln P curvature (which keeps a descent direction).
//! Every operation is deterministic; the problem has 2n + 1 ≤ 7 unknowns, so one Newton step
//! costs a pass over the constraints and a 7×7 Cholesky factorisation.
//!
//! F is not convex, so the method starts from the same families of starts as the reference
//! Nelder–Mead fit (a grid of corner frequencies, lightly damped poles at the envelope's peak,
//! the previous order's optimum extended by a cancelling pair), ranks them by their exact-gain
//! objective and runs the best few; the lowest exact J after factorisation wins. The previous
//! order's optimum with a cancelling pair is always a candidate, so order n + 1 is never looser
//! than order n.
//!
//! # Spectral factorisation
//! Each root r of P(x) gives the s-plane root s = −ω_c·√(−r) (principal square root, so
//! Re s < 0 unless r is real and positive, i.e. a zero on the jω axis, which is rejected):
//! num(s) = √p_n·Π(s − s_z), den(s) = Π(s − s_p), and |num/den(jω)|² = P(x)/Q(x).
use super::{build_weight, Band, UncertaintyWeight};
use crate::error::{Error, Result};
use crate::lti::{poly_from_roots, poly_roots};
use num_complex::Complex64;

const OBJECTIVE: &str = "minimise Σ_i w_i·ln(|W_m(jω_i)|/l_m(ω_i)) / Σ_i w_i (w_i: trapezoidal \
                         weights in ln ω) subject to |W_m(jω_i)| >= l_m(ω_i) at every measured \
                         frequency; |W_m|² = P(ω²)/Q(ω²) with P, Q >= 0 (linear constraints on \
                         the coefficients), log-barrier interior-point method, spectral \
                         factorisation to a stable, minimum-phase W_m";

/// Barrier parameter (per constraint, in units of F) at the first and the last stage, and the
/// reduction from one stage to the next.
const MU_START: f64 = 1e-2;
const MU_END: f64 = 1e-9;
const MU_FACTOR: f64 = 0.1;
/// Newton-decrement tolerance of an intermediate stage, relative to μ.
const STAGE_TOL: f64 = 1e-3;
/// Newton steps per barrier stage at most.
const NEWTON_MAX: usize = 50;
/// Exploration: every start follows the path to this μ with at most NEWTON_EXPLORE steps per
/// stage; the FINISH_RUNS best are then followed to MU_END.
const MU_EXPLORE: f64 = 1e-4;
const NEWTON_EXPLORE: usize = 20;
const FINISH_RUNS: usize = 3;
/// Cold starts run through the interior-point method per order (the best by their exact-gain
/// objective); every warm start is run as well.
const COLD_RUNS: usize = 4;
/// Positivity grid: points per decade of ω, decades beyond the band on each side.
const GRID_PER_DECADE: f64 = 8.0;
const GRID_DECADES_BEYOND: f64 = 3.0;

/// Coefficients of one candidate: P ascending (n + 1), Q ascending without its leading 1 (n).
#[derive(Debug, Clone)]
struct Coeffs {
    p: Vec<f64>,
    q: Vec<f64>,
}

/// A point on (near) the barrier path: coefficients θ, multipliers λ and the next μ.
struct PathPoint {
    th: Vec<f64>,
    lam: Vec<f64>,
    mu: f64,
}

/// The barrier problem of one order on one band.
struct Barrier<'a> {
    band: &'a Band,
    n: usize,
    /// Number of unknowns 2n + 1.
    d: usize,
    /// ω_c (rad/s).
    w_c: f64,
    /// Powers x_i^j, j = 0..=n, at the bins (row-major, bins × (n + 1)).
    xpow: Vec<f64>,
    /// l_m(ω_i)².
    l2: Vec<f64>,
    /// Normalised objective weights w̄_i.
    wbar: Vec<f64>,
    /// Constraint rows a_c (row-major, m × d) and offsets b_c.
    a: Vec<f64>,
    b: Vec<f64>,
    /// `a` column-major (d × m) and `xpow` column-major ((n + 1) × bins), for the vectorised
    /// passes of the Newton iteration.
    acol: Vec<f64>,
    xcol: Vec<f64>,
}

/// Scratch vectors of one path (no allocation inside the Newton iteration).
struct Scratch {
    /// Constraint values at a trial point (m).
    cons: Vec<f64>,
    /// Per-constraint or per-bin weights (max(m, bins)).
    tmp: Vec<f64>,
    /// P and Q at the bins.
    p: Vec<f64>,
    q: Vec<f64>,
}

impl<'a> Barrier<'a> {
    fn new(band: &'a Band, n: usize) -> Self {
        let nu = &band.nu;
        let m = nu.len();
        let w_c = (nu[0] * nu[m - 1]).sqrt();
        let d = 2 * n + 1;
        let powers = |x: f64| -> Vec<f64> {
            let mut v = Vec::with_capacity(n + 1);
            let mut t = 1.0;
            for _ in 0..=n {
                v.push(t);
                t *= x;
            }
            v
        };
        let xs: Vec<f64> = nu.iter().map(|w| (w / w_c) * (w / w_c)).collect();
        let xpow: Vec<f64> = xs.iter().flat_map(|&x| powers(x)).collect();
        let l2: Vec<f64> = band.env.iter().map(|l| l * l).collect();
        let wbar: Vec<f64> = band.weights.iter().map(|w| w / band.wsum).collect();
        let mut a = Vec::new();
        let mut b = Vec::new();
        // Overbound at every bin: Σ p_j x^j − l²·(Σ q_j x^j + x^n) >= 0.
        for (i, &l2i) in l2.iter().enumerate() {
            let v = &xpow[i * (n + 1)..(i + 1) * (n + 1)];
            a.extend_from_slice(v);
            a.extend(v[..n].iter().map(|t| -l2i * t));
            b.push(-l2i * v[n]);
        }
        // Positivity of P and Q on the grid, at x = 0 and (P) as x → ∞.
        let lo = (nu[0] / w_c).log10() - GRID_DECADES_BEYOND;
        let hi = (nu[m - 1] / w_c).log10() + GRID_DECADES_BEYOND;
        let npts = ((hi - lo) * GRID_PER_DECADE).ceil() as usize + 1;
        let mut grid: Vec<f64> = vec![0.0];
        grid.extend((0..npts).map(|k| {
            let e = lo + (hi - lo) * k as f64 / (npts - 1) as f64;
            10f64.powf(2.0 * e)
        }));
        for &x in &grid {
            let v = powers(x);
            a.extend_from_slice(&v);
            a.extend(std::iter::repeat_n(0.0, n));
            b.push(0.0);
            a.extend(std::iter::repeat_n(0.0, n + 1));
            a.extend_from_slice(&v[..n]);
            b.push(v[n]);
        }
        let mut lead = vec![0.0; d];
        lead[n] = 1.0;
        a.extend_from_slice(&lead);
        b.push(0.0);
        let mc = b.len();
        let acol = (0..d * mc).map(|k| a[(k % mc) * d + k / mc]).collect();
        let xcol = (0..(n + 1) * m)
            .map(|k| xpow[(k % m) * (n + 1) + k / m])
            .collect();
        Self {
            acol,
            xcol,
            band,
            n,
            d,
            w_c,
            xpow,
            l2,
            wbar,
            a,
            b,
        }
    }

    fn m(&self) -> usize {
        self.b.len()
    }

    /// (P(x_i), Q(x_i)) at bin i.
    fn pq(&self, th: &[f64], i: usize) -> (f64, f64) {
        let n = self.n;
        let v = &self.xpow[i * (n + 1)..(i + 1) * (n + 1)];
        let p: f64 = v.iter().zip(&th[..=n]).map(|(x, c)| x * c).sum();
        let q: f64 = v[n]
            + v[..n]
                .iter()
                .zip(&th[n + 1..])
                .map(|(x, c)| x * c)
                .sum::<f64>();
        (p, q)
    }

    fn constraint(&self, th: &[f64], c: usize) -> f64 {
        let row = &self.a[c * self.d..(c + 1) * self.d];
        row.iter().zip(th).map(|(a, t)| a * t).sum::<f64>() + self.b[c]
    }

    /// F(θ), or None outside the domain (P or Q not positive at a bin).
    fn objective(&self, th: &[f64]) -> Option<f64> {
        let mut f = 0.0;
        for (i, &w) in self.wbar.iter().enumerate() {
            let (p, q) = self.pq(th, i);
            if !(p > 0.0 && q > 0.0) {
                return None;
            }
            f += w * (p / q).ln();
        }
        Some(f)
    }

    fn scratch(&self) -> Scratch {
        let bins = self.l2.len();
        Scratch {
            cons: vec![0.0; self.m()],
            tmp: vec![0.0; self.m().max(bins)],
            p: vec![0.0; bins],
            q: vec![0.0; bins],
        }
    }

    /// All constraint values a_cᵀθ + b_c into `out` (column sweeps).
    fn constraints_into(&self, th: &[f64], out: &mut [f64]) {
        let m = self.m();
        out.copy_from_slice(&self.b);
        for (j, &t) in th.iter().enumerate() {
            for (o, a) in out.iter_mut().zip(&self.acol[j * m..(j + 1) * m]) {
                *o += t * a;
            }
        }
    }

    /// P and Q at every bin into `p`, `q` (column sweeps).
    fn pq_into(&self, th: &[f64], p: &mut [f64], q: &mut [f64]) {
        let (n, bins) = (self.n, self.l2.len());
        let col = |j: usize| &self.xcol[j * bins..(j + 1) * bins];
        p.fill(0.0);
        q.copy_from_slice(col(n));
        for (j, &t) in th[..=n].iter().enumerate() {
            for (o, x) in p.iter_mut().zip(col(j)) {
                *o += t * x;
            }
        }
        for j in 0..n {
            let t = th[n + 1 + j];
            for (o, x) in q.iter_mut().zip(col(j)) {
                *o += t * x;
            }
        }
    }

    /// φ_μ(θ) using `ws`, or None when a constraint is not strictly satisfied (or P, Q not
    /// positive at a bin).
    fn phi_ws(&self, th: &[f64], mu: f64, ws: &mut Scratch) -> Option<f64> {
        self.constraints_into(th, &mut ws.cons);
        // Σ ln c as ln of running products (one logarithm per few constraints), renormalised
        // well inside the f64 range.
        let (mut bar, mut prod) = (0.0, 1.0f64);
        for &v in &ws.cons {
            if !positive(v) {
                return None;
            }
            prod *= v;
            if !(1e-150..=1e150).contains(&prod) {
                bar += prod.ln();
                prod = 1.0;
            }
        }
        bar += prod.ln();
        self.pq_into(th, &mut ws.p, &mut ws.q);
        let mut f = 0.0;
        for ((&w, &p), &q) in self.wbar.iter().zip(&ws.p).zip(&ws.q) {
            if !(positive(p) && positive(q)) {
                return None;
            }
            f += w * (p / q).ln();
        }
        Some(f - mu / self.m() as f64 * bar)
    }

    /// The start of a barrier path at a strictly feasible θ (multipliers λ_c = μ_c/c).
    fn start(&self, th: Vec<f64>) -> PathPoint {
        let m = self.m();
        let lam = (0..m)
            .map(|c| MU_START / m as f64 / self.constraint(&th, c))
            .collect();
        PathPoint {
            th,
            lam,
            mu: MU_START,
        }
    }

    /// Follows the barrier path from `pt` down to μ = `mu_stop` (at most `newton_max` Newton
    /// steps per stage) by primal-dual Newton steps: the Newton matrix is
    /// ∇²F + Aᵀ·diag(λ/c)·A with multipliers λ carried along (so a reduction of μ does not cost
    /// boundary-limited steps), or its convex part when that is not positive definite; the step
    /// is accepted on φ_μ (Armijo, extended while φ_μ keeps falling) with a
    /// fraction-to-the-boundary rule on the constraints and on λ.
    fn advance(&self, pt: &mut PathPoint, mu_stop: f64, newton_max: usize) {
        let (d, m) = (self.d, self.m());
        let mut th = std::mem::take(&mut pt.th);
        let mut lam = std::mem::take(&mut pt.lam);
        let mut mu = pt.mu;
        let mut ws = self.scratch();
        let mut cval = vec![0.0; m];
        self.constraints_into(&th, &mut cval);
        let mut ad = vec![0.0; m];
        while mu >= mu_stop * 0.999 {
            let muc = mu / m as f64;
            // Centring accuracy of a stage: the barrier itself moves F by about μ, so an
            // intermediate stage needs only a fraction of μ; the last is solved tightly.
            let last = mu * MU_FACTOR < MU_END * 0.999;
            let stage_tol = if last { 1e-14 } else { STAGE_TOL * mu };
            for _ in 0..newton_max {
                let Some(f0) = self.phi_ws(&th, mu, &mut ws) else {
                    break;
                };
                let (g, hc, hp) = self.derivatives_pd(&th, muc, &cval, &lam, &mut ws);
                let full: Vec<f64> = hc.iter().zip(&hp).map(|(c, p)| c - p).collect();
                let fd = newton_direction(&full, &g, d, 0.0);
                let Some(dir) = fd
                    .or_else(|| newton_direction(&hc, &g, d, 0.0))
                    .or_else(|| newton_direction(&hc, &g, d, 1e-10))
                else {
                    break;
                };
                let slope: f64 = g.iter().zip(&dir).map(|(a, b)| a * b).sum();
                if !positive(-slope) || -slope < stage_tol {
                    break;
                }
                // Constraint rates and the largest feasible primal step.
                let mut amax = f64::INFINITY;
                ad.fill(0.0);
                for (j, &t) in dir.iter().enumerate() {
                    for (o, a) in ad.iter_mut().zip(&self.acol[j * m..(j + 1) * m]) {
                        *o += t * a;
                    }
                }
                for (&r, &c) in ad.iter().zip(&cval) {
                    if r < 0.0 {
                        amax = amax.min(-c / r);
                    }
                }
                let mut alpha = (0.99 * amax).min(1.0);
                let mut moved = false;
                let mut f_acc = f0;
                while alpha > 1e-14 {
                    let trial: Vec<f64> = th.iter().zip(&dir).map(|(t, s)| t + alpha * s).collect();
                    if let Some(f1) = self.phi_ws(&trial, mu, &mut ws) {
                        if f1 <= f0 + 1e-4 * alpha * slope {
                            th = trial;
                            f_acc = f1;
                            moved = true;
                            break;
                        }
                    }
                    alpha *= 0.5;
                }
                // A full step that stayed far from the boundary: the local model was too
                // cautious (the concave curvature was dropped, or F is nearly linear here), so
                // extend the step while φ keeps falling.
                if moved && alpha == 1.0 && amax > 2.0 {
                    let base = th.clone();
                    let mut a = 2.0;
                    while a < 0.99 * amax && a <= 64.0 {
                        let trial: Vec<f64> = base
                            .iter()
                            .zip(&dir)
                            .map(|(t, s)| t + (a - 1.0) * s)
                            .collect();
                        match self.phi_ws(&trial, mu, &mut ws) {
                            Some(f1) if f1 < f_acc => {
                                th = trial;
                                f_acc = f1;
                                a *= 2.0;
                            }
                            _ => break,
                        }
                    }
                }
                if !moved {
                    break;
                }
                // Dual step: dλ = μ_c/c − λ − (λ/c)·(A dθ), fraction to the boundary.
                let mut adual = 1.0f64;
                let dl: Vec<f64> = (0..m)
                    .map(|c| muc / cval[c] - lam[c] - lam[c] / cval[c] * ad[c])
                    .collect();
                for c in 0..m {
                    if dl[c] < 0.0 {
                        adual = adual.min(-0.99 * lam[c] / dl[c]);
                    }
                }
                for (l, d) in lam.iter_mut().zip(&dl) {
                    *l += adual * d;
                }
                self.constraints_into(&th, &mut cval);
                if -slope < stage_tol * 100.0 {
                    break;
                }
            }
            mu *= MU_FACTOR;
        }
        *pt = PathPoint { th, lam, mu };
    }

    /// Gradient of φ_μ (μ_c = μ/m per constraint), the convex part of the Newton matrix
    /// (∇²(−Σ w̄ ln Q) + Aᵀ·diag(λ/c)·A) and the concave part (−∇²Σ w̄ ln P, positive
    /// semidefinite), both d × d row-major.
    fn derivatives_pd(
        &self,
        th: &[f64],
        muc: f64,
        cval: &[f64],
        lam: &[f64],
        ws: &mut Scratch,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (n, d, m, bins) = (self.n, self.d, self.m(), self.l2.len());
        let mut g = vec![0.0; d];
        let mut hc = vec![0.0; d * d];
        let mut hp = vec![0.0; d * d];
        self.pq_into(th, &mut ws.p, &mut ws.q);
        let xc = |j: usize| &self.xcol[j * bins..(j + 1) * bins];
        // Objective: ∂/∂p_j Σ w̄ ln P = Σ w̄ x^j/P; curvature Σ w̄ x^j x^k/P² (and for Q).
        let tmp = &mut ws.tmp[..bins];
        for ((t, &w), &p) in tmp.iter_mut().zip(&self.wbar).zip(&ws.p) {
            *t = w / p;
        }
        for (j, gj) in g[..=n].iter_mut().enumerate() {
            *gj += dot(tmp, xc(j));
        }
        for ((t, &w), &p) in tmp.iter_mut().zip(&self.wbar).zip(&ws.p) {
            *t = w / (p * p);
        }
        let mut col = vec![0.0; bins.max(m)];
        for j in 0..=n {
            for ((c, &t), &x) in col.iter_mut().zip(tmp.iter()).zip(xc(j)) {
                *c = t * x;
            }
            for k in 0..=j {
                hp[j * d + k] = dot(&col[..bins], xc(k));
            }
        }
        for ((t, &w), &q) in tmp.iter_mut().zip(&self.wbar).zip(&ws.q) {
            *t = w / q;
        }
        for j in 0..n {
            g[n + 1 + j] -= dot(tmp, xc(j));
        }
        for ((t, &w), &q) in tmp.iter_mut().zip(&self.wbar).zip(&ws.q) {
            *t = w / (q * q);
        }
        for j in 0..n {
            for ((c, &t), &x) in col.iter_mut().zip(tmp.iter()).zip(xc(j)) {
                *c = t * x;
            }
            for k in 0..=j {
                hc[(n + 1 + j) * d + n + 1 + k] = dot(&col[..bins], xc(k));
            }
        }
        // Barrier: gradient −μ_c Σ a_c/c, Newton matrix Σ (λ_c/c)·a_c a_cᵀ.
        let ac = |j: usize| &self.acol[j * m..(j + 1) * m];
        let tmp = &mut ws.tmp[..m];
        for (t, &c) in tmp.iter_mut().zip(cval) {
            *t = muc / c;
        }
        for (j, gj) in g.iter_mut().enumerate() {
            *gj -= dot(tmp, ac(j));
        }
        for ((t, &c), &l) in tmp.iter_mut().zip(cval).zip(lam) {
            *t = l / c;
        }
        for j in 0..d {
            for ((c, &t), &a) in col.iter_mut().zip(tmp.iter()).zip(ac(j)) {
                *c = t * a;
            }
            for k in 0..=j {
                hc[j * d + k] += dot(&col[..m], ac(k));
            }
        }
        for j in 0..d {
            for k in 0..j {
                hc[k * d + j] = hc[j * d + k];
                hp[k * d + j] = hp[j * d + k];
            }
        }
        (g, hc, hp)
    }

    fn theta(&self, c: &Coeffs) -> Vec<f64> {
        c.p.iter().chain(&c.q).copied().collect()
    }

    fn coeffs(&self, th: &[f64]) -> Coeffs {
        Coeffs {
            p: th[..=self.n].to_vec(),
            q: th[self.n + 1..].to_vec(),
        }
    }

    /// Exact-gain objective of a candidate whose P is known up to scale: scales P to the
    /// smallest feasible level and returns (F, scaled coefficients).
    fn scaled(&self, c: &Coeffs, margin: f64) -> Option<(f64, Coeffs)> {
        let th = self.theta(c);
        let mut worst = 0.0f64;
        for i in 0..self.l2.len() {
            let (p, q) = self.pq(&th, i);
            if !(p > 0.0 && q > 0.0) {
                return None;
            }
            worst = worst.max(self.l2[i] * q / p);
        }
        let k = worst * margin;
        let out = Coeffs {
            p: c.p.iter().map(|v| v * k).collect(),
            q: c.q.clone(),
        };
        let f = self.objective(&self.theta(&out))?;
        f.is_finite().then_some((f, out))
    }

    /// W_m from (P, Q) by spectral factorisation; None when a root lies on the jω axis.
    fn weight(&self, c: &Coeffs) -> Option<UncertaintyWeight> {
        let pn = c.p[self.n];
        if !positive(pn) {
            return None;
        }
        let s_roots = |asc: Vec<f64>| -> Option<Vec<Complex64>> {
            let desc: Vec<f64> = asc.into_iter().rev().collect();
            let r = poly_roots(&desc).ok()?;
            let s: Vec<Complex64> = r.iter().map(|r| -(-r).sqrt() * self.w_c).collect();
            s.iter()
                .all(|z| z.re < 0.0 && z.re.is_finite() && z.im.is_finite())
                .then_some(s)
        };
        let zs = s_roots(c.p.clone())?;
        let mut q = c.q.clone();
        q.push(1.0);
        let ps = s_roots(q)?;
        let k = pn.sqrt();
        let num: Vec<f64> = poly_from_roots(&zs).ok()?.iter().map(|v| v * k).collect();
        let den = poly_from_roots(&ps).ok()?;
        if num.len() != self.n + 1 || den.len() != self.n + 1 {
            return None;
        }
        build_weight(self.n, num, den, self.band, OBJECTIVE).ok()
    }
}

/// Newton direction −H⁻¹g by Cholesky on the diagonally equilibrated H; None when H is not
/// (numerically) positive definite.
fn newton_direction(h: &[f64], g: &[f64], d: usize, ridge: f64) -> Option<Vec<f64>> {
    let s: Vec<f64> = (0..d)
        .map(|j| {
            let v = h[j * d + j];
            (v > 0.0).then(|| 1.0 / v.sqrt())
        })
        .collect::<Option<_>>()?;
    let mut l = vec![0.0; d * d];
    for j in 0..d {
        for k in 0..=j {
            let mut v = h[j * d + k] * s[j] * s[k] + if j == k { ridge } else { 0.0 };
            for t in 0..k {
                v -= l[j * d + t] * l[k * d + t];
            }
            if j == k {
                if !positive(v - 1e-13) {
                    return None;
                }
                l[j * d + j] = v.sqrt();
            } else {
                l[j * d + k] = v / l[k * d + k];
            }
        }
    }
    let mut y: Vec<f64> = (0..d).map(|j| -g[j] * s[j]).collect();
    for j in 0..d {
        for t in 0..j {
            y[j] -= l[j * d + t] * y[t];
        }
        y[j] /= l[j * d + j];
    }
    for j in (0..d).rev() {
        for t in j + 1..d {
            y[j] -= l[t * d + j] * y[t];
        }
        y[j] /= l[j * d + j];
    }
    let dir: Vec<f64> = y.iter().zip(&s).map(|(y, s)| y * s).collect();
    dir.iter().all(|v| v.is_finite()).then_some(dir)
}

/// Dot product with four independent accumulators (the long sums of the Newton matrix are
/// latency-bound otherwise).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a4, b4) = (a[..n].chunks_exact(4), b[..n].chunks_exact(4));
    let (ra, rb) = (a4.remainder(), b4.remainder());
    let mut acc = [0.0f64; 4];
    for (x, y) in a4.zip(b4) {
        for k in 0..4 {
            acc[k] += x[k] * y[k];
        }
    }
    let tail: f64 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// True for a number > 0 (false for NaN).
fn positive(v: f64) -> bool {
    v > 0.0
}

/// Ascending product of two ascending polynomials.
fn mul_asc(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut r = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            r[i + j] += x * y;
        }
    }
    r
}

/// |section(jω)|² as an ascending polynomial in x = (ω/ω_c)²: a real root at −a gives x + ã²,
/// a quadratic s² + 2ζω₀s + ω₀² gives x² + (4ζ² − 2)ω̃₀²x + ω̃₀⁴ (tilde: divided by ω_c).
fn sections_poly(quads: &[(f64, f64)], reals: &[f64], w_c: f64) -> Vec<f64> {
    let mut p = vec![1.0];
    for &(w, z) in quads {
        let wt = (w / w_c) * (w / w_c);
        p = mul_asc(&p, &[wt * wt, (4.0 * z * z - 2.0) * wt, 1.0]);
    }
    for &a in reals {
        let at = a / w_c;
        p = mul_asc(&p, &[at * at, 1.0]);
    }
    p
}

/// Fits W_m of every order 1..=`order` (module docs), in increasing order.
pub(super) fn fit_orders(band: &Band, order: usize) -> Result<Vec<UncertaintyWeight>> {
    let nu = &band.nu;
    let m = nu.len();
    let (w_lo, w_hi) = (nu[0], nu[m - 1]);
    let grid = crate::robust::norms::logspace(w_lo / 10.0, w_hi * 10.0, 7);
    let ipk = (0..m)
        .max_by(|&a, &b| band.ln_l[a].total_cmp(&band.ln_l[b]))
        .unwrap_or(0);
    let wpk = nu[ipk];
    let mut fits: Vec<UncertaintyWeight> = Vec::new();
    let mut prev: Option<Coeffs> = None;
    for n in 1..=order {
        let bar = Barrier::new(band, n);
        let w_c = bar.w_c;
        // (zero sections, pole sections) of every cold start, as in the reference fit.
        type Half = (Vec<(f64, f64)>, Vec<f64>);
        let mut starts: Vec<(Half, Half)> = Vec::new();
        for &wz in &grid {
            for &wp in &grid {
                match n {
                    1 => starts.push(((vec![], vec![wz]), (vec![], vec![wp]))),
                    2 => {
                        for z in [0.3, 1.0] {
                            starts.push(((vec![(wz, z)], vec![]), (vec![(wp, z)], vec![])));
                        }
                    }
                    _ => starts.push(((vec![(wz, 0.7)], vec![wz]), (vec![(wp, 0.7)], vec![wp]))),
                }
            }
        }
        if n >= 2 {
            for &wz in &grid {
                for zeta in [0.03, 0.1, 0.3] {
                    if n == 2 {
                        starts.push(((vec![(wz, 0.7)], vec![]), (vec![(wpk, zeta)], vec![])));
                    } else {
                        starts.push(((vec![(wz, 0.7)], vec![wz]), (vec![(wpk, zeta)], vec![w_hi])));
                    }
                }
            }
        }
        let cold: Vec<Coeffs> = starts
            .iter()
            .map(|((zq, zr), (pq, pr))| {
                let q = sections_poly(pq, pr, w_c);
                Coeffs {
                    p: sections_poly(zq, zr, w_c),
                    q: q[..n].to_vec(),
                }
            })
            .collect();
        let mut scored: Vec<(f64, Coeffs)> =
            cold.iter().filter_map(|c| bar.scaled(c, 1.02)).collect();
        scored.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut runs: Vec<Coeffs> = scored.into_iter().take(COLD_RUNS).map(|(_, c)| c).collect();
        // Warm starts: the previous optimum times a cancelling factor (x + c²) on P and Q, for
        // every c of the grid (they all start at the previous order's J, and lead to different
        // optima, so all are run).
        let mut embedded: Option<Coeffs> = None;
        if let Some(pc) = &prev {
            let mut q = pc.q.clone();
            q.push(1.0);
            let extend = |ct: f64| {
                let f = [ct, 1.0];
                let qn = mul_asc(&q, &f);
                Coeffs {
                    p: mul_asc(&pc.p, &f),
                    q: qn[..n].to_vec(),
                }
            };
            for &c in &grid {
                if let Some((_, s)) = bar.scaled(&extend((c / w_c) * (c / w_c)), 1.02) {
                    runs.push(s);
                }
            }
            embedded = Some(extend(1.0));
        }
        let mut best: Option<(f64, UncertaintyWeight, Coeffs)> = None;
        let consider = |c: Coeffs, best: &mut Option<(f64, UncertaintyWeight, Coeffs)>| {
            if let Some(w) = bar.weight(&c) {
                let j = w.mean_overbound_db;
                if w.constraint_holds && best.as_ref().is_none_or(|b| j < b.0) {
                    *best = Some((j, w, c));
                }
            }
        };
        // Explore every start along the path to μ = MU_EXPLORE, then finish the best few
        // (ranked by their exact-gain objective there).
        let mut pts: Vec<PathPoint> = runs.into_iter().map(|c| bar.start(bar.theta(&c))).collect();
        for pt in &mut pts {
            bar.advance(pt, MU_EXPLORE, NEWTON_EXPLORE);
        }
        let mut ranked: Vec<(f64, PathPoint)> = pts
            .into_iter()
            .filter_map(|pt| Some((bar.scaled(&bar.coeffs(&pt.th), 1.0)?.0, pt)))
            .collect();
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (_, mut pt) in ranked.into_iter().take(FINISH_RUNS) {
            bar.advance(&mut pt, MU_END, NEWTON_MAX);
            consider(bar.coeffs(&pt.th), &mut best);
        }
        if let Some(e) = embedded {
            consider(e, &mut best);
        }
        let (_, w, c) = best.ok_or_else(|| {
            Error::Numerical(format!(
                "uncertainty weight: no order-{n} candidate factorised to a stable, \
                 minimum-phase weight"
            ))
        })?;
        fits.push(w);
        prev = Some(c);
    }
    Ok(fits)
}
