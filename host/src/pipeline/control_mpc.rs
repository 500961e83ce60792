//! `[control] method = "mpc"` (issue 14): the condensed MPC of [`crate::synth::mpc`] on G0,
//! its receipts and its codegen block (see [`super::control_stage`] for the other methods).
//!
//! The MPC is a state-feedback law on the model's state with the input box ±actuator_limit
//! and a rate limit, solved by ADMM with a fixed budget per sample (what the firmware runs).
//! Receipts ([`mpc_receipts`]): `controller_design` (−3 dB bandwidth of the unconstrained
//! law's closed loop r → y), `closed_loop_stable` (that loop's pole modulus), and the
//! constrained step from the host simulation of the fixed-budget law: `step_actuator_demand`
//! (rails and rate limit respected), `step_overshoot`, `step_settling_time`. The
//! frequency-domain loop receipts need an LTI output-feedback controller and are listed in
//! `control.not_applicable` with the reason.
//!
//! When the run's gap verdict names one effect the step simulation can place
//! (`diagnosed_effect`), the three step receipts simulate it between the MPC and G0
//! ([`MpcDesign::closed_loop_step_with`]): they gate the run on the plant as diagnosed. The
//! same step on G0 alone goes to `control.linear_step_receipts` (comparable with the other
//! methods' step receipts and the QEMU replay), and `control.step_effect` says which effect was
//! simulated or why none was. Without a verdict effect nothing changes.
use super::config::PipelineConfig;
use super::control_stage::{
    design_receipt, finding, ControlMethod, ControlOutcome, ControlStageInputs, DesignSummary,
    MpcSpecSummary, NotApplicable,
};
use super::{fmt_num, log_grid};
use crate::error::Result;
use crate::robust::receipts::{
    push_failed_step_receipts, push_step_shape_receipts, Comparison, Receipt, ReceiptKind,
    ReceiptLimits, Receipts,
};
use crate::synth::mpc::{MpcDesign, MpcSpec, MpcStep, UnconstrainedLaw};

/// Default of `control.mpc_horizon`.
pub const DEFAULT_MPC_HORIZON: usize = 10;
/// Largest `control.mpc_horizon` (the firmware's K is N² f32: 16 KiB at 64).
pub const MAX_MPC_HORIZON: usize = 64;
/// Default of `control.mpc_output_weight`.
pub const DEFAULT_MPC_OUTPUT_WEIGHT: f64 = 1.0;
/// Default of `control.mpc_rate_weight`.
pub const DEFAULT_MPC_RATE_WEIGHT: f64 = 1e-2;
/// Default of `control.mpc_rate_limit` as a fraction of the actuator limit.
pub const DEFAULT_MPC_RATE_FRACTION: f64 = 1.0 / 6.0;
/// Default of `control.mpc_rho`.
pub const DEFAULT_MPC_RHO: f64 = 1.0;
/// Default of `control.mpc_iterations`.
pub const DEFAULT_MPC_ITERATIONS: usize = 60;
/// Largest `control.mpc_iterations` (the firmware counts them in a u16).
pub const MAX_MPC_ITERATIONS: usize = 10_000;

/// The MPC's settings from `[control]` (defaults filled in): box ±actuator_limit.
pub fn mpc_spec(c: &PipelineConfig) -> MpcSpec {
    let k = &c.control;
    MpcSpec {
        horizon: k.mpc_horizon.unwrap_or(DEFAULT_MPC_HORIZON),
        q: k.mpc_output_weight.unwrap_or(DEFAULT_MPC_OUTPUT_WEIGHT),
        r_rate: k.mpc_rate_weight.unwrap_or(DEFAULT_MPC_RATE_WEIGHT),
        u_min: -k.actuator_limit,
        u_max: k.actuator_limit,
        du_max: k
            .mpc_rate_limit
            .unwrap_or(DEFAULT_MPC_RATE_FRACTION * k.actuator_limit),
        rho: k.mpc_rho.unwrap_or(DEFAULT_MPC_RHO),
        iterations: k.mpc_iterations.unwrap_or(DEFAULT_MPC_ITERATIONS),
    }
}

/// Why the frequency-domain loop receipts do not apply to the MPC.
const MPC_NOT_APPLICABLE: [(ReceiptKind, &str); 7] = [
    (ReceiptKind::GainMargin, "a gain margin of the output loop"),
    (
        ReceiptKind::PhaseMargin,
        "a phase margin of the output loop",
    ),
    (ReceiptKind::SensitivityPeak, "S = 1/(1 + G·K)"),
    (
        ReceiptKind::ComplementarySensitivityPeak,
        "T = G·K/(1 + G·K)",
    ),
    (
        ReceiptKind::RobustStability,
        "‖W_m T‖∞ on T of the output loop",
    ),
    (
        ReceiptKind::DisturbanceRejectionBandwidth,
        "the −3 dB frequency of |S|",
    ),
    (ReceiptKind::PeakControlEffort, "‖KS‖∞ of an LTI K"),
];

/// Designs the MPC on G0, simulates its constrained step and fills `out` (receipts, design,
/// step, not-applicable list). Returns the crossover the receipt limits refer to (the target).
pub(super) fn run_mpc(
    c: &PipelineConfig,
    inp: &ControlStageInputs<'_>,
    out: &mut ControlOutcome,
) -> Result<f64> {
    let k = &c.control;
    let fc = k.crossover_hz;
    let spec = mpc_spec(c);
    let d = match finding(MpcDesign::new(inp.model, spec))? {
        Ok(d) => d,
        Err(e) => {
            let e = format!("MPC design: {e}");
            out.receipts.push(design_receipt(
                c,
                ControlMethod::Mpc,
                Err(&e),
                out.baseline_pid_crossover_hz,
            ));
            out.error = Some(e);
            return Ok(fc);
        }
    };
    let limits = super::stages::receipt_limits(c, fc);
    let r = mpc_receipts(c, inp, &d, &limits)?;
    for x in r.receipts.receipts {
        out.receipts.push(x);
    }
    out.not_applicable = MPC_NOT_APPLICABLE
        .iter()
        .map(|(kind, what)| NotApplicable {
            name: kind.name().to_string(),
            reason: format!(
                "the MPC is a state-feedback law on the model's state (the host simulation \
                 feeds back the model state exactly; no observer is designed) whose constrained \
                 form is nonlinear: there is no LTI output-feedback controller K, so no {what}"
            ),
        })
        .collect();
    out.status = "designed";
    out.gain_crossover_hz = r.bandwidth_hz;
    out.step = r.step.as_ref().map(|s| s.step.clone());
    out.step_effect = r.step_effect.clone();
    out.linear_step_receipts = r.linear_step_receipts.clone();
    out.design = Some(DesignSummary::Mpc {
        spec: MpcSpecSummary {
            horizon: spec.horizon,
            output_weight: spec.q,
            rate_weight: spec.r_rate,
            u_min: spec.u_min,
            u_max: spec.u_max,
            rate_limit: spec.du_max,
            rho: spec.rho,
            iterations: spec.iterations,
        },
        sigma: d.sigma,
        model_states: inp.model.n_states(),
        unconstrained_kx: r.law.kx.clone(),
        unconstrained_kr: r.law.kr,
        unconstrained_ku: r.law.ku,
        unconstrained_pole_modulus: r.pole_modulus,
        unconstrained_bandwidth_hz: r.bandwidth_hz,
        step_max_abs_du: r.step.as_ref().map_or(f64::NAN, |s| s.max_abs_du),
        step_max_raw_excess: r.step.as_ref().map_or(f64::NAN, |s| s.max_raw_excess),
    });
    out.mpc = Some((d, inp.model.clone()));
    Ok(fc)
}

/// The MPC's receipts and the numbers behind them.
pub struct MpcReceipts {
    /// `controller_design`, `closed_loop_stable`, `step_actuator_demand`, `step_overshoot`,
    /// `step_settling_time`.
    pub receipts: Receipts,
    /// The unconstrained law.
    pub law: UnconstrainedLaw,
    /// Largest pole modulus of its closed loop.
    pub pole_modulus: f64,
    /// Its −3 dB bandwidth r → y, Hz (None: not below Nyquist).
    pub bandwidth_hz: Option<f64>,
    /// The constrained step the receipts come from (None: the simulation failed; its
    /// receipts say why).
    pub step: Option<MpcStep>,
    /// The gap verdict's effect and whether the step simulates it.
    pub step_effect: Option<StepEffect>,
    /// With the effect simulated: the step receipts on G0 alone (else empty).
    pub linear_step_receipts: Vec<Receipt>,
}

/// Receipts of the MPC `d` on G0 (module docs).
pub(super) fn mpc_receipts(
    c: &PipelineConfig,
    inp: &ControlStageInputs<'_>,
    d: &MpcDesign,
    limits: &ReceiptLimits,
) -> Result<MpcReceipts> {
    let k = &c.control;
    let fc = k.crossover_hz;
    let ts = inp.model.ts;
    let law = d.unconstrained_law()?;
    let cl = d.unconstrained_closed_loop(inp.model)?;
    let pole_modulus = cl.poles()?.iter().map(|z| z.norm()).fold(0.0, f64::max);
    let nyq = 0.5 / ts;
    let f_lo = fc / 100.0;
    let t0 = cl.freq_response_siso(f_lo)?.norm();
    let mut bandwidth_hz = None;
    for f in log_grid(f_lo, nyq * 0.999, 2000) {
        if cl.freq_response_siso(f)?.norm() < t0 / 2f64.sqrt() {
            bandwidth_hz = Some(f);
            break;
        }
    }
    let mut rs = Receipts::default();
    rs.push(design_receipt(
        c,
        ControlMethod::Mpc,
        Ok(bandwidth_hz.unwrap_or(nyq)),
        inp.baseline_crossover_hz(),
    ));
    rs.push(Receipt::new(
        ReceiptKind::ClosedLoopStable,
        "largest closed-loop pole modulus of the MPC's unconstrained law on G0 (stable when < 1)",
        pole_modulus,
        Comparison::LessThan,
        1.0,
        "1",
        format!(
            "{} poles (model states and u_prev), ts = {ts} s; |T(0)| = {}; the constrained \
             law equals it while no limit is active",
            inp.model.n_states() + 1,
            fmt_num(t0)
        ),
    ));
    let samples = ((limits.settling_time_s_max * 2.0).max(50.0 / fc) / ts).floor() as usize;
    let (step_effect, effect) = diagnosed_effect(inp.gap);
    let (linear, linear_step) = step_receipts(c, inp, d, limits, samples, None)?;
    let (linear_step_receipts, step) = match &effect {
        Some(e) => {
            let (with, step) = step_receipts(c, inp, d, limits, samples, Some(e))?;
            for r in with {
                rs.push(r);
            }
            (linear, step)
        }
        None => {
            for r in linear {
                rs.push(r);
            }
            (Vec::new(), linear_step)
        }
    };
    Ok(MpcReceipts {
        receipts: rs,
        law,
        pole_modulus,
        bandwidth_hz,
        step,
        step_effect,
        linear_step_receipts,
    })
}

/// The gap verdict's effect as the MPC's step simulation sees it (`control.step_effect`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct StepEffect {
    /// The verdict (`GapReport::verdict`).
    pub verdict: String,
    /// The effect simulated (null when not simulated).
    pub effect: Option<String>,
    /// Its place.
    pub place: Option<String>,
    /// Its fitted parameters.
    pub params: Option<std::collections::BTreeMap<String, f64>>,
    /// True when the top-level `step_*` receipts simulate it between the MPC and G0.
    pub simulated: bool,
    /// What was done, or why the effect is not simulated (the step receipts are then G0's).
    pub note: String,
}

/// The effect of the run's gap verdict that [`MpcDesign::closed_loop_step_with`] simulates
/// where the diagnosis placed it: dead zone, backlash, saturation, slew rate or delay at
/// `drive`; Coulomb friction at `motor` with the output as its velocity; quantisation at
/// `sensor`. None (and no record) when no verdict effect was diagnosed; a record without an
/// effect when the verdict names several effects or one the simulation cannot place.
fn diagnosed_effect(
    gap: Option<&crate::gap::GapReport>,
) -> (Option<StepEffect>, Option<crate::gap::effect::Effect>) {
    let Some(report) = gap else {
        return (None, None);
    };
    // The velocity proxy of the verdict's own fit (friction), as the compensation stage reads it.
    let velocity = report.verdict_effects.first().and_then(|v| {
        report
            .effects
            .iter()
            .find(|e| e.effect == v.effect && e.place == v.place)
            .and_then(|e| e.velocity_from.as_deref())
    });
    effect_from_verdict(&report.verdict, &report.verdict_effects, velocity)
}

/// [`diagnosed_effect`] from the parts of a gap report: the verdict, its effects and the
/// velocity source of its friction fit (`None`: output).
fn effect_from_verdict(
    verdict: &str,
    verdict_effects: &[crate::gap::report::VerdictEffect],
    velocity: Option<&str>,
) -> (Option<StepEffect>, Option<crate::gap::effect::Effect>) {
    use crate::gap::effect::Effect;
    use crate::gap::place::Place;
    let placed = match crate::compensation::parse_verdict(verdict, verdict_effects) {
        Ok(p) if p.is_empty() => return (None, None),
        Ok(p) => p,
        Err(e) => {
            return (
                Some(not_simulated(
                    verdict,
                    format!("the verdict does not parse: {e}"),
                )),
                None,
            )
        }
    };
    let [pe] = placed.as_slice() else {
        return (
            Some(not_simulated(
                verdict,
                format!(
                    "the verdict names {} effects; the MPC's step simulation takes one, so the \
                     step receipts are G0's",
                    placed.len()
                ),
            )),
            None,
        );
    };
    let fits = match (&pe.effect, pe.place) {
        (
            Effect::Deadzone { .. }
            | Effect::Backlash { .. }
            | Effect::Saturation { .. }
            | Effect::SlewRate { .. }
            | Effect::TimeDelay { .. },
            Place::Drive,
        ) => true,
        (Effect::CoulombFriction { .. }, Place::Motor) => {
            matches!(velocity, None | Some("output"))
        }
        (Effect::Quantization { .. }, Place::Sensor) => true,
        _ => false,
    };
    let mut rec = StepEffect {
        verdict: verdict.to_string(),
        effect: Some(pe.effect.kind().to_string()),
        place: Some(pe.place.to_string()),
        params: Some(verdict_effects[0].params.clone()),
        simulated: fits,
        note: String::new(),
    };
    if fits {
        rec.note = format!(
            "step_actuator_demand, step_overshoot and step_settling_time simulate {} at {} \
             between the MPC and G0 (MpcDesign::closed_loop_step_with; the MPC does not know \
             it); linear_step_receipts hold the same step on G0 alone",
            pe.effect.kind(),
            pe.place
        );
        (Some(rec), Some(pe.effect))
    } else {
        rec.note = format!(
            "{} at {}{} is not simulated in the MPC's step (it needs the sub-sampled plant or \
             another place in the loop); the step receipts are G0's",
            pe.effect.kind(),
            pe.place,
            velocity.map_or(String::new(), |v| format!(" (velocity from {v})"))
        );
        (Some(rec), None)
    }
}

fn not_simulated(verdict: &str, note: String) -> StepEffect {
    StepEffect {
        verdict: verdict.to_string(),
        effect: None,
        place: None,
        params: None,
        simulated: false,
        note,
    }
}

/// The three step receipts of the MPC's constrained step on G0, with `effect` between the MPC
/// and G0 when given, and the step (None: the simulation failed; its receipts say why).
fn step_receipts(
    c: &PipelineConfig,
    inp: &ControlStageInputs<'_>,
    d: &MpcDesign,
    limits: &ReceiptLimits,
    samples: usize,
    effect: Option<&crate::gap::effect::Effect>,
) -> Result<(Vec<Receipt>, Option<MpcStep>)> {
    let k = &c.control;
    let ts = inp.model.ts;
    let mut rs = Receipts::default();
    let with = effect.map_or(String::new(), |e| {
        let p: Vec<String> = e
            .params()
            .iter()
            .map(|(n, v)| format!("{n} = {}", fmt_num(*v)))
            .collect();
        format!(
            "with the diagnosed {} ({}) in the loop: ",
            e.kind(),
            p.join(", ")
        )
    });
    let r = k.reference_amplitude;
    let step = match finding(d.closed_loop_step_with(inp.model, effect, r, samples, 0.02))? {
        Ok(s) => s,
        Err(e) => {
            push_failed_step_receipts(
                &mut rs,
                limits,
                [
                    "MPC step: rails and rate limit",
                    "MPC step overshoot",
                    "MPC step settling time",
                ],
                &format!("{with}{e}"),
            );
            return Ok((rs.receipts, None));
        }
    };
    let s = &step.step;
    let max_u = s.u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let ratio = (max_u / k.actuator_limit).max(step.max_abs_du / d.spec.du_max);
    let unit = &c.signals.input_unit;
    rs.push(Receipt::new(
        ReceiptKind::StepActuatorDemand,
        "largest of max|u|/actuator limit and max|Δu|/rate limit in the MPC's constrained step \
         (≤ 1: the rails and the rate limit hold; 1 + 1e-9 allows the rounding of u_prev ± Δu)",
        ratio,
        Comparison::AtMost,
        1.0 + 1e-9,
        "1",
        format!(
            "{with}step of {} to rails ±{} {unit}, rate limit {} {unit}/sample: max |u| {}, max |Δu| \
             {}; {} samples at the rail; raw ADMM U₀ at most {} {unit} outside the box before \
             the clamp; host simulation of the fixed-budget law ({} ADMM iterations, N = {}), \
             ts = {ts} s",
            fmt_num(k.reference_amplitude),
            fmt_num(k.actuator_limit),
            fmt_num(d.spec.du_max),
            fmt_num(max_u),
            fmt_num(step.max_abs_du),
            s.samples_at_rail,
            fmt_num(step.max_raw_excess),
            d.spec.iterations,
            d.spec.horizon
        ),
    ));
    push_step_shape_receipts(
        &mut rs,
        limits,
        s,
        [
            "overshoot of the MPC's constrained closed-loop step",
            "2 % settling time of the MPC's constrained closed-loop step (tracking)",
        ],
        &with,
        format!(
            "{with}simulated {} s; final error {} (no integral action: offset-free only on the \
             model itself)",
            fmt_num(s.t.last().copied().unwrap_or(0.0)),
            fmt_num(s.final_error)
        ),
    );
    Ok((rs.receipts, Some(step)))
}

/// The MPC as a codegen block (None unless an MPC was designed): the prediction model's
/// matrices and the firmware QP data.
pub fn mpc_codegen_block(c: &ControlOutcome) -> Option<ferrosid_codegen::StateController> {
    let (d, model) = c.mpc.as_ref()?;
    Some(mpc_state_controller(d, model))
}

/// The codegen block of the MPC `d` designed on the prediction model `model`.
pub fn mpc_state_controller(
    d: &MpcDesign,
    model: &crate::lti::StateSpace,
) -> ferrosid_codegen::StateController {
    let (gx, gr) = d.firmware_terms();
    let rows = |m: &faer::Mat<f64>| -> Vec<Vec<f64>> {
        (0..m.nrows())
            .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
            .collect()
    };
    let s = d.spec;
    ferrosid_codegen::StateController {
        method: "mpc".into(),
        ts_s: model.ts,
        matrices: crate::ops::codegen::matrices(model),
        note: format!(
            "condensed MPC, N = {}, q = {}, ρ_Δ = {}, box ±{}, |Δu| ≤ {} per sample, ADMM ρ = {}, \
             {} iterations per step; state feedback on the model state; receipts as in \
             receipts.json",
            s.horizon,
            fmt_num(s.q),
            fmt_num(s.r_rate),
            fmt_num(s.u_max),
            fmt_num(s.du_max),
            fmt_num(s.rho),
            s.iterations
        ),
        mpc: Some(ferrosid_codegen::MpcController {
            horizon: s.horizon,
            k: rows(&d.k),
            gx: rows(&gx),
            gr,
            two_r_rate: 2.0 * s.r_rate,
            sigma: d.sigma,
            rho: s.rho,
            u_min: s.u_min,
            u_max: s.u_max,
            du_max: s.du_max,
            iterations: s.iterations as u32,
        }),
        saturation: None,
        pid_notch: None,
    }
}

#[cfg(test)]
mod tests {
    use super::effect_from_verdict;
    use crate::gap::effect::Effect;
    use crate::gap::report::VerdictEffect;

    fn ve(effect: &str, place: &str, params: &[(&str, f64)]) -> VerdictEffect {
        VerdictEffect {
            effect: effect.into(),
            place: place.into(),
            params: params.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            share: 1.0,
        }
    }

    #[test]
    fn only_one_effect_the_simulation_can_place_is_simulated() {
        // No effect: no record (receipts.json unchanged).
        assert!(matches!(
            effect_from_verdict("none", &[], None),
            (None, None)
        ));
        assert!(matches!(
            effect_from_verdict("unexplained", &[], None),
            (None, None)
        ));
        // A dead zone at the drive: simulated, with its fitted width.
        let (rec, e) = effect_from_verdict(
            "deadzone",
            &[ve("deadzone", "drive", &[("width", 0.02)])],
            None,
        );
        assert_eq!(e, Some(Effect::Deadzone { width: 0.02 }));
        let rec = rec.unwrap();
        assert!(rec.simulated && rec.place.as_deref() == Some("drive"));
        // Friction at the motor with the output as velocity: simulated; with a differentiated
        // position output (the simulation's law takes the output's sign): not.
        let f = [ve("coulomb_friction", "motor", &[("level", 0.01)])];
        assert_eq!(
            effect_from_verdict("coulomb_friction", &f, Some("output")).1,
            Some(Effect::CoulombFriction { level: 0.01 })
        );
        let (rec, e) = effect_from_verdict("coulomb_friction", &f, Some("output_derivative"));
        assert!(e.is_none());
        let rec = rec.unwrap();
        assert!(
            !rec.simulated && rec.note.contains("output_derivative"),
            "{}",
            rec.note
        );
        // Backlash between the inertias is not at the plant input: not simulated.
        let (rec, e) = effect_from_verdict(
            "backlash",
            &[ve("backlash", "drivetrain", &[("gap", 0.01)])],
            None,
        );
        assert!(e.is_none() && !rec.unwrap().simulated);
        // Two effects: the simulation takes one; recorded, not simulated.
        let two = [
            ve("deadzone", "drive", &[("width", 0.02)]),
            ve("coulomb_friction", "motor", &[("level", 0.01)]),
        ];
        let (rec, e) = effect_from_verdict("deadzone+coulomb_friction", &two, None);
        assert!(e.is_none());
        let rec = rec.unwrap();
        assert!(!rec.simulated && rec.effect.is_none() && rec.note.contains("2 effects"));
    }
}
