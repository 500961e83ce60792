//! The template context: the validated input with every number already formatted as a C and a
//! Rust literal, so the templates only substitute text (no filters), which lets the same
//! template files render through askama (built in) and minijinja (user overrides).
use serde::Serialize;

use crate::error::{Error, Result};
use crate::input::{check_f32, CodegenInput, Matrices};
use crate::text::{
    c_float, c_string, comment_text, f32_literal, f64_text, rust_string, sanitize_prefix,
};

/// Largest number of check frequencies (keeps the firmware's receipt bounded).
pub const MAX_CHECKS: usize = 64;

/// One check frequency after snapping to the Welch bin grid.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CheckPoint {
    /// Frequency the user asked for, Hz.
    pub requested_hz: f64,
    /// Welch bin `k = round(f·N/fs)`.
    pub bin: usize,
    /// Bin frequency `k·fs/N`, Hz.
    pub hz: f64,
}

/// A number in both languages.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Lit {
    pub c: String,
    pub rs: String,
}

pub(crate) fn lit(v: f64) -> Lit {
    Lit {
        c: c_float(v),
        rs: f32_literal(v),
    }
}

/// A matrix: rows of comma-separated literals in both languages.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct MatLit {
    pub rows_c: Vec<String>,
    pub rows_rs: Vec<String>,
    /// `f64` rows for documentation comments.
    pub rows_doc: Vec<String>,
}

pub(crate) fn mat_lit(m: &[Vec<f64>]) -> MatLit {
    MatLit {
        rows_c: m
            .iter()
            .map(|r| r.iter().map(|&v| c_float(v)).collect::<Vec<_>>().join(", "))
            .collect(),
        rows_rs: m
            .iter()
            .map(|r| {
                r.iter()
                    .map(|&v| f32_literal(v))
                    .collect::<Vec<_>>()
                    .join(", ")
            })
            .collect(),
        rows_doc: m
            .iter()
            .map(|r| {
                r.iter()
                    .map(|&v| f64_text(v))
                    .collect::<Vec<_>>()
                    .join(", ")
            })
            .collect(),
    }
}

fn vec_lit(v: &[f64]) -> (String, String) {
    (
        v.iter().map(|&x| c_float(x)).collect::<Vec<_>>().join(", "),
        v.iter()
            .map(|&x| f32_literal(x))
            .collect::<Vec<_>>()
            .join(", "),
    )
}

#[derive(Debug, Clone, Serialize)]
pub(crate) struct CheckLit {
    pub bin: usize,
    pub hz: Lit,
    pub requested: String,
}

#[derive(Debug, Clone, Serialize)]
pub(crate) struct SourceLit {
    pub comment: String,
    pub c_str: String,
    pub rs_str: String,
    pub sha256: String,
}

#[derive(Debug, Clone, Serialize)]
pub(crate) struct ReceiptLit {
    pub comment: String,
    pub name_c: String,
    pub name_rs: String,
    pub value_rs: String,
    pub condition_rs: String,
    pub pass: bool,
    /// `true`/`false` as text (minijinja would print a bool as `True`).
    pub pass_rs: String,
}

/// Everything the templates see, under the name `c`.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Context {
    pub tool: String,
    pub p: String,
    pub guard: String,
    pub c_file: String,
    pub rs_file: String,
    pub prefix_rs: String,
    pub n_states: usize,
    pub n_inputs: usize,
    pub n_outputs: usize,
    pub ts: Lit,
    pub ts_doc: String,
    pub control_rate_hz: Lit,
    pub a: MatLit,
    pub b: MatLit,
    pub cm: MatLit,
    pub d: MatLit,
    pub has_continuous: bool,
    pub cont_note: String,
    pub cont_a: Vec<String>,
    pub cont_b: Vec<String>,
    pub cont_c: Vec<String>,
    pub cont_d: Vec<String>,
    pub has_pid: bool,
    pub pid_kp: Lit,
    pub pid_ki_d: Lit,
    pub pid_a_d: Lit,
    pub pid_b_d: Lit,
    pub pid_has_rolloff: bool,
    pub pid_rolloff_b_c: String,
    pub pid_rolloff_a_c: String,
    pub pid_rolloff_b_rs: String,
    pub pid_rolloff_a_rs: String,
    pub pid_doc: Vec<String>,
    pub wm_order: usize,
    pub wm_num_c: String,
    pub wm_den_c: String,
    pub wm_num_rs: String,
    pub wm_den_rs: String,
    pub wm_doc: Vec<String>,
    pub welch_n: usize,
    pub fs_hz: Lit,
    pub coherence_gate: Lit,
    pub averages: u32,
    pub settle_periods: u32,
    pub self_id_samples: u64,
    pub excitation_rms: Lit,
    pub excitation_max_bin: usize,
    pub min_checked: usize,
    pub check_count: usize,
    pub checks: Vec<CheckLit>,
    pub check_bins: String,
    pub check_hz_c: String,
    pub check_hz_rs: String,
    pub inputs_sha256: String,
    pub source_count: usize,
    pub sources: Vec<SourceLit>,
    pub receipt_count: usize,
    pub receipts_all_pass: bool,
    pub receipts_all_pass_rs: String,
    pub receipts: Vec<ReceiptLit>,
    pub notes: Vec<String>,
    pub u0_c: String,
    pub u0_rs: String,
    pub y0_c: String,
    pub y0_rs: String,
    pub op_note: String,
    /// The compensation block (`c.comp`).
    pub comp: crate::context_comp::CompLit,
    /// The closed-loop check settings (`c.clcheck`).
    pub clcheck: crate::context_check::ClCheckLit,
    /// The state-space controller block (`c.sk`).
    pub sk: crate::context_sk::SkLit,
    /// The MPC block (`c.mpc`).
    pub mpc: crate::context_sk::MpcLit,
    /// PID + notch form of the chosen controller (`pid-notch`).
    pub kn: crate::context_sk::KnLit,
}

fn is_hex64(s: &str) -> bool {
    s.len() == 64
        && s.bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// Snaps the requested check frequencies to bins (see [`CheckPoint`]), sorted by frequency.
///
/// # Errors
/// A frequency that is not finite/positive, that lands on bin 0, on or above `N/2`, above the
/// highest excited bin `max_bin`, or on the same bin as another one (both named).
pub fn snap_checks(
    check_hz: &[f64],
    welch_n: usize,
    fs_hz: f64,
    max_bin: usize,
) -> Result<Vec<CheckPoint>> {
    if check_hz.is_empty() {
        return Err(Error::input("self_id.check_hz", "no check frequency given"));
    }
    if check_hz.len() > MAX_CHECKS {
        return Err(Error::input(
            "self_id.check_hz",
            format!("{} frequencies, at most {MAX_CHECKS}", check_hz.len()),
        ));
    }
    let df = fs_hz / welch_n as f64;
    let mut pts = Vec::with_capacity(check_hz.len());
    for (i, &f) in check_hz.iter().enumerate() {
        let field = format!("self_id.check_hz[{i}]");
        if !(f.is_finite() && f > 0.0) {
            return Err(Error::input(
                field,
                format!("{f} Hz must be finite and > 0"),
            ));
        }
        let bin = (f / df).round();
        if bin < 1.0 {
            return Err(Error::input(
                field,
                format!("{f} Hz is below the first Welch bin ({df} Hz = fs/N)"),
            ));
        }
        let bin = bin as usize;
        if bin > max_bin {
            return Err(Error::input(
                field,
                format!(
                    "{f} Hz (bin {bin}) is above the highest excited line (bin {max_bin}, {} Hz)",
                    max_bin as f64 * df
                ),
            ));
        }
        pts.push(CheckPoint {
            requested_hz: f,
            bin,
            hz: bin as f64 * df,
        });
    }
    pts.sort_by_key(|p| p.bin);
    for w in pts.windows(2) {
        if w[0].bin == w[1].bin {
            return Err(Error::input(
                "self_id.check_hz",
                format!(
                    "{} Hz and {} Hz fall on the same Welch bin {} ({} Hz); the bin spacing is \
                     {df} Hz",
                    w[0].requested_hz, w[1].requested_hz, w[0].bin, w[0].hz
                ),
            ));
        }
    }
    Ok(pts)
}

fn mat_doc(m: &Matrices) -> [Vec<String>; 4] {
    [
        mat_lit(&m.a).rows_doc,
        mat_lit(&m.b).rows_doc,
        mat_lit(&m.c).rows_doc,
        mat_lit(&m.d).rows_doc,
    ]
}

/// Validates `input` and builds the template context. `inputs_sha256` is the digest of the
/// canonical input (computed by the caller).
pub(crate) fn build(
    input: &CodegenInput,
    inputs_sha256: &str,
) -> Result<(Context, Vec<CheckPoint>)> {
    let p = sanitize_prefix(&input.prefix)?;
    let dims = input.model.matrices.validate("model")?;
    let ts = input.model.ts_s;
    if !(ts.is_finite() && ts > 0.0) {
        return Err(Error::input(
            "model.ts_s",
            format!("{ts} s: the model must be discrete (sample time > 0)"),
        ));
    }
    check_f32("model.ts_s", ts)?;
    let fs = 1.0 / ts;
    // The firmware holds TS_S and the rate in f32: both must be normal f32 numbers (a 1e-300 s
    // step made the rate infinite and the sample time zero).
    if !(f64::from(f32::MIN_POSITIVE)..=f64::from(f32::MAX)).contains(&ts)
        || fs > f64::from(f32::MAX)
    {
        return Err(Error::input(
            "model.ts_s",
            format!("{ts:e} s: the sample time and the rate 1/ts must be normal 32-bit floats"),
        ));
    }

    // Compensation (validated here; rendered below).
    if let Some(comp) = &input.compensation {
        comp.validate_at(ts)?;
    }

    // Continuous model (documentation).
    let (has_continuous, cont_note, cont) = match &input.continuous {
        Some(cm) => {
            let cd = cm.matrices.validate("continuous")?;
            if (cd.n, cd.m, cd.p) != (dims.n, dims.m, dims.p) {
                return Err(Error::input(
                    "continuous",
                    format!(
                        "has {}x{} with {} states, the discrete model {}x{} with {}",
                        cd.p, cd.m, cd.n, dims.p, dims.m, dims.n
                    ),
                ));
            }
            (true, comment_text(&cm.note), mat_doc(&cm.matrices))
        }
        None => (false, String::new(), Default::default()),
    };
    let [cont_a, cont_b, cont_c, cont_d] = cont;

    // PID.
    let (has_pid, pid_vals, pid_has_rolloff, rb, ra, pid_doc) = match &input.pid {
        Some(pid) => {
            for (name, v) in [
                ("pid.ts_s", pid.ts_s),
                ("pid.kp", pid.kp),
                ("pid.ki_d", pid.ki_d),
                ("pid.a_d", pid.a_d),
                ("pid.b_d", pid.b_d),
            ] {
                check_f32(name, v)?;
            }
            if (pid.ts_s - ts).abs() > 1e-9 * ts {
                return Err(Error::input(
                    "pid.ts_s",
                    format!(
                        "{} s differs from the model's sample time {ts} s; tune at the control rate",
                        pid.ts_s
                    ),
                ));
            }
            let (has_r, rb, ra) = match &pid.rolloff {
                Some(bq) => {
                    for (k, v) in bq.b.iter().enumerate() {
                        check_f32(&format!("pid.rolloff.b[{k}]"), *v)?;
                    }
                    for (k, v) in bq.a.iter().enumerate() {
                        check_f32(&format!("pid.rolloff.a[{k}]"), *v)?;
                    }
                    if bq.a[0] != 1.0 {
                        return Err(Error::input(
                            "pid.rolloff.a[0]",
                            format!("{} must be 1 (normalised section)", bq.a[0]),
                        ));
                    }
                    (true, vec_lit(&bq.b), vec_lit(&bq.a))
                }
                None => (false, vec_lit(&[0.0, 0.0, 0.0]), vec_lit(&[1.0, 0.0, 0.0])),
            };
            let mut doc = Vec::new();
            if let Some(f) = pid.prewarp_hz {
                doc.push(format!("Tustin, prewarped at {} Hz.", f64_text(f)));
            } else {
                doc.push("Tustin (no prewarp).".to_string());
            }
            if let Some(c) = pid.continuous {
                doc.push(format!(
                    "Continuous: Kp = {}, Ki = {} 1/s, Kd = {} s, tau_f = {} s.",
                    f64_text(c.kp),
                    f64_text(c.ki),
                    f64_text(c.kd),
                    f64_text(c.tau_f)
                ));
            }
            (
                true,
                [lit(pid.kp), lit(pid.ki_d), lit(pid.a_d), lit(pid.b_d)],
                has_r,
                rb,
                ra,
                doc,
            )
        }
        None => (
            false,
            [lit(0.0), lit(0.0), lit(0.0), lit(0.0)],
            false,
            vec_lit(&[0.0, 0.0, 0.0]),
            vec_lit(&[1.0, 0.0, 0.0]),
            Vec::new(),
        ),
    };
    let [pid_kp, pid_ki_d, pid_a_d, pid_b_d] = pid_vals;

    // W_m.
    let w = &input.weight;
    if w.num.is_empty() || w.num.len() != w.den.len() {
        return Err(Error::input(
            "weight",
            format!(
                "numerator has {} coefficients and denominator {}; they must be equal and >= 1 \
                 (a proper weight)",
                w.num.len(),
                w.den.len()
            ),
        ));
    }
    for (k, v) in w.num.iter().enumerate() {
        check_f32(&format!("weight.num[{k}]"), *v)?;
    }
    for (k, v) in w.den.iter().enumerate() {
        check_f32(&format!("weight.den[{k}]"), *v)?;
    }
    if w.den[0] == 0.0 {
        return Err(Error::input("weight.den[0]", "leading coefficient is 0"));
    }
    let (wm_num_c, wm_num_rs) = vec_lit(&w.num);
    let (wm_den_c, wm_den_rs) = vec_lit(&w.den);
    let wm_doc = vec![
        comment_text(&w.note),
        format!(
            "num(s) = [{}], den(s) = [{}] (f64, descending powers of s in rad/s)",
            w.num
                .iter()
                .map(|&v| f64_text(v))
                .collect::<Vec<_>>()
                .join(", "),
            w.den
                .iter()
                .map(|&v| f64_text(v))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    ];

    // Self-identification settings.
    let s = &input.self_id;
    let n = s.welch_n;
    if !(n.is_power_of_two() && (64..=4096).contains(&n)) {
        return Err(Error::input(
            "self_id.welch_n",
            format!("{n} must be a power of two in 64..=4096 (the firmware's Welch sizes)"),
        ));
    }
    if !(s.coherence_gate.is_finite() && s.coherence_gate > 0.0 && s.coherence_gate < 1.0) {
        return Err(Error::input(
            "self_id.coherence_gate",
            format!("{} must lie in (0, 1)", s.coherence_gate),
        ));
    }
    if !(2..=1 << 20).contains(&s.averages) {
        return Err(Error::input(
            "self_id.averages",
            format!(
                "{} must be in 2..=1048576 (coherence of one average is identically 1)",
                s.averages
            ),
        ));
    }
    if s.settle_periods > 10_000 {
        return Err(Error::input(
            "self_id.settle_periods",
            format!("{} is more than 10000", s.settle_periods),
        ));
    }
    if !(s.excitation_rms.is_finite() && s.excitation_rms > 0.0 && s.excitation_rms <= 1e9) {
        return Err(Error::input(
            "self_id.excitation_rms",
            format!("{} must be finite, > 0 and <= 1e9", s.excitation_rms),
        ));
    }
    let df = fs / n as f64;
    let max_bin_f = (s.excitation_max_hz / df).floor();
    if !(s.excitation_max_hz.is_finite() && max_bin_f >= 1.0) {
        return Err(Error::input(
            "self_id.excitation_max_hz",
            format!(
                "{} Hz excites no line (bin spacing {df} Hz)",
                s.excitation_max_hz
            ),
        ));
    }
    let max_bin = (max_bin_f as usize).min(n / 2 - 1);
    if (max_bin_f as usize) > n / 2 - 1 {
        return Err(Error::input(
            "self_id.excitation_max_hz",
            format!(
                "{} Hz is at or above the Nyquist frequency {} Hz",
                s.excitation_max_hz,
                fs / 2.0
            ),
        ));
    }
    let checks = snap_checks(&s.check_hz, n, fs, max_bin)?;
    if !(1..=checks.len()).contains(&s.min_checked) {
        return Err(Error::input(
            "self_id.min_checked",
            format!("{} must be in 1..={}", s.min_checked, checks.len()),
        ));
    }
    let check_lits: Vec<CheckLit> = checks
        .iter()
        .map(|c| CheckLit {
            bin: c.bin,
            hz: lit(c.hz),
            requested: f64_text(c.requested_hz),
        })
        .collect();
    let hz: Vec<f64> = checks.iter().map(|c| c.hz).collect();
    let (check_hz_c, check_hz_rs) = vec_lit(&hz);

    // Provenance.
    let pv = &input.provenance;
    let mut sources = Vec::new();
    for (i, sd) in pv.sources.iter().enumerate() {
        if !is_hex64(&sd.sha256) {
            return Err(Error::input(
                format!("provenance.sources[{i}].sha256"),
                format!("{:?} is not 64 lower-case hex digits", sd.sha256),
            ));
        }
        sources.push(SourceLit {
            comment: comment_text(&sd.label),
            c_str: c_string(&sd.label),
            rs_str: rust_string(&sd.label),
            sha256: sd.sha256.clone(),
        });
    }
    let receipts: Vec<ReceiptLit> = pv
        .receipts
        .iter()
        .map(|r| ReceiptLit {
            comment: comment_text(&format!(
                "{} {}: {} (limit {})",
                if r.pass { "PASS" } else { "FAIL" },
                r.name,
                r.value,
                r.condition
            )),
            name_c: c_string(&r.name),
            name_rs: rust_string(&r.name),
            value_rs: rust_string(&r.value),
            condition_rs: rust_string(&r.condition),
            pass: r.pass,
            pass_rs: r.pass.to_string(),
        })
        .collect();

    // Operating point.
    let (u0, y0, op_note) = match &input.operating_point {
        Some(op) => {
            if op.u0.len() != dims.m {
                return Err(Error::input(
                    "model.operating_point.u0",
                    format!("{} values for {} inputs", op.u0.len(), dims.m),
                ));
            }
            if op.y0.len() != dims.p {
                return Err(Error::input(
                    "model.operating_point.y0",
                    format!("{} values for {} outputs", op.y0.len(), dims.p),
                ));
            }
            for (name, vals) in [("u0", &op.u0), ("y0", &op.y0)] {
                for (i, &v) in vals.iter().enumerate() {
                    check_f32(&format!("model.operating_point.{name}[{i}]"), v)?;
                }
            }
            (op.u0.clone(), op.y0.clone(), comment_text(&op.note))
        }
        None => (
            vec![0.0; dims.m],
            vec![0.0; dims.p],
            "no operating point recorded with the model: it maps the raw signals".to_string(),
        ),
    };
    let (u0_c, u0_rs) = vec_lit(&u0);
    let (y0_c, y0_rs) = vec_lit(&y0);

    let comp = crate::context_comp::comp_lit(input.compensation.as_ref(), ts);
    let clcheck = crate::context_check::clcheck_lit(input)?;
    let sk = crate::context_sk::sk_lit(input.state_controller.as_ref(), ts)?;
    let mpc = crate::context_sk::mpc_lit(input.state_controller.as_ref(), ts, dims.n)?;
    let kn = crate::context_sk::kn_lit(input.state_controller.as_ref(), ts)?;

    let ctx = Context {
        comp,
        clcheck,
        sk,
        mpc,
        kn,
        u0_c,
        u0_rs,
        y0_c,
        y0_rs,
        op_note,
        tool: comment_text(&pv.tool),
        guard: format!("{p}_MODEL_H"),
        c_file: format!("{}.h", p.to_ascii_lowercase()),
        rs_file: format!("{}.rs", p.to_ascii_lowercase()),
        prefix_rs: rust_string(&p),
        p,
        n_states: dims.n,
        n_inputs: dims.m,
        n_outputs: dims.p,
        ts: lit(ts),
        ts_doc: f64_text(ts),
        control_rate_hz: lit(fs),
        a: mat_lit(&input.model.matrices.a),
        b: mat_lit(&input.model.matrices.b),
        cm: mat_lit(&input.model.matrices.c),
        d: mat_lit(&input.model.matrices.d),
        has_continuous,
        cont_note,
        cont_a,
        cont_b,
        cont_c,
        cont_d,
        has_pid,
        pid_kp,
        pid_ki_d,
        pid_a_d,
        pid_b_d,
        pid_has_rolloff,
        pid_rolloff_b_c: rb.0,
        pid_rolloff_b_rs: rb.1,
        pid_rolloff_a_c: ra.0,
        pid_rolloff_a_rs: ra.1,
        pid_doc,
        wm_order: w.num.len() - 1,
        wm_num_c,
        wm_den_c,
        wm_num_rs,
        wm_den_rs,
        wm_doc,
        welch_n: n,
        fs_hz: lit(fs),
        coherence_gate: lit(s.coherence_gate),
        averages: s.averages,
        settle_periods: s.settle_periods,
        self_id_samples: u64::from(s.settle_periods + s.averages) * n as u64,
        excitation_rms: lit(s.excitation_rms),
        excitation_max_bin: max_bin,
        min_checked: s.min_checked,
        check_count: checks.len(),
        checks: check_lits,
        check_bins: checks
            .iter()
            .map(|c| c.bin.to_string())
            .collect::<Vec<_>>()
            .join(", "),
        check_hz_c,
        check_hz_rs,
        inputs_sha256: inputs_sha256.to_string(),
        source_count: sources.len(),
        sources,
        receipt_count: receipts.len(),
        receipts_all_pass: pv.receipts.iter().all(|r| r.pass),
        receipts_all_pass_rs: pv.receipts.iter().all(|r| r.pass).to_string(),
        receipts,
        notes: pv.notes.iter().map(|n| comment_text(n)).collect(),
    };
    Ok((ctx, checks))
}
