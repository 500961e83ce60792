//! The nominal ("simulation") model handed to `ferrosid gap --sim`.
//!
//! JSON, one of
//! * state space: `{"ts": 0.0, "a": [[..], ..], "b": [[..], ..], "c": [[..]], "d": [[..]]}`,
//!   matrices as lists of rows (A n×n, B n×1, C 1×n, D 1×1 for the SISO logs the diagnosis
//!   takes);
//! * transfer function: `{"ts": .., "num": [..], "den": [..]}`, coefficients in descending
//!   powers of s (continuous) or z (discrete).
//!
//! `ts` is the sample time in seconds, 0 for a continuous model. Units are those of the logs.
//! A continuous model is discretised by zero-order hold at the logs' sample time; a discrete
//! one must have the logs' sample time (relative tolerance 1e-9).
use crate::data::OperatingPoint;
use crate::error::{Error, Result};
use crate::lti::{StateSpace, StateSpaceData, TransferFunction};
use serde::Deserialize;
use std::path::Path;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TfData {
    ts: f64,
    num: Vec<f64>,
    den: Vec<f64>,
}

/// Reads and checks a sim model file (see the module docs). Errors name the file: unreadable
/// ([`Error::Io`]), malformed JSON ([`Error::Parse`] with the line), neither form or
/// inconsistent shapes ([`Error::Data`]).
pub fn load_sim(path: &Path) -> Result<StateSpace> {
    Ok(load_sim_with_operating_point(path)?.0)
}

/// Reads a sim model file like [`load_sim`] and also returns the operating point a state-space
/// model file carries (`operating_point`, written by `identify` and `run`; `None` for transfer
/// functions and older files). See [`crate::operating_point`] for how it applies to raw logs.
pub fn load_sim_with_operating_point(path: &Path) -> Result<(StateSpace, Option<OperatingPoint>)> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        file: path.to_path_buf(),
        source,
    })?;
    let sys = parse_sim(&text, path)?;
    // parse_sim has validated the JSON; only a state-space file can carry an operating point.
    let op = serde_json::from_str::<serde_json::Value>(&text)
        .ok()
        .filter(|v| v.get("a").is_some())
        .and_then(|v| serde_json::from_value::<StateSpaceData>(v).ok())
        .and_then(|ss| ss.operating_point);
    Ok((sys, op))
}

/// Parses sim-model JSON text; `path` is only used to name the source in errors.
pub fn parse_sim(text: &str, path: &Path) -> Result<StateSpace> {
    let data_err = |msg: String| Error::Data {
        file: path.to_path_buf(),
        msg,
    };
    let value: serde_json::Value = serde_json::from_str(text).map_err(|e| Error::Parse {
        file: path.to_path_buf(),
        line: e.line(),
        msg: format!("invalid JSON: {e}"),
    })?;
    let Some(obj) = value.as_object() else {
        return Err(data_err(
            "sim model must be a JSON object with `ts` and either a, b, c, d or num, den".into(),
        ));
    };
    let has = |k: &str| obj.contains_key(k);
    if !has("ts") {
        return Err(data_err(
            "sim model has no `ts` (sample time in seconds; 0 for continuous time)".into(),
        ));
    }
    let sys = if has("num") || has("den") {
        let tf: TfData = serde_json::from_value(value.clone())
            .map_err(|e| data_err(format!("transfer-function sim model: {e}")))?;
        TransferFunction::new(tf.num, tf.den, tf.ts)
            .and_then(|t| t.to_state_space())
            .map_err(|e| data_err(format!("transfer-function sim model: {e}")))?
    } else if has("a") {
        let ss: StateSpaceData = serde_json::from_value(value.clone())
            .map_err(|e| data_err(format!("state-space sim model: {e}")))?;
        StateSpace::try_from(&ss).map_err(|e| data_err(format!("state-space sim model: {e}")))?
    } else {
        return Err(data_err(
            "sim model needs either `a`, `b`, `c`, `d` (state space) or `num`, `den` (transfer \
             function)"
                .into(),
        ));
    };
    Ok(sys)
}

/// The sim model as a discrete model at the logs' sample time `ts` (s): ZOH-discretised when
/// continuous, checked when discrete. Errors when the model is not SISO (the logs have one
/// input and one output), when a discrete model has another sample time, or when the
/// discrete model has a pole on or outside the unit circle other than an integrator (z = 1,
/// see [`is_integrator_pole`]; the diagnosis compares free-run simulations), and when its
/// response is identically zero ([`zero_response`]); `path` names the sim file in the error.
pub fn discretise_for_logs(sys: &StateSpace, ts: f64, path: &Path) -> Result<StateSpace> {
    let data_err = |msg: String| Error::Data {
        file: path.to_path_buf(),
        msg,
    };
    if !sys.is_siso() {
        return Err(data_err(format!(
            "sim model has {} input(s) and {} output(s), but the logs have one input and one \
             output",
            sys.n_inputs(),
            sys.n_outputs()
        )));
    }
    let d = if sys.is_discrete() {
        if (sys.ts - ts).abs() > 1e-9 * ts {
            return Err(data_err(format!(
                "sim model is discrete with ts = {} s but the logs are sampled at ts = {ts} s",
                sys.ts
            )));
        }
        sys.clone()
    } else {
        sys.c2d_zoh(ts)
            .map_err(|e| data_err(format!("discretising the sim model at {ts} s: {e}")))?
    };
    let poles = d
        .poles()
        .map_err(|e| data_err(format!("poles of the sim model: {e}")))?;
    if let Some(p) = poles
        .iter()
        .find(|p| p.norm() >= 1.0 - 1e-9 && !is_integrator_pole(**p))
    {
        let s = if sys.is_discrete() {
            String::new()
        } else {
            let sp = num_complex::Complex64::new(p.norm().ln(), p.im.atan2(p.re)) / ts;
            format!(" (s = {:.4} {:+.4}j rad/s)", sp.re, sp.im)
        };
        return Err(data_err(format!(
            "sim model is not asymptotically stable: pole z = {:.6} {:+.6}j, |z| = {:.6}{s}. The \
             gap diagnosis compares free-run simulations, which need a stable (damped) model; \
             integrators (poles at z = 1, s = 0) are accepted",
            p.re,
            p.im,
            p.norm()
        )));
    }
    if let Some(msg) = zero_response(&d) {
        return Err(data_err(msg));
    }
    Ok(d)
}

/// Largest distance |z − 1| at which a discrete pole counts as an integrator (a pole at z = 1,
/// s = 0), which [`discretise_for_logs`] accepts (a position output of a velocity-driven axis).
pub const INTEGRATOR_TOL: f64 = 1e-6;

/// Whether the discrete pole `z` is an integrator (|z − 1| <= [`INTEGRATOR_TOL`]).
pub fn is_integrator_pole(z: num_complex::Complex64) -> bool {
    (z - 1.0).norm() <= INTEGRATOR_TOL
}

/// `Some(reason)` when the SISO model's response is identically zero: every Markov parameter
/// D, CB, CAB, …, CA^(n−1)B is zero (relative to the scale ‖C‖·‖A‖^k·‖B‖ at 1e-12; B = 0 or
/// C = 0 with D = 0 are the common cases). Such a model cannot be compared with a log.
pub fn zero_response(sys: &StateSpace) -> Option<String> {
    let n = sys.n_states();
    let max_abs = |m: faer::MatRef<'_, f64>| {
        let mut v = 0.0f64;
        for j in 0..m.ncols() {
            for i in 0..m.nrows() {
                v = v.max(m[(i, j)].abs());
            }
        }
        v
    };
    if max_abs(sys.d.as_ref()) > 0.0 {
        return None;
    }
    let (nb, nc, na) = (
        max_abs(sys.b.as_ref()),
        max_abs(sys.c.as_ref()),
        max_abs(sys.a.as_ref()),
    );
    let what = if nb == 0.0 {
        "B = 0 (the input reaches no state) and D = 0"
    } else if nc == 0.0 {
        "C = 0 (no state reaches the output) and D = 0"
    } else {
        // Markov parameters C A^k B, k = 0..n-1.
        let mut x: Vec<f64> = (0..n).map(|i| sys.b[(i, 0)]).collect();
        let mut scale = nb * nc * n as f64;
        for _ in 0..n {
            let h: f64 = (0..n).map(|i| sys.c[(0, i)] * x[i]).sum();
            if h.abs() > 1e-12 * scale {
                return None;
            }
            x = (0..n)
                .map(|i| (0..n).map(|j| sys.a[(i, j)] * x[j]).sum())
                .collect();
            scale *= na.max(1e-300) * n as f64;
        }
        "every Markov parameter (D, CB, CAB, ...) zero"
    };
    Some(format!(
        "sim model has {what}: its output is identically zero, so there is no response to \
         compare with the logs"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_both_forms() {
        let p = Path::new("x.json");
        let ss = parse_sim(
            r#"{"ts": 0.0, "a": [[-2.0]], "b": [[1.0]], "c": [[3.0]], "d": [[0.0]]}"#,
            p,
        )
        .unwrap();
        assert_eq!(ss.n_states(), 1);
        let tf = parse_sim(r#"{"ts": 0, "num": [3.0], "den": [1.0, 2.0]}"#, p).unwrap();
        // Both are 3/(s+2): equal DC gain 1.5.
        assert!((tf.dc_gain().unwrap()[(0, 0)] - 1.5).abs() < 1e-12);
        assert!((ss.dc_gain().unwrap()[(0, 0)] - 1.5).abs() < 1e-12);
    }

    #[test]
    fn bad_json_names_file_and_line() {
        let e = parse_sim("{\n\"ts\": 0,\n\"a\": [[1,]]\n}", Path::new("sim.json")).unwrap_err();
        let s = e.to_string();
        assert!(s.contains("sim.json:3"), "{s}");
    }

    #[test]
    fn missing_parts_are_errors() {
        let p = Path::new("m.json");
        assert!(parse_sim(r#"{"a": [[1]]}"#, p)
            .unwrap_err()
            .to_string()
            .contains("ts"));
        assert!(parse_sim(r#"{"ts": 0}"#, p)
            .unwrap_err()
            .to_string()
            .contains("num"));
        let e = parse_sim(
            r#"{"ts": 0, "a": [[1, 0]], "b": [[1]], "c": [[1]], "d": [[0]]}"#,
            p,
        )
        .unwrap_err();
        assert!(e.to_string().contains("m.json"), "{e}");
    }

    #[test]
    fn two_input_and_unstable_models_are_refused() {
        let p = Path::new("s.json");
        let two = parse_sim(
            r#"{"ts": 0, "a": [[-1]], "b": [[1, 2]], "c": [[1]], "d": [[0, 0]]}"#,
            p,
        )
        .unwrap();
        let e = discretise_for_logs(&two, 1e-3, p).unwrap_err().to_string();
        assert!(e.contains("2 input"), "{e}");
        let unstable = parse_sim(r#"{"ts": 0, "num": [1], "den": [1, -3]}"#, p).unwrap();
        let e = discretise_for_logs(&unstable, 1e-3, p)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("not asymptotically stable") && e.contains("s = 3.0000"),
            "{e}"
        );
        let wrong_ts = parse_sim(r#"{"ts": 0.01, "num": [1], "den": [1, -0.5]}"#, p).unwrap();
        let e = discretise_for_logs(&wrong_ts, 1e-3, p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("ts = 0.01"), "{e}");
    }
}
