//! The state-space controller block of the template context (`c.sk`): A, B, C, D of a
//! [`StateController`] as C and Rust literals (B as a column, C as a row), validated as a
//! discrete SISO controller at the model's sample time; or, for an MPC, its QP data (`c.mpc`).
use serde::Serialize;

use crate::context::{lit, mat_lit, Lit, MatLit};
use crate::error::{Error, Result};
use crate::input::{check_f32, MpcController, StateController};
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
}

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
        });
    };
    let dims = k.matrices.validate("state_controller")?;
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
    Ok(SkLit {
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
