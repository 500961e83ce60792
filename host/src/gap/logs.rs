//! The logs of a diagnosis, checked against each other and the nominal sim: SISO, equal
//! sample times, long enough, finite, not constant.
use super::diagnose::MIN_SAMPLES;
use crate::data::Log;
use crate::error::{Error, Result};
use crate::lti::StateSpace;

/// The logs of a diagnosis, checked: training and validation inputs and outputs, sample time.
pub struct Logs {
    /// Sample time, s.
    pub ts: f64,
    /// Training inputs, one per log.
    pub tu: Vec<Vec<f64>>,
    /// Training outputs, one per log.
    pub ty: Vec<Vec<f64>>,
    /// Validation input.
    pub vu: Vec<f64>,
    /// Validation output.
    pub vy: Vec<f64>,
}

/// Checks the logs against each other and the sim (errors as documented on [`crate::gap::diagnose()`]).
pub fn read_logs(sim: &StateSpace, train: &[Log], validate: &Log) -> Result<Logs> {
    if train.is_empty() {
        return Err(Error::InvalidArgument(
            "the gap diagnosis needs at least one training log (--real)".into(),
        ));
    }
    let ts = validate.ts;
    for log in train.iter().chain(std::iter::once(validate)) {
        if (log.ts - ts).abs() > 1e-9 * ts {
            return Err(Error::Data {
                file: log.path.clone(),
                msg: format!(
                    "sample time {} s differs from the validation log's {} s",
                    log.ts, ts
                ),
            });
        }
    }
    if !sim.is_discrete() || (sim.ts - ts).abs() > 1e-9 * ts || !sim.is_siso() {
        return Err(Error::InvalidArgument(format!(
            "diagnose needs the sim as a SISO discrete model at the logs' ts = {ts} s (got {}x{}, \
             ts = {} s); use discretise_for_logs",
            sim.n_outputs(),
            sim.n_inputs(),
            sim.ts
        )));
    }
    let mut tu = Vec::new();
    let mut ty = Vec::new();
    for log in train {
        let (u, y) = siso(log, "training")?;
        tu.push(u);
        ty.push(y);
    }
    let (vu, vy) = siso(validate, "validation")?;
    if let Some(msg) = super::simfile::zero_response(sim) {
        return Err(Error::InvalidArgument(msg));
    }
    Ok(Logs { ts, tu, ty, vu, vy })
}

fn siso(log: &Log, role: &str) -> Result<(Vec<f64>, Vec<f64>)> {
    if log.inputs.len() != 1 || log.outputs.len() != 1 {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: format!(
                "{role} log has {} input and {} output channel(s); the gap diagnosis is SISO",
                log.inputs.len(),
                log.outputs.len()
            ),
        });
    }
    let (u, y) = (log.u(), log.y());
    if u.len() != y.len() {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: format!("input has {} samples, output {}", u.len(), y.len()),
        });
    }
    if u.len() < MIN_SAMPLES {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: format!(
                "{role} log is too short for the gap diagnosis: {} samples, at least \
                 {MIN_SAMPLES} needed",
                u.len()
            ),
        });
    }
    if let Some(k) = u.iter().chain(y).position(|v| !v.is_finite()) {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: format!("non-finite sample at index {}", k % u.len()),
        });
    }
    for (sig, what) in [(u, "input"), (y, "output")] {
        if sig.iter().all(|&v| v == sig[0]) {
            return Err(Error::Data {
                file: log.path.clone(),
                msg: format!(
                    "{role} log's {what} is constant (every sample equals {}): there is no \
                     response to compare (NRMSE undefined)",
                    sig[0]
                ),
            });
        }
    }
    Ok((u.to_vec(), y.to_vec()))
}
