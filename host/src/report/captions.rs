//! The figures' captions (`host/templates/report/captions.txt`, one `when` per figure): plain
//! text, escaped where `figure.html` inlines it. The figure functions of [`super::charts`],
//! [`super::compensation_section`] and [`super::control_section`] fill a [`Caption`] from the
//! data they plot.
use super::filters;
use crate::error::{Error, Result};
use crate::limit_cycle::{LimitCycleAnalysis, PredictedLimitCycle};
use crate::pipeline::control_mpc::StepEffect;
use crate::robust::audit::NonlinearityAudit;
use crate::robust::step::StepResponse;
use askama::Template;

/// One figure's caption, with what it quotes.
#[derive(Template)]
#[template(path = "report/captions.txt")]
pub(super) enum Caption<'a> {
    /// `bode`: the estimation run, the coherence gate and the model order.
    Bode {
        run: &'a str,
        gate: f64,
        order: usize,
    },
    /// `coherence`: the gate.
    Coherence { gate: f64 },
    /// `singular_values`: the chosen order and why.
    SingularValues { order: usize, reason: &'a str },
    /// `robustness`: the ‖W_m T‖∞ receipt's value.
    Robustness { value: String },
    /// `uncertainty`: the family and the weight's overbound.
    Uncertainty {
        family: &'a [String],
        worst_ratio: f64,
        mean_db: f64,
    },
    /// `sensitivity`: the M_s receipt's value and the limit.
    Sensitivity { value: String, ms: f64 },
    /// `step`: the saturated PID step.
    Step {
        s: &'a StepResponse,
        output_unit: &'a str,
        input_unit: &'a str,
    },
    /// `audit`: the audit's runs, band and verdict.
    Audit {
        a: &'a NonlinearityAudit,
        verdict: &'static str,
    },
    /// `validation`: the shown window of the validation log and the fit.
    Validation {
        log: &'a str,
        shown: usize,
        samples: usize,
        fit_percent: f64,
        nrmse: f64,
    },
    /// `describing_function`: the effect and the first predicted cycle, if any.
    DescribingFunction {
        label: &'a str,
        cycle: Option<&'a PredictedLimitCycle>,
    },
    /// `limit_cycle`: the simulated loop without and (if analysed) with the compensation.
    LimitCycle {
        label: &'a str,
        before: SimOutcome,
        after: Option<SimOutcome>,
    },
    /// `control_loop`: the method and its lowest gain crossover.
    ControlLoop {
        method: &'a str,
        crossover_hz: Option<f64>,
    },
    /// `control_sensitivity`: the method.
    ControlSensitivity { method: &'a str },
    /// `control_step`: the chosen loop's step, with the diagnosed effect an MPC step may
    /// simulate between the controller and G0.
    ControlStep {
        method: &'a str,
        s: &'a StepResponse,
        output_unit: &'a str,
        input_unit: &'a str,
        effect: Option<&'a StepEffect>,
    },
}

/// What the simulation of a loop with a nonlinearity shows, for the `limit_cycle` caption.
pub(super) struct SimOutcome {
    /// Frequency of the counted cycle, Hz (None: no counted cycle).
    cycle_hz: Option<f64>,
    /// Half peak-to-peak of the output's tail.
    half_ptp: f64,
}

impl SimOutcome {
    pub(super) fn of(a: &LimitCycleAnalysis) -> Self {
        let cycle_hz = match &a.simulated_output {
            Some(s) if a.simulated_counts() => Some(s.freq_hz),
            _ => None,
        };
        Self {
            cycle_hz,
            half_ptp: a.output_tail_half_ptp,
        }
    }
}

impl Caption<'_> {
    /// The caption text.
    pub(super) fn text(&self) -> Result<String> {
        self.render()
            .map_err(|e| Error::Numerical(format!("rendering a figure caption: {e}")))
    }
}

#[cfg(test)]
mod tests {
    //! The caption branches the bundled example's reports do not reach (their byte-identity
    //! with the `format!` captions before the templates was checked on those reports), against
    //! the sentences as the figure functions wrote them.
    use super::{Caption, SimOutcome};
    use crate::limit_cycle::{PredictedLimitCycle, Site};
    use crate::pipeline::fmt_num;
    use crate::robust::step::StepResponse;

    fn step(settling: Option<f64>) -> StepResponse {
        StepResponse {
            ts: 1e-3,
            amplitude: 5.0,
            actuator_limit: 0.3,
            t: vec![0.0],
            y: vec![0.0],
            u: vec![0.0],
            u_demand: vec![0.0],
            hits_rail: false,
            samples_at_rail: 0,
            peak_demand_ratio: 0.75,
            overshoot_pct: 12.345,
            settling_time_s: settling,
            rise_time_s: None,
            final_error: 0.0,
        }
    }

    #[test]
    fn a_predicted_cycle_and_a_counted_one_are_described() {
        let c = PredictedLimitCycle {
            freq_hz: 12.3456,
            amplitude: 0.0123,
            stable: false,
            output_amplitude: 1.0,
            site: Site::Velocity,
            loop_value: (-1.0, 0.0),
            df_value: (1.0, 0.0),
            refined: true,
        };
        let text = Caption::DescribingFunction {
            label: "coulomb_friction at motor",
            cycle: Some(&c),
        }
        .text()
        .unwrap();
        assert_eq!(
            text,
            format!(
                "Describing function of coulomb_friction at motor: the loop's linear part meets \
                 −1/N(A) at {} Hz, amplitude {} (unstable) — a harmonic-balance solution, \
                 confirmed or refuted by the simulation.",
                fmt_num(12.3456),
                fmt_num(0.0123)
            )
        );
        let text = Caption::LimitCycle {
            label: "stiction at drive",
            before: SimOutcome {
                cycle_hz: Some(3.25),
                half_ptp: 0.5,
            },
            after: Some(SimOutcome {
                cycle_hz: None,
                half_ptp: 1e-4,
            }),
        }
        .text()
        .unwrap();
        assert_eq!(
            text,
            format!(
                "Simulated closed loop with stiction at drive after a start-up kick: without \
                 compensation a cycle at {} Hz, output half peak-to-peak {}; with compensation no \
                 counted cycle (output half peak-to-peak {}).",
                fmt_num(3.25),
                fmt_num(0.5),
                fmt_num(1e-4)
            )
        );
    }

    #[test]
    fn an_unsettled_step_and_an_unnamed_effect_are_described() {
        let s = step(None);
        let text = Caption::Step {
            s: &s,
            output_unit: "rad/s",
            input_unit: "N·m",
        }
        .text()
        .unwrap();
        assert_eq!(
            text,
            format!(
                "Closed-loop step of {} rad/s through a hard actuator saturation at ±{} N·m; the \
                 command stays inside the rails (peak demand {} of the rail), overshoot {} %, \
                 settling not reached.",
                fmt_num(5.0),
                fmt_num(0.3),
                fmt_num(0.75),
                fmt_num(12.345)
            )
        );
        let effect = crate::pipeline::control_mpc::StepEffect {
            verdict: "deadzone".into(),
            effect: None,
            place: None,
            params: None,
            simulated: true,
            note: String::new(),
        };
        let text = Caption::ControlStep {
            method: "mpc",
            s: &s,
            output_unit: "rad/s",
            input_unit: "N·m",
            effect: Some(&effect),
        }
        .text()
        .unwrap();
        assert_eq!(
            text,
            format!(
                "Saturated step of the mpc loop: {} rad/s against rails ±{} N·m; overshoot {} %, \
                 settling not reached. With the diagnosed effect at ? in the loop; the command is \
                 the controller's, before the effect (the same step on G0 alone: \
                 control.linear_step_receipts).",
                fmt_num(5.0),
                fmt_num(0.3),
                fmt_num(12.345)
            )
        );
    }
}
