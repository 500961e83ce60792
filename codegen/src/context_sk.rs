//! The state-space controller block of the template context (`c.sk`): A, B, C, D of a
//! [`StateController`] as C and Rust literals (B as a column, C as a row), validated as a
//! discrete SISO controller at the model's sample time.
use serde::Serialize;

use crate::context::{lit, mat_lit, Lit, MatLit};
use crate::error::{Error, Result};
use crate::input::StateController;
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

/// Validates and renders `sk` for a model sampled at `ts` s.
pub(crate) fn sk_lit(sk: Option<&StateController>, ts: f64) -> Result<SkLit> {
    let Some(k) = sk else {
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
