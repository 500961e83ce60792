//! The report's sections other than the gap, compensation, physical and chosen-controller
//! ones (which have their own files), in page order; [`super::render_html`] calls them. Each
//! renders its template of `host/templates/report/`.
use super::{append, filters, poly_text, verdict_text, View};
use crate::error::Result;
use crate::pipeline::document::{weight_high_gain, weight_low_gain};
use crate::pipeline::{EnvelopeData, InputFile, LogData, Mode, PipelineRun};
use crate::robust::audit::NonlinearityAudit;
use crate::robust::receipts::{Receipt, ReceiptKind};
use crate::robust::uncertainty::UncertaintyWeight;
use crate::spectral::ExcludedBand;
use crate::validate::{ResidualKind, ResidualTest};
use askama::Template;

/// `banner.html`: the document head, the verdict banner and the navigation.
#[derive(Template)]
#[template(path = "report/banner.html")]
struct Banner<'a> {
    title: &'a str,
    all_pass: bool,
    n_receipts: usize,
    failed: Vec<&'a str>,
    order: usize,
    fs_hz: f64,
    /// The PID's crossover and its target, Hz.
    pid: Option<(f64, f64)>,
    /// The M_s receipt's value with its unit.
    ms: Option<String>,
    /// The ‖W_m T‖∞ receipt's value.
    wmt: Option<String>,
    validation_fit: Option<f64>,
}

/// The document head, the verdict banner and the navigation.
pub(super) fn banner(h: &mut String, run: &PipelineRun) -> Result<()> {
    let rs = &run.receipts;
    let value = |kind| rs.of_kind(kind).map(|_| super::receipt_value(run, kind));
    let t = Banner {
        title: &run.title,
        all_pass: rs.all_pass,
        n_receipts: rs.receipts.len(),
        failed: rs.failed().map(|r| r.name.as_str()).collect(),
        order: run.ident.order,
        fs_hz: 1.0 / run.model().ts,
        pid: run
            .tuned()
            .map(|t| (t.design.crossover_hz, t.target_crossover_hz)),
        ms: value(ReceiptKind::SensitivityPeak),
        wmt: value(ReceiptKind::RobustStability),
        validation_fit: run.validation_fit.as_ref().map(|f| f.fit_percent[0]),
    };
    append(h, &t)
}

/// `receipts.html`: the receipts table.
#[derive(Template)]
#[template(path = "report/receipts.html")]
struct Receipts<'a> {
    receipts: &'a [Receipt],
}

/// The receipts table.
pub(super) fn receipts(h: &mut String, run: &PipelineRun) -> Result<()> {
    append(
        h,
        &Receipts {
            receipts: &run.receipts.receipts,
        },
    )
}

/// `model.html`: frequency response with the coherence gate, coherence, model order and modes.
#[derive(Template)]
#[template(path = "report/model.html")]
struct Model<'a>(View<'a>);

view_deref!(Model);

impl Model<'_> {
    /// Frequency resolution of the estimation run's Welch estimate, Hz.
    fn resolution_hz(&self) -> f64 {
        let e = &self.run.nominal_run().etfe;
        e.fs / e.nperseg as f64
    }
    /// The estimation run's bands rejected by the coherence gate.
    fn excluded_bands(&self) -> Vec<ExcludedBand> {
        let gate = self.run.config.etfe.coherence_gate;
        self.run.nominal_run().etfe.excluded_bands(gate)
    }
    /// The sign between a discrete pole's real and imaginary part: "−" below the real axis,
    /// "±" for the upper member of a pair (and for a real pole).
    fn im_sign(&self, m: &Mode) -> &'static str {
        if m.z[1] < 0.0 {
            "−"
        } else {
            "±"
        }
    }
}

/// Frequency response with the coherence gate, coherence, model order and modes.
pub(super) fn model(h: &mut String, v: View<'_>) -> Result<()> {
    append(h, &Model(v))
}

/// `design_loop.html`: robust stability (|T| against 1/|W_m|, the weight), sensitivity and the
/// saturated step.
#[derive(Template)]
#[template(path = "report/design_loop.html")]
struct DesignLoop<'a>(View<'a>);

view_deref!(DesignLoop);

impl DesignLoop<'_> {
    fn poly(&self, c: &[f64]) -> String {
        poly_text(c)
    }
    fn low_gain(&self, w: &UncertaintyWeight) -> f64 {
        weight_low_gain(&w.num, &w.den)
    }
    fn high_gain(&self, w: &UncertaintyWeight) -> f64 {
        weight_high_gain(&w.num, &w.den)
    }
    /// The lowest measured frequency of the envelope, Hz.
    fn first_measured_hz(&self, e: &EnvelopeData) -> f64 {
        e.freq_hz.get(e.below).copied().unwrap_or(f64::NAN)
    }
    /// The level assumed in the decade below the measured band.
    fn assumed_level(&self, e: &EnvelopeData) -> f64 {
        e.level.first().copied().unwrap_or(f64::NAN)
    }
}

/// Robust stability (|T| against 1/|W_m|, the weight), sensitivity and the saturated step.
pub(super) fn design_loop(h: &mut String, v: View<'_>) -> Result<()> {
    append(h, &DesignLoop(v))
}

/// `audit.html`: the dual-amplitude nonlinearity audit.
#[derive(Template)]
#[template(path = "report/audit.html")]
struct Audit<'a>(View<'a>);

view_deref!(Audit);

impl Audit<'_> {
    fn verdict(&self, a: &NonlinearityAudit) -> &'static str {
        verdict_text(a.verdict)
    }
}

/// The dual-amplitude nonlinearity audit.
pub(super) fn audit(h: &mut String, v: View<'_>) -> Result<()> {
    append(h, &Audit(v))
}

/// `validation.html`: validation on fresh data.
#[derive(Template)]
#[template(path = "report/validation.html")]
struct Validation<'a>(View<'a>);

view_deref!(Validation);

impl Validation<'_> {
    fn residual_kind(&self, r: &ResidualTest) -> &'static str {
        match r.kind {
            ResidualKind::OneStepPrediction => {
                "one-step-prediction residual of the Kalman predictor"
            }
            ResidualKind::OutputError => "output-error residual",
        }
    }
}

/// Validation on fresh data.
pub(super) fn validation(h: &mut String, v: View<'_>) -> Result<()> {
    append(h, &Validation(v))
}

/// `controller.html`: the PID controller.
#[derive(Template)]
#[template(path = "report/controller.html")]
struct Controller<'a> {
    run: &'a PipelineRun,
}

/// The controller.
pub(super) fn controller(h: &mut String, run: &PipelineRun) -> Result<()> {
    append(h, &Controller { run })
}

/// `provenance.html`: provenance (inputs, preprocessing, settings) and the document end.
#[derive(Template)]
#[template(path = "report/provenance.html")]
struct Provenance<'a> {
    run: &'a PipelineRun,
}

impl<'a> Provenance<'a> {
    /// The pipeline file, then every log file.
    fn files(&self) -> Vec<&'a InputFile> {
        std::iter::once(&self.run.pipeline_file)
            .chain(self.run.inputs.iter())
            .collect()
    }
    /// The runs, then the validation log.
    fn logs(&self) -> Vec<&'a LogData> {
        self.run
            .runs
            .iter()
            .chain(self.run.validation.iter())
            .collect()
    }
    /// The preprocessing steps of `l` in words.
    fn steps(&self, l: &LogData) -> Vec<String> {
        l.preprocessing
            .steps
            .iter()
            .map(|s| match s {
                crate::preprocess::StepRecord::RemoveMean { .. } => "mean removed".to_string(),
                crate::preprocess::StepRecord::RemoveTrend { .. } => "trend removed".to_string(),
                crate::preprocess::StepRecord::Decimate { factor, .. } => {
                    format!("decimated by {factor}")
                }
            })
            .collect()
    }
    /// The configuration with all defaults filled in, as TOML.
    fn settings(&self) -> String {
        toml::to_string(&self.run.config).unwrap_or_else(|e| format!("<{e}>"))
    }
    fn version(&self) -> &'static str {
        env!("CARGO_PKG_VERSION")
    }
}

/// Provenance (inputs, preprocessing, settings) and the document end.
pub(super) fn provenance(h: &mut String, run: &PipelineRun) -> Result<()> {
    append(h, &Provenance { run })
}
