//! Validation of a parsed pipeline file, one function per section; every error names the
//! file, the key and (when written) its line ([`LoadedConfig::key_error`]).
use super::{LoadedConfig, LogEntry, MAX_BAND_FACTOR};
use crate::error::{Error, Result};

impl LoadedConfig {
    /// Checks every section (the keys' ranges are in docs/pipeline-schema.md).
    pub(super) fn validate(&self) -> Result<()> {
        let names = self.run_names();
        self.validate_logs(&names)?;
        self.validate_spectral()?;
        self.validate_identification(&names)?;
        self.validate_audit()?;
        self.validate_uncertainty(&names)?;
        self.validate_control()?;
        self.validate_receipts()?;
        self.validate_compensation()?;
        self.validate_physical(&names)
    }

    /// `[physical]`: a known structure, known parameter names and a confidence level in
    /// (0, 1) (checked by the grey-box options), and a `run` that names a `[[runs]]` entry.
    fn validate_physical(&self, names: &[String]) -> Result<()> {
        let Some(p) = &self.config.physical else {
            return Ok(());
        };
        p.options()
            .map_err(|e| self.key_error("physical.structure", e))?;
        if let Some(r) = &p.run {
            if !names.iter().any(|n| n == r) {
                return Err(self.key_error(
                    "physical.run",
                    format!("`{r}` is not a [[runs]] name ({})", names.join(", ")),
                ));
            }
        }
        Ok(())
    }

    /// `key` must be finite and > 0.
    pub(super) fn positive(&self, key: &str, v: f64) -> Result<()> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(self.key_error(key, format!("must be finite and > 0, got {v}")))
        }
    }

    fn validate_logs(&self, names: &[String]) -> Result<()> {
        let c = &self.config;
        if c.runs.is_empty() {
            return Err(Error::Data {
                file: self.path.clone(),
                msg: "no `[[runs]]`: give at least one excitation log".into(),
            });
        }
        for (i, n) in names.iter().enumerate() {
            if n.is_empty() || n == "validation" {
                return Err(self.key_error(
                    &format!("runs[{i}].name"),
                    format!("`{n}` is reserved or empty; choose another name"),
                ));
            }
            if names[..i].contains(n) {
                return Err(self.key_error(
                    &format!("runs[{i}].name"),
                    format!("duplicate run name `{n}`"),
                ));
            }
        }
        let mut entries: Vec<(String, &LogEntry)> = c
            .runs
            .iter()
            .enumerate()
            .map(|(i, r)| (format!("runs[{i}]"), r))
            .collect();
        if let Some(v) = &c.validation {
            entries.push(("validation".into(), v));
        }
        for (k, e) in &entries {
            if e.file.as_os_str().is_empty() {
                return Err(self.key_error(&format!("{k}.file"), "empty path"));
            }
            if let Some(a) = e.amplitude {
                self.positive(&format!("{k}.amplitude"), a)?;
            }
            if let Some(fs) = e.fs {
                self.positive(&format!("{k}.fs"), fs)?;
            }
        }
        if let Some(fs) = c.signals.fs {
            self.positive("signals.fs", fs)?;
        }
        if let Some(s) = c.signals.time_scale {
            self.positive("signals.time_scale", s)?;
        }
        if let Some(j) = c.signals.time_jitter {
            if !(0.0..=crate::io::MAX_TIME_JITTER_REL).contains(&j) {
                return Err(self.key_error(
                    "signals.time_jitter",
                    format!(
                        "must lie in [0, {}], got {j}",
                        crate::io::MAX_TIME_JITTER_REL
                    ),
                ));
            }
        }
        Ok(())
    }

    fn validate_spectral(&self) -> Result<()> {
        let c = &self.config;
        let max_q = crate::preprocess::MAX_DECIMATION;
        if !(1..=max_q).contains(&c.preprocess.decimate) {
            return Err(self.key_error(
                "preprocess.decimate",
                format!(
                    "must be in 1..={max_q} (1 = no decimation), got {}",
                    c.preprocess.decimate
                ),
            ));
        }
        let e = &c.etfe;
        let (lo, hi) = (crate::spectral::MIN_NPERSEG, crate::spectral::MAX_NPERSEG);
        if !(lo..=hi).contains(&e.nperseg) {
            return Err(self.key_error(
                "etfe.nperseg",
                format!("must be in {lo}..={hi}, got {}", e.nperseg),
            ));
        }
        if let Some(o) = e.overlap {
            if o >= e.nperseg {
                return Err(self.key_error(
                    "etfe.overlap",
                    format!("must be < nperseg = {}, got {o}", e.nperseg),
                ));
            }
        }
        if !(e.coherence_gate > 0.0 && e.coherence_gate <= 1.0) {
            return Err(self.key_error(
                "etfe.coherence_gate",
                format!("must lie in (0, 1], got {}", e.coherence_gate),
            ));
        }
        Ok(())
    }

    fn validate_identification(&self, names: &[String]) -> Result<()> {
        let c = &self.config;
        let id = &c.identification;
        if let Some(r) = &id.run {
            if !names.contains(r) {
                return Err(self.key_error(
                    "identification.run",
                    format!("no run named `{r}` (runs: {})", names.join(", ")),
                ));
            }
        }
        let max_i = crate::n4sid::MAX_BLOCK_ROWS;
        if !(2..=max_i).contains(&id.block_rows) {
            return Err(self.key_error(
                "identification.block_rows",
                format!("must be in 2..={max_i}, got {}", id.block_rows),
            ));
        }
        if id.order == Some(0) {
            return Err(self.key_error("identification.order", "must be >= 1"));
        }
        if id.order.is_some() && (id.order_min.is_some() || id.order_max.is_some()) {
            return Err(self.key_error(
                "identification.order",
                "give either a fixed `order` or `order_min`/`order_max`, not both",
            ));
        }
        if let (Some(lo), Some(hi)) = (id.order_min, id.order_max) {
            if lo == 0 || hi < lo {
                return Err(self.key_error(
                    "identification.order_max",
                    format!("order range {lo}..={hi} is empty or starts at 0"),
                ));
            }
        }
        if let Some(m) = id.stability_margin {
            if !(m > 0.0 && m < 1.0) {
                return Err(self.key_error(
                    "identification.stability_margin",
                    format!("must lie in (0, 1), got {m}"),
                ));
            }
        }
        Ok(())
    }

    fn validate_audit(&self) -> Result<()> {
        let c = &self.config;
        let a = &c.audit;
        if !(a.band_factor > 1.0 && a.band_factor <= MAX_BAND_FACTOR) {
            return Err(self.key_error(
                "audit.band_factor",
                format!("must lie in (1, {MAX_BAND_FACTOR}], got {}", a.band_factor),
            ));
        }
        self.positive("audit.max_gain_shift_db", a.max_gain_shift_db)?;
        self.positive("audit.max_phase_shift_deg", a.max_phase_shift_deg)?;
        if !(0.0..=1.0).contains(&a.min_coherence) {
            return Err(self.key_error(
                "audit.min_coherence",
                format!("must lie in [0, 1], got {}", a.min_coherence),
            ));
        }
        if !(a.coherence_band_factor >= 1.0 && a.coherence_band_factor <= MAX_BAND_FACTOR) {
            return Err(self.key_error(
                "audit.coherence_band_factor",
                format!(
                    "must lie in [1, {MAX_BAND_FACTOR}], got {}",
                    a.coherence_band_factor
                ),
            ));
        }
        Ok(())
    }

    fn validate_uncertainty(&self, names: &[String]) -> Result<()> {
        let c = &self.config;
        let u = &c.uncertainty;
        if !(1..=3).contains(&u.order) {
            return Err(self.key_error(
                "uncertainty.order",
                format!("must be 1, 2 or 3, got {}", u.order),
            ));
        }
        self.positive("uncertainty.min_level", u.min_level)?;
        if !(u.beyond_band_level.is_finite() && u.beyond_band_level >= 0.0) {
            return Err(self.key_error(
                "uncertainty.beyond_band_level",
                format!("must be finite and >= 0, got {}", u.beyond_band_level),
            ));
        }
        if let Some(b) = u.below_band_level {
            if !(b.is_finite() && b > 0.0) {
                return Err(self.key_error(
                    "uncertainty.below_band_level",
                    format!("must be finite and > 0, got {b}"),
                ));
            }
        }
        if let Some(fam) = &u.family {
            if fam.is_empty() {
                return Err(self.key_error("uncertainty.family", "is empty"));
            }
            for m in fam {
                let known = names.contains(m) || (m == "validation" && c.validation.is_some());
                if !known {
                    return Err(self.key_error(
                        "uncertainty.family",
                        format!(
                            "no log named `{m}` (runs: {}{})",
                            names.join(", "),
                            if c.validation.is_some() {
                                ", validation"
                            } else {
                                ""
                            }
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    fn validate_control(&self) -> Result<()> {
        let c = &self.config;
        let k = &c.control;
        self.positive("control.crossover_hz", k.crossover_hz)?;
        if !(k.ms_max.is_finite() && k.ms_max > 1.0) {
            return Err(self.key_error(
                "control.ms_max",
                format!(
                    "must be finite and > 1 (|S| >= 1 somewhere for every loop), got {}",
                    k.ms_max
                ),
            ));
        }
        self.positive("control.actuator_limit", k.actuator_limit)?;
        self.positive("control.reference_amplitude", k.reference_amplitude)?;
        if let Some(r) = k.rolloff_ratio {
            if !(r.is_finite() && r > 1.0) {
                return Err(self.key_error(
                    "control.rolloff_ratio",
                    format!("must be > 1 (corner above the crossover), got {r}"),
                ));
            }
        }
        self.positive("control.rolloff_zeta", k.rolloff_zeta)?;
        if !(k.min_crossover_scale > 0.0 && k.min_crossover_scale <= 1.0) {
            return Err(self.key_error(
                "control.min_crossover_scale",
                format!("must lie in (0, 1], got {}", k.min_crossover_scale),
            ));
        }
        super::super::control_stage::validate_method_keys(self)
    }

    fn validate_receipts(&self) -> Result<()> {
        let c = &self.config;
        let r = &c.receipts;
        for (key, v) in [
            ("receipts.gain_margin_db_min", r.gain_margin_db_min),
            ("receipts.phase_margin_deg_min", r.phase_margin_deg_min),
            ("receipts.mt_max", r.mt_max),
            (
                "receipts.disturbance_bandwidth_hz_min",
                r.disturbance_bandwidth_hz_min,
            ),
            ("receipts.overshoot_pct_max", r.overshoot_pct_max),
            ("receipts.settling_time_s_max", r.settling_time_s_max),
            (
                "receipts.etfe_phase_error_deg_max",
                r.etfe_phase_error_deg_max,
            ),
            ("receipts.etfe_max_freq_factor", r.etfe_max_freq_factor),
        ] {
            if let Some(v) = v {
                self.positive(key, v)?;
            }
        }
        if let Some(v) = r.cross_validation_fit_min {
            if !(v.is_finite() && v <= 100.0) {
                return Err(self.key_error(
                    "receipts.cross_validation_fit_min",
                    format!("must be finite and <= 100 %, got {v}"),
                ));
            }
        }
        Ok(())
    }

    fn validate_compensation(&self) -> Result<()> {
        let k = &self.config.compensation;
        for (key, v) in [
            ("compensation.velocity_resolution", k.velocity_resolution),
            ("compensation.tracking_time_s", k.tracking_time_s),
            ("compensation.simulate_s", k.simulate_s),
        ] {
            if let Some(v) = v {
                self.positive(key, v)?;
            }
        }
        if let Some(t) = k.amplitude_tol {
            if !(t.is_finite() && t >= 0.0) {
                return Err(self.key_error(
                    "compensation.amplitude_tol",
                    format!("must be finite and >= 0, got {t}"),
                ));
            }
        }
        let s = k.inverse_smoothing_rel;
        if !(s.is_finite() && s > 0.0 && s <= 1.0) {
            return Err(self.key_error(
                "compensation.inverse_smoothing_rel",
                format!("must lie in (0, 1], got {s}"),
            ));
        }
        Ok(())
    }
}
