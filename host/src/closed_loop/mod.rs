//! Identification from closed-loop logs, and a test that tells when a log was recorded under
//! feedback.
//!
//! Why: with the loop closed, the plant input u = S·C·r − S·C·v depends on the output noise v
//! through the controller C. Direct N4SID on (u, y) then treats part of the noise as the input's
//! effect and converges to a mix of the plant G and the inverse controller −1/C (the more so
//! where the noise dominates the reference). The two methods here use the reference r, which
//! is independent of the noise, as the instrument:
//!
//! - [`ClosedLoopMethod::TwoStage`] (Van den Hof & Schrama 1993): stage 1 identifies the input
//!   sensitivity r → u (N4SID; the closed loop is stable, so this is an open-loop problem with
//!   r as input), stage 2 simulates it to get the noise-free part û of the input and
//!   identifies û → y. û is a function of r only, so the noise in y (S·v) is uncorrelated with
//!   it and stage 2 is an ordinary open-loop problem with the plant's order: N4SID, refined
//!   (SISO) by an output-error fit that coloured noise does not bias (see `iv.rs`; the plant model then has no Kalman gain). Works for stable
//!   and integrating plants (stage 2 simulates the plant model over the log, so a strictly
//!   unstable plant is refused with a pointer to the joint method).
//! - [`ClosedLoopMethod::JointInputOutput`] (Ljung 1999, §13.5): one N4SID model of
//!   r → [u; y] (the closed loop, stable even for an unstable plant), then
//!   G = G_yr·G_ur⁻¹ in state space: with u = C_u x + D_u r, r = D_u⁻¹(u − C_u x) and
//!   x⁺ = (A − B D_u⁻¹ C_u) x + B D_u⁻¹ u, y = (C_y − D_y D_u⁻¹ C_u) x + D_y D_u⁻¹ u. The result
//!   has the closed loop's order (plant + controller states; the controller's dynamics appear as
//!   near-cancelling pole/zero pairs) and needs a controller with direct feedthrough
//!   (D_u invertible: proportional action within the sample), else it is refused.
//!
//! The feedback detector ([`feedback_test`]) is in [`feedback`].
//!
//! Units: the model maps the log's input units to its output units; time in seconds.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
pub mod feedback;
mod iv;

pub use feedback::{feedback_test, FeedbackTest, FEEDBACK_SIGNIFICANCE};

use crate::error::{Error, Result};
use crate::lti::{StateSpace, TransferFunction};
use crate::n4sid::{self, ChannelSet, N4sidOptions, N4sidResult, OrderSelection};
use faer::Mat;
use serde::Serialize;

/// Which unbiased closed-loop method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum ClosedLoopMethod {
    /// Project u onto r (stage 1, r → u), identify û → y (stage 2): plant order.
    #[default]
    TwoStage,
    /// Identify r → [u; y], then G = G_yr·G_ur⁻¹: closed-loop order, unstable plants.
    JointInputOutput,
}

/// Options of [`identify_closed_loop`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClosedLoopOptions {
    /// The method.
    pub method: ClosedLoopMethod,
    /// N4SID options of the plant model (two-stage: stage 2; joint: the r → [u; y] model, whose
    /// order is the closed loop's, so a fixed order here should count the controller states).
    pub n4sid: N4sidOptions,
    /// Order of the stage-1 model r → u (two-stage only); `None`: automatic.
    pub stage1_order: Option<usize>,
}

impl Default for ClosedLoopOptions {
    fn default() -> Self {
        ClosedLoopOptions {
            method: ClosedLoopMethod::TwoStage,
            n4sid: N4sidOptions::default(),
            stage1_order: None,
        }
    }
}

/// Result of [`identify_closed_loop`].
#[derive(Debug, Clone)]
pub struct ClosedLoopResult {
    /// The method used.
    pub method: ClosedLoopMethod,
    /// The plant model u → y with its N4SID evidence. Two-stage: the stage-2 model (û → y).
    /// Joint: the r → [u; y] evidence with `model` replaced by G = G_yr·G_ur⁻¹ and no Kalman
    /// gain (the closed-loop one does not describe the plant's noise).
    pub plant: N4sidResult,
    /// The closed-loop model: two-stage r → u (stage 1), joint r → [u; y].
    pub closed_loop: StateSpace,
    /// Share of the (mean-removed) input's energy that the reference explains:
    /// 1 − ‖u − û‖²/‖u‖². Low values mean the reference excites little of the input and the
    /// estimate's variance is large.
    pub input_explained: Vec<f64>,
    /// Non-fatal findings.
    pub warnings: Vec<String>,
}

/// Serialisable summary of a [`ClosedLoopResult`] (for reports).
#[derive(Debug, Clone, Serialize)]
pub struct ClosedLoopSummary {
    /// The method used.
    pub method: ClosedLoopMethod,
    /// Order of the closed-loop model (stage 1 or r → [u; y]).
    pub closed_loop_order: usize,
    /// Share of each input's energy explained by the reference.
    pub input_explained: Vec<f64>,
    /// How the method works, in words.
    pub description: &'static str,
}

impl ClosedLoopResult {
    /// The serialisable summary.
    pub fn summary(&self) -> ClosedLoopSummary {
        ClosedLoopSummary {
            method: self.method,
            closed_loop_order: self.closed_loop.n_states(),
            input_explained: self.input_explained.clone(),
            description: match self.method {
                ClosedLoopMethod::TwoStage => {
                    "two-stage: stage 1 identifies reference -> input, stage 2 identifies the \
                     reference-driven part of the input -> output (unbiased under feedback)"
                }
                ClosedLoopMethod::JointInputOutput => {
                    "joint input-output: reference -> [input; output] identified, plant = \
                     G_yr * inv(G_ur) (unbiased under feedback; closed-loop order)"
                }
            },
        }
    }
}

/// Fraction of input energy below which the reference is said to explain little of the input.
const WEAK_REFERENCE: f64 = 0.05;

/// Identifies the plant u → y from a closed-loop log: `data` holds u (inputs) and y (outputs),
/// `r` the reference channels (as many as inputs, same length; the signal the loop tracks or
/// any excitation added inside the loop that is independent of the noise).
///
/// # Errors
/// [`Error::Data`] naming `data.source` for a reference of the wrong count, length, a
/// non-finite or constant reference; [`Error::Numerical`] when a stage's N4SID fails, the
/// two-stage plant model is unstable (use the joint method), or the joint method's D_u is
/// singular (no controller feedthrough).
pub fn identify_closed_loop(
    data: &ChannelSet<'_>,
    r: &[&[f64]],
    opts: &ClosedLoopOptions,
) -> Result<ClosedLoopResult> {
    check_reference(data, r)?;
    let r_names: Vec<String> = (0..r.len()).map(|j| format!("reference {j}")).collect();
    match opts.method {
        ClosedLoopMethod::TwoStage => two_stage(data, r, &r_names, opts),
        ClosedLoopMethod::JointInputOutput => joint(data, r, &r_names, opts),
    }
}

fn check_reference(data: &ChannelSet<'_>, r: &[&[f64]]) -> Result<()> {
    let err = |msg: String| Error::Data {
        file: data.source.to_path_buf(),
        msg,
    };
    let m = data.u.len();
    if r.len() != m {
        return Err(err(format!(
            "closed-loop identification needs one reference per input: {} references for {m} \
             inputs",
            r.len()
        )));
    }
    let len = data.u.first().map_or(0, |c| c.len());
    for (j, c) in r.iter().enumerate() {
        if c.len() != len {
            return Err(err(format!(
                "reference {j} has {} samples, the inputs {len}",
                c.len()
            )));
        }
        if let Some(k) = c.iter().position(|v| !v.is_finite()) {
            return Err(err(format!("reference {j} sample {k} is not finite")));
        }
        let (lo, hi) = c
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        if !(hi > lo) {
            return Err(err(format!(
                "reference {j} is constant: it excites nothing, the loop cannot be identified \
                 from it"
            )));
        }
    }
    Ok(())
}

/// Mean-removed copies of channels.
fn centred(ch: &[&[f64]]) -> Vec<Vec<f64>> {
    ch.iter().map(|c| crate::validate::demeaned(c)).collect()
}

fn explained(u: &[Vec<f64>], uhat: &[Vec<f64>]) -> Vec<f64> {
    u.iter()
        .zip(uhat)
        .map(|(a, b)| {
            let e: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
            let t: f64 = a.iter().map(|x| x * x).sum();
            if t > 0.0 {
                1.0 - e / t
            } else {
                0.0
            }
        })
        .collect()
}

fn weak_reference_warnings(expl: &[f64], warnings: &mut Vec<String>) {
    for (j, e) in expl.iter().enumerate() {
        if *e < WEAK_REFERENCE {
            warnings.push(format!(
                "the reference explains {:.1} % of input {j}'s energy: the closed-loop estimate \
                 rests on a small part of the data and its variance is large",
                100.0 * e.max(0.0)
            ));
        }
    }
}

fn two_stage(
    data: &ChannelSet<'_>,
    r: &[&[f64]],
    r_names: &[String],
    opts: &ClosedLoopOptions,
) -> Result<ClosedLoopResult> {
    let rc = centred(r);
    let uc = centred(data.u);
    let yc = centred(data.y);
    let rs: Vec<&[f64]> = rc.iter().map(Vec::as_slice).collect();
    let us: Vec<&[f64]> = uc.iter().map(Vec::as_slice).collect();
    let ys: Vec<&[f64]> = yc.iter().map(Vec::as_slice).collect();
    let stage1_opts = N4sidOptions {
        order: opts
            .stage1_order
            .map_or(OrderSelection::Auto, OrderSelection::Fixed),
        estimate_d: true,
        estimate_kalman_gain: false,
        ..opts.n4sid.clone()
    };
    let s1 = n4sid::identify(
        &ChannelSet {
            source: data.source,
            ts: data.ts,
            u: &rs,
            y: &us,
            u_names: r_names,
            y_names: data.u_names,
        },
        &stage1_opts,
    )
    .map_err(|e| Error::Numerical(format!("closed loop, stage 1 (reference -> input): {e}")))?;
    let uhat = s1.model.simulate(&rs, Some(&s1.x0))?;
    let input_explained = explained(&uc, &uhat);
    let mut warnings: Vec<String> = s1
        .warnings
        .iter()
        .map(|w| format!("stage 1 (reference -> input): {w}"))
        .collect();
    weak_reference_warnings(&input_explained, &mut warnings);
    let uh: Vec<&[f64]> = uhat.iter().map(Vec::as_slice).collect();
    let plant = n4sid::identify(
        &ChannelSet {
            source: data.source,
            ts: data.ts,
            u: &uh,
            y: &ys,
            u_names: data.u_names,
            y_names: data.y_names,
        },
        &opts.n4sid,
    )
    .map_err(|e| {
        Error::Numerical(format!(
            "closed loop, stage 2 (projected input -> output): {e}"
        ))
    })?;
    let mut plant = plant;
    if plant.model.is_siso() {
        plant.model = iv::refine(
            &plant.model,
            uh[0],
            ys[0],
            plant.order,
            opts.n4sid.estimate_d,
        )?;
        plant.x0 = vec![0.0; plant.model.n_states()];
        plant.kalman_gain = None;
        plant.innovation_cov = None;
    } else {
        warnings.push(
            "several inputs or outputs: stage 2 is the N4SID model alone (the output-error \
             refinement is SISO), which coloured noise can bias at a low order"
                .into(),
        );
    }
    let unstable = plant.model.poles()?.iter().any(|z| z.norm() > 1.0 + 1e-3);
    if unstable {
        return Err(Error::Numerical(format!(
            "{}: the two-stage plant model is unstable (a pole outside |z| = 1.001); the \
             two-stage method simulates the plant over the log and cannot hold an unstable one: \
             use the joint input-output method",
            data.source.display()
        )));
    }
    warnings.extend(
        plant
            .warnings
            .iter()
            .map(|w| format!("stage 2 (projected input -> output): {w}")),
    );
    Ok(ClosedLoopResult {
        method: ClosedLoopMethod::TwoStage,
        plant,
        closed_loop: s1.model,
        input_explained,
        warnings,
    })
}

fn joint(
    data: &ChannelSet<'_>,
    r: &[&[f64]],
    r_names: &[String],
    opts: &ClosedLoopOptions,
) -> Result<ClosedLoopResult> {
    let (m, p) = (data.u.len(), data.y.len());
    let rc = centred(r);
    let mut out = centred(data.u);
    out.extend(centred(data.y));
    let rs: Vec<&[f64]> = rc.iter().map(Vec::as_slice).collect();
    let os: Vec<&[f64]> = out.iter().map(Vec::as_slice).collect();
    let names: Vec<String> = data.u_names.iter().chain(data.y_names).cloned().collect();
    let cl_opts = N4sidOptions {
        estimate_d: true,
        d_significance: None,
        ..opts.n4sid.clone()
    };
    let mut cl = n4sid::identify(
        &ChannelSet {
            source: data.source,
            ts: data.ts,
            u: &rs,
            y: &os,
            u_names: r_names,
            y_names: &names,
        },
        &cl_opts,
    )
    .map_err(|e| {
        Error::Numerical(format!(
            "closed loop, joint model (reference -> [input; output]): {e}"
        ))
    })?;
    let t = &cl.model;
    let n = t.n_states();
    let cu = Mat::from_fn(m, n, |i, j| t.c[(i, j)]);
    let cy = Mat::from_fn(p, n, |i, j| t.c[(m + i, j)]);
    let du = Mat::from_fn(m, m, |i, j| t.d[(i, j)]);
    let dy = Mat::from_fn(p, m, |i, j| t.d[(m + i, j)]);
    let du_inv = invert_checked(t, &du, data)?;
    let b_dinv = &t.b * &du_inv;
    let a = &t.a - &b_dinv * &cu;
    let dy_dinv = &dy * &du_inv;
    let c = &cy - &dy_dinv * &cu;
    let mut plant_model = StateSpace::new(a, b_dinv, c, dy_dinv, t.ts)?;
    let uhat = t.simulate(&rs, Some(&cl.x0))?;
    let input_explained = explained(&out[..m], &uhat[..m]);
    let mut warnings: Vec<String> = cl
        .warnings
        .iter()
        .map(|w| format!("joint model (reference -> [input; output]): {w}"))
        .collect();
    if m == 1 && p == 1 {
        match joint_oe(t, rs[0], &out[0], &out[1], opts.n4sid.estimate_d) {
            Ok(g) => plant_model = g,
            Err(e) => warnings.push(format!(
                "joint model: the output-error refinement failed ({e}); the plant is the \
                 N4SID model alone, which coloured noise can bias"
            )),
        }
    } else {
        warnings.push(
            "several inputs or outputs: the joint plant model is the N4SID model alone (the \
             output-error refinement is SISO), which coloured noise can bias"
                .into(),
        );
    }
    weak_reference_warnings(&input_explained, &mut warnings);
    let closed_loop = std::mem::replace(&mut cl.model, plant_model);
    cl.kalman_gain = None;
    cl.innovation_cov = None;
    cl.x0 = vec![0.0; n];
    Ok(ClosedLoopResult {
        method: ClosedLoopMethod::JointInputOutput,
        plant: cl,
        closed_loop,
        input_explained,
        warnings,
    })
}

/// The SISO channel `row` of the closed-loop model `t` (reference -> [input; output]).
fn channel(t: &StateSpace, row: usize) -> Result<StateSpace> {
    let n = t.n_states();
    StateSpace::new(
        t.a.clone(),
        t.b.clone(),
        Mat::from_fn(1, n, |_, j| t.c[(row, j)]),
        Mat::from_fn(1, 1, |_, _| t.d[(row, 0)]),
        t.ts,
    )
}

/// Numerator of `tf` divided by the leading denominator coefficient, aligned to z^n .. z^0.
fn aligned_num(tf: &TransferFunction, n: usize) -> Vec<f64> {
    let lead = tf.den[0];
    let pad = (n + 1).saturating_sub(tf.num.len());
    (0..=n)
        .map(|k| if k < pad { 0.0 } else { tf.num[k - pad] / lead })
        .collect()
}

/// The joint method's plant, refined (SISO): one output-error fit of both closed-loop channels
/// with a common denominator, G_ur = B_u/F (r -> u, with feedthrough) and G_yr = B_y/F (r -> y),
/// started from the N4SID model, then G = G_yr/G_ur = B_y/B_u (F cancels exactly, so the plant
/// keeps the closed loop's order and no pole of G comes from a mismatch of two fitted
/// denominators). The channels are stable (the closed loop), so the output-error criterion can
/// be simulated even when the plant is unstable, and it is consistent whatever the noise colour
/// since r is independent of the noise; the N4SID model at the closed loop's order is not (the
/// Monte Carlo study in host/examples/closed_loop_unstable_study.rs finds its error on an
/// unstable plant is bias, 0.22 against a spread of 0.02). The plant's unstable poles are the
/// zeros of B_u.
fn joint_oe(
    t: &StateSpace,
    r: &[f64],
    u: &[f64],
    y: &[f64],
    y_feedthrough: bool,
) -> Result<StateSpace> {
    let n = t.n_states();
    let tu = channel(t, 0)?.to_transfer_function()?;
    let ty = channel(t, 1)?.to_transfer_function()?;
    let f0: Vec<f64> = tu.den[1..].iter().map(|v| v / tu.den[0]).collect();
    if f0.len() != n {
        return Err(Error::Numerical(format!(
            "closed loop, joint refinement: start denominator of degree {} for order {n}",
            f0.len()
        )));
    }
    let chans = [
        iv::Channel {
            num: aligned_num(&tu, n),
            y: u,
            feedthrough: true,
        },
        iv::Channel {
            num: aligned_num(&ty, n),
            y,
            feedthrough: y_feedthrough,
        },
    ];
    let (_, nums) = iv::refine_common(&f0, &chans, r)?;
    TransferFunction::new(nums[1].clone(), nums[0].clone(), t.ts)?.to_state_space()
}

/// Smallest |D_u| relative to the peak gain of G_ur accepted as controller feedthrough: below
/// it the estimate of D_u is indistinguishable from noise and its inverse meaningless.
pub const MIN_FEEDTHROUGH: f64 = 1e-2;

/// D_u⁻¹, refused when D_u is small against the peak gain of G_ur (r → u, the first `m`
/// outputs of `t`) on 200 frequencies up to Nyquist: the controller has no feedthrough.
fn invert_checked(t: &StateSpace, du: &Mat<f64>, data: &ChannelSet<'_>) -> Result<Mat<f64>> {
    let m = du.nrows();
    let nyq = 0.5 / t.ts;
    let freqs: Vec<f64> = (1..=200).map(|k| nyq * k as f64 / 200.0).collect();
    let mut peak = 0.0f64;
    for h in t.freq_responses_hz(&freqs)? {
        let g: f64 = (0..m)
            .flat_map(|i| (0..m).map(move |j| (i, j)))
            .map(|(i, j)| h[(i, j)].norm_sqr())
            .sum();
        peak = peak.max(g.sqrt());
    }
    let d: f64 = (0..m)
        .flat_map(|i| (0..m).map(move |j| (i, j)))
        .map(|(i, j)| du[(i, j)] * du[(i, j)])
        .sum::<f64>()
        .sqrt();
    let refuse = |detail: String| {
        Error::Numerical(format!(
            "{}: joint input-output method: {detail}; the reference -> input model has no usable \
             direct feedthrough, so G_ur cannot be inverted (the controller acts with a delay \
             of a sample or more): use the two-stage method",
            data.source.display()
        ))
    };
    if !(d > MIN_FEEDTHROUGH * peak) {
        return Err(refuse(format!(
            "|D_u| = {d:.3e} is below {MIN_FEEDTHROUGH} x the peak |G_ur| {peak:.3e}"
        )));
    }
    crate::lti::dense::solve_square(
        du.as_ref(),
        Mat::<f64>::identity(m, m).as_ref(),
        "D_u (reference -> input feedthrough)",
    )
    .map_err(|e| refuse(e.to_string()))
}
