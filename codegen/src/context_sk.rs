//! The state-space controller block of the template context (`c.sk`): A, B, C, D of a
//! [`StateController`] as C and Rust literals (B as a column, C as a row), validated as a
//! discrete SISO controller at the model's sample time, with its rails and anti-windup gain
//! when given; for `pid-notch` also the PID + notch biquads (`c.kn`); or, for an MPC, its QP
//! data (`c.mpc`).
use serde::Serialize;

use crate::context::{lit, mat_lit, Lit, MatLit};
use crate::error::{Error, Result};
use crate::input::{check_f32, MpcController, PidNotchController, StateController};
use crate::text::comment_text;

/// What the templates see under `c.sk` (`has == false`: nothing is emitted).
#[derive(Debug, Clone, Serialize)]
pub(crate) struct SkLit {
    pub has: bool,
    pub n: usize,
    pub a: MatLit,
    /// B as one row (the column's entries).
    pub b: MatLit,
    pub c: MatLit,
    pub d: Lit,
    pub doc: Vec<String>,
    /// Rails and back-calculation gain present.
    pub has_sat: bool,
    /// L as one row.
    pub l: MatLit,
    pub u_min: Lit,
    pub u_max: Lit,
}

/// Largest state-space controller order the generator accepts (the firmware's
/// `MAX_STATE_ORDER`).
pub const MAX_CONTROLLER_ORDER: usize = 16;
/// Most notch/lead sections (the firmware's `MAX_SECTIONS`).
pub const MAX_NOTCH_SECTIONS: usize = 8;

/// Validates and renders `sk` for a model sampled at `ts` s (nothing when it is an MPC: see
/// [`mpc_lit`]).
pub(crate) fn sk_lit(sk: Option<&StateController>, ts: f64) -> Result<SkLit> {
    let Some(k) = sk.filter(|k| k.mpc.is_none()) else {
        return Ok(SkLit {
            has: false,
            n: 0,
            a: mat_lit(&[]),
            b: mat_lit(&[]),
            c: mat_lit(&[]),
            d: lit(0.0),
            doc: Vec::new(),
            has_sat: false,
            l: mat_lit(&[]),
            u_min: lit(0.0),
            u_max: lit(0.0),
        });
    };
    let dims = k.matrices.validate("state_controller")?;
    if dims.n > MAX_CONTROLLER_ORDER {
        return Err(Error::input(
            "state_controller.a",
            format!(
                "order {} is above the firmware's {MAX_CONTROLLER_ORDER} (reduce it: \
                 control.hinf_order)",
                dims.n
            ),
        ));
    }
    if dims.m != 1 || dims.p != 1 {
        return Err(Error::input(
            "state_controller",
            format!(
                "must be SISO (e in, u out), got {} outputs and {} inputs",
                dims.p, dims.m
            ),
        ));
    }
    if !((k.ts_s - ts).abs() <= 1e-12 * ts) {
        return Err(Error::input(
            "state_controller.ts_s",
            format!("{} s differs from the model's {ts} s", k.ts_s),
        ));
    }
    let m = &k.matrices;
    let b_row: Vec<f64> = m.b.iter().map(|r| r[0]).collect();
    let (has_sat, l, u_min, u_max) = match &k.saturation {
        Some(s) => {
            if s.l.len() != dims.n {
                return Err(Error::input(
                    "state_controller.saturation.l",
                    format!("has {} entries, expected {}", s.l.len(), dims.n),
                ));
            }
            for (i, &v) in s.l.iter().enumerate() {
                check_f32(&format!("state_controller.saturation.l[{i}]"), v)?;
            }
            check_rails("state_controller.saturation", s.u_min, s.u_max)?;
            (true, s.l.clone(), s.u_min, s.u_max)
        }
        None => (false, Vec::new(), 0.0, 0.0),
    };
    Ok(SkLit {
        has_sat,
        l: mat_lit(&[l]),
        u_min: lit(u_min),
        u_max: lit(u_max),
        has: true,
        n: dims.n,
        a: mat_lit(&m.a),
        b: mat_lit(&[b_row]),
        c: mat_lit(&m.c),
        d: lit(m.d[0][0]),
        doc: vec![
            format!("method: {}", comment_text(&k.method)),
            comment_text(&k.note),
        ],
    })
}

fn check_rails(what: &str, u_min: f64, u_max: f64) -> Result<()> {
    check_f32(&format!("{what}.u_min"), u_min)?;
    check_f32(&format!("{what}.u_max"), u_max)?;
    if u_min < u_max {
        Ok(())
    } else {
        Err(Error::input(
            format!("{what}.u_max"),
            format!("the rails [{u_min}, {u_max}] are empty"),
        ))
    }
}

/// What the templates see under `c.kn` (`has == false`: nothing is emitted).
#[derive(Debug, Clone, Serialize)]
pub(crate) struct KnLit {
    pub has: bool,
    pub sections: usize,
    pub kp: Lit,
    pub ki_d: Lit,
    pub a_d: Lit,
    pub b_d: Lit,
    pub has_rolloff: bool,
    /// Roll-off `[b]` and `[a]` as rows (identity when absent).
    pub rolloff: MatLit,
    /// One row `[b0, b1, b2, a0, a1, a2]` per section.
    pub sos: MatLit,
    pub u_min: Lit,
    pub u_max: Lit,
    pub anti_windup: bool,
}

/// Validates and renders the PID + notch form of `sk` at the model's sample time `ts`.
pub(crate) fn kn_lit(sk: Option<&StateController>, ts: f64) -> Result<KnLit> {
    let Some(k) = sk.and_then(|k| k.pid_notch.as_ref()) else {
        return Ok(KnLit {
            has: false,
            sections: 0,
            kp: lit(0.0),
            ki_d: lit(0.0),
            a_d: lit(0.0),
            b_d: lit(0.0),
            has_rolloff: false,
            rolloff: mat_lit(&[]),
            sos: mat_lit(&[]),
            u_min: lit(0.0),
            u_max: lit(0.0),
            anti_windup: false,
        });
    };
    check_kn(k, ts)?;
    let p = &k.pid;
    let ro = p
        .rolloff
        .map_or(([1.0, 0.0, 0.0], [1.0, 0.0, 0.0]), |b| (b.b, b.a));
    Ok(KnLit {
        has: true,
        sections: k.sections.len(),
        kp: lit(p.kp),
        ki_d: lit(p.ki_d),
        a_d: lit(p.a_d),
        b_d: lit(p.b_d),
        has_rolloff: p.rolloff.is_some(),
        rolloff: mat_lit(&[ro.0.to_vec(), ro.1.to_vec()]),
        sos: mat_lit(
            &k.sections
                .iter()
                .map(|s| s.b.iter().chain(s.a.iter()).copied().collect())
                .collect::<Vec<_>>(),
        ),
        u_min: lit(k.u_min),
        u_max: lit(k.u_max),
        anti_windup: k.anti_windup,
    })
}

fn check_kn(k: &PidNotchController, ts: f64) -> Result<()> {
    let w = "state_controller.pid_notch";
    let n = k.sections.len();
    if !(1..=MAX_NOTCH_SECTIONS).contains(&n) {
        return Err(Error::input(
            format!("{w}.sections"),
            format!("{n} sections, need 1..={MAX_NOTCH_SECTIONS}"),
        ));
    }
    let p = &k.pid;
    if !((p.ts_s - ts).abs() <= 1e-12 * ts) {
        return Err(Error::input(
            format!("{w}.pid.ts_s"),
            format!("{} s differs from the model's {ts} s", p.ts_s),
        ));
    }
    for (name, v) in [
        ("kp", p.kp),
        ("ki_d", p.ki_d),
        ("a_d", p.a_d),
        ("b_d", p.b_d),
    ] {
        check_f32(&format!("{w}.pid.{name}"), v)?;
    }
    if !(p.a_d.abs() < 1.0) {
        return Err(Error::input(
            format!("{w}.pid.a_d"),
            format!("{} is not inside the unit circle", p.a_d),
        ));
    }
    let bqs = p
        .rolloff
        .iter()
        .map(|b| ("pid.rolloff".to_string(), b))
        .chain(
            k.sections
                .iter()
                .enumerate()
                .map(|(i, b)| (format!("sections[{i}]"), b)),
        );
    for (name, b) in bqs {
        for (j, &v) in b.b.iter().chain(b.a.iter()).enumerate() {
            check_f32(&format!("{w}.{name}[{j}]"), v)?;
        }
        if b.a[0] != 1.0 {
            return Err(Error::input(
                format!("{w}.{name}.a[0]"),
                format!("{} must be 1 (normalised section)", b.a[0]),
            ));
        }
    }
    check_rails(w, k.u_min, k.u_max)
}

/// What the templates see under `c.mpc` (`has == false`: nothing is emitted).
#[derive(Debug, Clone, Serialize)]
pub(crate) struct MpcLit {
    pub has: bool,
    pub n: usize,
    pub nx: usize,
    pub k: MatLit,
    pub gx: MatLit,
    /// g_r as one row.
    pub gr: MatLit,
    pub two_r_rate: Lit,
    pub sigma: Lit,
    pub rho: Lit,
    pub u_min: Lit,
    pub u_max: Lit,
    pub du_max: Lit,
    pub iterations: u32,
    pub doc: Vec<String>,
}

/// Largest MPC horizon the generator accepts (K is N² floats).
pub const MAX_MPC_HORIZON: usize = 64;

/// Validates and renders the MPC of `sk` for a model of `n_model` states sampled at `ts` s.
pub(crate) fn mpc_lit(sk: Option<&StateController>, ts: f64, n_model: usize) -> Result<MpcLit> {
    let (Some(k), Some(m)) = (sk, sk.and_then(|k| k.mpc.as_ref())) else {
        return Ok(MpcLit {
            has: false,
            n: 0,
            nx: 0,
            k: mat_lit(&[]),
            gx: mat_lit(&[]),
            gr: mat_lit(&[]),
            two_r_rate: lit(0.0),
            sigma: lit(0.0),
            rho: lit(0.0),
            u_min: lit(0.0),
            u_max: lit(0.0),
            du_max: lit(0.0),
            iterations: 0,
            doc: Vec::new(),
        });
    };
    let dims = k.matrices.validate("state_controller")?;
    if dims.m != 1 || dims.p != 1 || dims.n != n_model {
        return Err(Error::input(
            "state_controller",
            format!(
                "an MPC's prediction model must be the SISO model ({n_model} states), got {} \
                 states, {} outputs, {} inputs",
                dims.n, dims.p, dims.m
            ),
        ));
    }
    if k.matrices.d[0][0] != 0.0 {
        return Err(Error::input(
            "state_controller.d",
            "an MPC's prediction model needs D = 0",
        ));
    }
    if !((k.ts_s - ts).abs() <= 1e-12 * ts) {
        return Err(Error::input(
            "state_controller.ts_s",
            format!("{} s differs from the model's {ts} s", k.ts_s),
        ));
    }
    check_mpc(m, dims.n)?;
    Ok(MpcLit {
        has: true,
        n: m.horizon,
        nx: dims.n,
        k: mat_lit(&m.k),
        gx: mat_lit(&m.gx),
        gr: mat_lit(std::slice::from_ref(&m.gr)),
        two_r_rate: lit(m.two_r_rate),
        sigma: lit(m.sigma),
        rho: lit(m.rho),
        u_min: lit(m.u_min),
        u_max: lit(m.u_max),
        du_max: lit(m.du_max),
        iterations: m.iterations,
        doc: vec![
            format!("method: {}", comment_text(&k.method)),
            comment_text(&k.note),
        ],
    })
}

fn check_mpc(m: &MpcController, nx: usize) -> Result<()> {
    let n = m.horizon;
    if !(1..=MAX_MPC_HORIZON).contains(&n) {
        return Err(Error::input(
            "state_controller.mpc.horizon",
            format!("{n} is outside [1, {MAX_MPC_HORIZON}]"),
        ));
    }
    for (name, mat, cols) in [("k", &m.k, n), ("gx", &m.gx, nx)] {
        if mat.len() != n {
            return Err(Error::input(
                format!("state_controller.mpc.{name}"),
                format!("has {} rows, expected the horizon {n}", mat.len()),
            ));
        }
        for (i, row) in mat.iter().enumerate() {
            if row.len() != cols {
                return Err(Error::input(
                    format!("state_controller.mpc.{name}[{i}]"),
                    format!("has {} entries, expected {cols}", row.len()),
                ));
            }
            for (j, &v) in row.iter().enumerate() {
                check_f32(&format!("state_controller.mpc.{name}[{i}][{j}]"), v)?;
            }
        }
    }
    if m.gr.len() != n {
        return Err(Error::input(
            "state_controller.mpc.gr",
            format!("has {} entries, expected the horizon {n}", m.gr.len()),
        ));
    }
    for (i, &v) in m.gr.iter().enumerate() {
        check_f32(&format!("state_controller.mpc.gr[{i}]"), v)?;
    }
    for (name, v) in [
        ("two_r_rate", m.two_r_rate),
        ("sigma", m.sigma),
        ("rho", m.rho),
        ("u_min", m.u_min),
        ("u_max", m.u_max),
        ("du_max", m.du_max),
    ] {
        check_f32(&format!("state_controller.mpc.{name}"), v)?;
    }
    if !(m.rho > 0.0 && m.sigma >= 0.0 && m.two_r_rate >= 0.0) {
        return Err(Error::input(
            "state_controller.mpc",
            format!(
                "needs rho > 0, sigma >= 0 and two_r_rate >= 0, got {}, {}, {}",
                m.rho, m.sigma, m.two_r_rate
            ),
        ));
    }
    if !(m.u_min < m.u_max) {
        return Err(Error::input(
            "state_controller.mpc.u_max",
            format!("the box [{}, {}] is empty", m.u_min, m.u_max),
        ));
    }
    if !(m.du_max > 0.0) {
        return Err(Error::input(
            "state_controller.mpc.du_max",
            format!("must be > 0, got {}", m.du_max),
        ));
    }
    if !(1..=u32::from(u16::MAX)).contains(&m.iterations) {
        return Err(Error::input(
            "state_controller.mpc.iterations",
            format!("{} is outside [1, 65535]", m.iterations),
        ));
    }
    Ok(())
}
