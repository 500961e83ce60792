//! The `limit_cycle` receipts of the chosen controller's own loop (issue 14).
//!
//! The compensation stage ([`super::compensation_stage`]) analyses the diagnosed nonlinearities
//! in the loop of the PID. With `[control] method` = `loopshape` or `hinf` the loop that runs is
//! another LTI controller, so its `limit_cycle` receipts are recomputed for it: the same
//! nonlinearities (each analysed effect of the stage, at its site, with the friction fit's
//! velocity source), the same cycle tolerance (`compensation.amplitude_tol`) and simulated time,
//! describing function on that loop's linear part and simulation with that controller's law
//! ([`crate::limit_cycle::LureLoop::with_controller`]). They replace the PID's in the run's list
//! (the PID's go to `control.replaced_pid_receipts`). The compensation law of the host is the
//! PID's, so the chosen loop is analysed without compensation (its detail says so when the run
//! chose `compensate`).
//!
//! The MPC is not an LTI controller: the describing-function analysis does not apply. Its run
//! lists `limit_cycle` under `control.not_applicable` with the reason and carries no PID
//! `limit_cycle` receipt (the MPC's step receipts simulate the diagnosed effect instead,
//! `control.step_effect`).
use super::compensation_stage::{lure_loop, verdict_velocity_from, Choice};
use super::config::PipelineConfig;
use super::control_stage::{finding, ControlMethod, ControlStageInputs, NotApplicable};
use crate::error::Result;
use crate::limit_cycle::{analyse, receipt, AnalysisOptions};
use crate::lti::StateSpace;
use crate::robust::receipts::{Comparison, Receipt, ReceiptKind};
use crate::synth::sim::DiscreteLaw;

/// True when the run analysed limit cycles of the PID loop (the remedy stage decided and
/// analysed at least one effect): the chosen method then owns the `limit_cycle` receipts.
pub(super) fn analysed(inp: &ControlStageInputs<'_>) -> bool {
    inp.remedy.is_some_and(|d| !d.stage.effects.is_empty())
}

/// The `limit_cycle` receipts of the loop of G0 with the discrete controller `k` (stepped by
/// `law`), one per effect the compensation stage analysed (module docs); empty when it analysed
/// none. A failing analysis is a failing receipt that says why.
pub(super) fn chosen_limit_cycles(
    c: &PipelineConfig,
    inp: &ControlStageInputs<'_>,
    method: ControlMethod,
    k: &StateSpace,
    law: &DiscreteLaw,
) -> Result<Vec<Receipt>> {
    let (Some(dec), Some(report), Some(pid)) = (
        inp.remedy,
        inp.gap,
        inp.baseline.and_then(|t| t.discrete.as_ref()),
    ) else {
        return Ok(Vec::new());
    };
    if dec.stage.effects.is_empty() {
        return Ok(Vec::new());
    }
    let lp = finding(
        lure_loop(inp.model, pid, verdict_velocity_from(report))
            .and_then(|(lp, _)| lp.with_controller(k, law.clone())),
    )?;
    let opts = AnalysisOptions {
        amplitude_tol: dec.amplitude_tol,
        duration_s: c.compensation.simulate_s,
        ..AnalysisOptions::default()
    };
    let mut out = Vec::new();
    for e in &dec.stage.effects {
        let label = format!("{} ({} loop)", e.label, method.name());
        let analysis = match &lp {
            Ok(lp) => finding(analyse(lp, &e.before.nonlinearity, None, &opts))?,
            Err(m) => Err(m.clone()),
        };
        let mut r = match analysis {
            Ok(a) => receipt(&a, &label),
            Err(m) => Receipt::new(
                ReceiptKind::LimitCycle,
                &format!("self-sustained oscillation with {label}"),
                f64::NAN,
                Comparison::AtMost,
                0.0,
                "1",
                format!(
                    "the limit-cycle analysis of the {} loop failed: {m}",
                    method.name()
                ),
            ),
        };
        r.detail.push_str(&format!(
            "; loop of G0 and the {} controller (order {}){}",
            method.name(),
            k.n_states(),
            if dec.choice == Choice::Compensate {
                "; the run chose `compensate`, but the host's compensation law wraps the PID: \
                 this loop is analysed without it"
            } else {
                ""
            }
        ));
        out.push(r);
    }
    Ok(out)
}

/// The MPC's `limit_cycle` entry of `control.not_applicable` (None when the run analysed no
/// limit cycle).
pub(super) fn mpc_not_applicable(inp: &ControlStageInputs<'_>) -> Option<NotApplicable> {
    analysed(inp).then(|| NotApplicable {
        name: ReceiptKind::LimitCycle.name().to_string(),
        reason: "the describing-function analysis needs an LTI controller in the loop (the \
                 nonlinearity's linear part L(e^{jωT})); the constrained MPC is a nonlinear \
                 state-feedback law, so no limit-cycle receipt is issued for it and the PID's \
                 (in replaced_pid_receipts) do not describe this loop. The diagnosed effect \
                 enters the MPC's step receipts instead (control.step_effect)"
            .to_string(),
    })
}
