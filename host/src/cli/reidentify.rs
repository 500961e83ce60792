//! `ferrosid reidentify`: read the spectra frame a target emitted after its power-up
//! self-identification ([`crate::target_frame`]) and re-identify a discrete model from it
//! ([`crate::rational_fit`], Sanathanan–Koerner fit of H1 = S_uy/S_uu on the gated, excited
//! bins).
//!
//! The model is written as JSON `{"ts","a","b","c","d"}` (`--out`), the same form `ferrosid
//! identify` writes, so it can go straight back into `ferrosid codegen`.
//!
//! Exit status: 0 fit done; 3 unreadable or malformed frame (file and line named); 4 the fit
//! failed (rank deficient, unstable, or too few gated bins).
//!
//! Examples:
//! ```text
//! ferrosid reidentify target.log --out drifted.json
//! ferrosid reidentify target.log --na 2 --nb 1 --max-delay 8 --json
//! ```
use super::ExitCode;
use crate::error::{Error, Result};
use crate::io::file_safety::{check_output_file, refuse_input_overwrite, write_atomic, Own};
use crate::lti::StateSpaceData;
use crate::rational_fit::{fit_discrete_rational_delay_search, RationalFit, RationalFitOptions};
use crate::target_frame::{FrfPoints, TargetFrame};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Flags of `ferrosid reidentify`.
#[derive(Debug, Clone, clap::Args)]
#[command(
    after_help = "Examples:\n  ferrosid reidentify target.log --out drifted.json\n  \
    ferrosid reidentify target.log --na 2 --nb 1 --max-delay 8 --json\n\n\
    Exit codes: 0 fit done, 2 usage error, 3 unreadable or malformed frame (file and line named), \
    4 the fit failed (rank deficient, unstable, or too few gated bins)."
)]
pub struct Args {
    /// Decoded target log holding FRAME_BEGIN / FRAME / FRAME_END lines.
    pub frame: PathBuf,
    /// Denominator order, 1..=40.
    #[arg(long, default_value_t = 2)]
    pub na: usize,
    /// Numerator order (nb + 1 coefficients), 0..=40.
    #[arg(long, default_value_t = 1)]
    pub nb: usize,
    /// Smallest input delay tried, samples, 0..=512 (1 for a ZOH plant without feedthrough).
    #[arg(long, default_value_t = 1)]
    pub min_delay: usize,
    /// Largest input delay tried, samples, up to 512 (the best-fitting delay is kept).
    #[arg(long, default_value_t = 1)]
    pub max_delay: usize,
    /// Coherence gate (default: the target's own gate, else 0.9).
    #[arg(long)]
    pub gate: Option<f64>,
    /// Bins whose S_uu is below this fraction of the largest are not used (not excited).
    #[arg(long, default_value_t = 1e-6)]
    pub min_rel_suu: f64,
    /// Write the model JSON here.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Replace an existing --out file even when ferrosid did not write it.
    #[arg(long)]
    pub force: bool,
    /// Print a JSON report on stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Frame, selected points and fit of one re-identification.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Reidentification {
    /// Coherence gate applied.
    pub gate: f64,
    /// Points used.
    pub points: FrfPoints,
    /// The fit.
    pub fit: RationalFit,
    /// The fitted model as state space (row-major JSON form).
    pub model: StateSpaceData,
}

/// Re-identifies a model from `frame` (library entry point of the command).
///
/// # Errors
/// [`Error::Data`] when fewer bins pass the gate than the orders need; fit errors from
/// [`crate::rational_fit`].
pub fn reidentify(
    frame: &TargetFrame,
    opts: &RationalFitOptions,
    delays: std::ops::RangeInclusive<usize>,
    gate: Option<f64>,
    min_rel_suu: f64,
) -> Result<Reidentification> {
    if let Some(g) = gate {
        if !(g.is_finite() && (0.0..=1.0).contains(&g)) {
            return Err(Error::InvalidArgument(format!(
                "--gate must be a coherence in [0, 1], got {g}"
            )));
        }
    }
    let gate = gate.or(frame.gate).unwrap_or(0.9);
    if !(gate.is_finite() && (0.0..=1.0).contains(&gate)) {
        return Err(Error::Data {
            file: frame.source.clone(),
            msg: format!(
                "the frame header's gate = {gate} is not a coherence in [0, 1]; override it \
                 with --gate"
            ),
        });
    }
    let points = frame.gated_h1(gate, min_rel_suu);
    let need = (opts.na + opts.nb + 1).div_ceil(2) + 1;
    if points.h.len() < need {
        return Err(Error::Data {
            file: frame.source.clone(),
            msg: format!(
                "only {} bins pass the coherence gate {gate} and carry excitation; the fit \
                 (na = {}, nb = {}) needs at least {need}",
                points.h.len(),
                opts.na,
                opts.nb
            ),
        });
    }
    let fit = fit_discrete_rational_delay_search(
        &points.freq_hz,
        &points.h,
        None,
        frame.ts(),
        opts,
        delays,
    )?;
    let model = StateSpaceData::from(&fit.state_space()?);
    Ok(Reidentification {
        gate,
        points,
        fit,
        model,
    })
}

/// Runs `ferrosid reidentify`.
pub fn run(args: &Args) -> Result<ExitCode> {
    use crate::rational_fit::{MAX_DELAY, MAX_ORDER};
    if !(1..=MAX_ORDER).contains(&args.na) {
        return Err(Error::InvalidArgument(format!(
            "--na must be in 1..={MAX_ORDER}, got {}",
            args.na
        )));
    }
    if args.nb > MAX_ORDER {
        return Err(Error::InvalidArgument(format!(
            "--nb must be in 0..={MAX_ORDER}, got {}",
            args.nb
        )));
    }
    for (flag, v) in [
        ("--min-delay", args.min_delay),
        ("--max-delay", args.max_delay),
    ] {
        if v > MAX_DELAY {
            return Err(Error::InvalidArgument(format!(
                "{flag} must be in 0..={MAX_DELAY} samples, got {v}"
            )));
        }
    }
    if let Some(g) = args.gate {
        if !(g.is_finite() && (0.0..=1.0).contains(&g)) {
            return Err(Error::InvalidArgument(format!(
                "--gate must be a coherence in [0, 1], got {g}"
            )));
        }
    }
    if !(args.min_rel_suu.is_finite() && (0.0..1.0).contains(&args.min_rel_suu)) {
        return Err(Error::InvalidArgument(format!(
            "--min-rel-suu must be in [0, 1), got {}",
            args.min_rel_suu
        )));
    }
    if let Some(out) = &args.out {
        refuse_input_overwrite(out, "--out", &[args.frame.as_path()])?;
        check_output_file(
            out,
            "--out",
            Own::Content(super::own_model_file),
            args.force,
        )?;
    }
    if args.max_delay < args.min_delay {
        return Err(Error::InvalidArgument(format!(
            "--max-delay {} is below --min-delay {}",
            args.max_delay, args.min_delay
        )));
    }
    // Regular file, size cap, UTF-8 (io::input) before the frame parser reads it.
    crate::io::input::read_text(&args.frame)?;
    let frame = TargetFrame::read(&args.frame)?;
    let opts = RationalFitOptions::new(args.na, args.nb, args.min_delay);
    let r = reidentify(
        &frame,
        &opts,
        args.min_delay..=args.max_delay,
        args.gate,
        args.min_rel_suu,
    )?;
    if let Some(out) = &args.out {
        let text = serde_json::to_string_pretty(&r.model)
            .map_err(|e| Error::InvalidArgument(format!("model JSON: {e}")))?;
        write_atomic(out, (text + "\n").as_bytes())?;
    }
    if args.json {
        super::output::emit(&super::output::json_string(&r)?)?;
        return Ok(ExitCode::Ok);
    }
    let mut t = String::new();
    let _ = writeln!(
        t,
        "frame {}: fs {} Hz, N {}, {} averages, target verdict {}",
        args.frame.display(),
        frame.fs_hz,
        frame.n,
        frame.averages.map_or("?".into(), |a| a.to_string()),
        frame.verdict.as_deref().unwrap_or("(none)")
    );
    let _ = writeln!(
        t,
        "fit on {} bins ({:.3}..{:.3} Hz) with coherence >= {}: na {}, nb {}, delay {} samples",
        r.points.h.len(),
        r.points.freq_hz.first().copied().unwrap_or(0.0),
        r.points.freq_hz.last().copied().unwrap_or(0.0),
        super::num(r.gate),
        r.fit.options.na,
        r.fit.options.nb,
        r.fit.options.nk
    );
    let _ = writeln!(
        t,
        "relative error |H_fit - H1|/|H1|: rms {:.3e}, max {:.3e} ({} SK iterations{})",
        r.fit.rms_rel_error,
        r.fit.max_rel_error,
        r.fit.iterations,
        if r.fit.converged {
            ""
        } else {
            ", not converged"
        }
    );
    for p in &r.fit.poles {
        let z = num_complex::Complex64::new(p[0], p[1]);
        let s = z.ln() / frame.ts();
        let _ = writeln!(
            t,
            "pole z = {:.6}{:+.6}j  (|z| {:.6}; {:.3} Hz, damping {:.4})",
            p[0],
            p[1],
            z.norm(),
            s.norm() / (2.0 * std::f64::consts::PI),
            -s.re / s.norm()
        );
    }
    if let Some(out) = &args.out {
        let _ = writeln!(t, "model written to {}", out.display());
    }
    super::output::emit(&t)?;
    Ok(ExitCode::Ok)
}
