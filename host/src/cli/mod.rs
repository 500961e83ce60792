//! The `ferrosid` command line. Each subcommand lives in its own module and exposes
//! `pub struct Args` (clap `Args`) and `pub fn run(args: &Args) -> Result<ExitCode, Error>`.
//!
//! Exit codes (documented in `ferrosid --help` and README.md):
//! * 0 — success (and, for commands that check receipts, every receipt passed);
//! * 1 — the command ran but a check failed (a receipt, a gate, a verdict the caller asked to enforce);
//! * 2 — usage error (bad flags; produced by clap);
//! * 3 — input data error (unreadable or invalid log, named with file and line);
//! * 4 — numerical failure (ill-conditioned or unstable fit that could not be trusted).
use crate::Error;
use clap::{Parser, Subcommand};

pub mod codegen;
pub mod fleet;
pub mod frf;
pub mod gap;
pub mod identify;
pub mod output;
pub mod reidentify;
pub mod run;

/// Exit status of a command that ran to completion.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitCode {
    /// Everything passed.
    Ok = 0,
    /// A check (receipt, gate) failed.
    CheckFailed = 1,
}

/// Top-level parser.
#[derive(Debug, Parser)]
#[command(
    name = "ferrosid",
    version,
    about = "System identification with receipts: from raw logs to a verified plant model",
    after_help = "Exit codes: 0 success, 1 a check/receipt failed, 2 usage error, \
                  3 input data error, 4 numerical failure."
)]
pub struct Cli {
    /// The command to run.
    #[command(subcommand)]
    pub command: Command,
}

/// All subcommands. Each variant wraps its module's `Args`.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Sim-to-real gap diagnosis: where a nominal model and the plant disagree, which effect
    /// explains it, and how far the gap shrinks once it is added.
    Gap(gap::Args),
    /// Empirical frequency response (Welch H1 or period-synchronous) with coherence gating.
    Frf(frf::Args),
    /// N4SID state-space model with order selection, validation and a model file.
    Identify(identify::Args),
    /// C header and no_std Rust module of a model, PID, W_m and power-up check settings.
    Codegen(codegen::Args),
    /// Re-identify a model from the spectra frame a target emitted at power-up.
    Reidentify(reidentify::Args),
    /// The whole chain from raw logs to receipts, driven by a PIPELINE.toml: model, receipts,
    /// HTML report; exits 1 when a receipt fails.
    Run(run::Args),
    /// The pipeline on every unit of a fleet directory in parallel, with parameter
    /// distributions across serial numbers.
    Fleet(fleet::Args),
}

pub use crate::ops::{check_flag, num};

/// `msg` with every decimal number of more than 24 digits (a huge or tiny f64 printed with
/// `{}`: "1000…000" or "0.000…001") rewritten in scientific notation, so no message carries a
/// 300-digit number whatever the value a user passed.
pub fn tidy_numbers(msg: &str) -> String {
    let b = msg.as_bytes();
    let mut out = String::with_capacity(msg.len());
    let mut i = 0;
    while i < b.len() {
        let start_ok = i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
        if start_ok && b[i].is_ascii_digit() {
            let mut j = i;
            while j < b.len() && (b[j].is_ascii_digit() || b[j] == b'.') {
                j += 1;
            }
            let tok = &msg[i..j];
            let digits = tok.bytes().filter(u8::is_ascii_digit).count();
            if digits > 24 {
                if let Ok(v) = tok.trim_end_matches('.').parse::<f64>() {
                    out.push_str(&format!("{v:e}"));
                    i = j;
                    continue;
                }
            }
            out.push_str(tok);
            i = j;
            continue;
        }
        let ch = msg[i..].chars().next().unwrap_or(' ');
        out.push(ch);
        i += ch.len_utf8();
    }
    out
}

/// True when `bytes` is a model file exactly as ferrosid prints one (`identify --out`,
/// `reidentify --out`): parsed and printed again, it gives the same bytes. A hand-written or
/// edited model, or any other file, is not.
pub fn own_model_file(bytes: &[u8]) -> bool {
    match serde_json::from_slice::<crate::lti::StateSpaceData>(bytes) {
        Ok(m) => output::json_string(&m).is_ok_and(|t| t.as_bytes() == bytes),
        Err(_) => false,
    }
}

/// Maps an error to the documented process exit code.
pub fn exit_code_for(err: &Error) -> i32 {
    match err {
        Error::Io { .. } | Error::Parse { .. } | Error::MatVar { .. } | Error::Data { .. } => 3,
        Error::InvalidArgument(_) => 2,
        Error::Numerical(_) => 4,
    }
}

/// Runs the parsed command line.
pub fn run(cli: &Cli) -> Result<ExitCode, Error> {
    match &cli.command {
        Command::Gap(a) => gap::run(a),
        Command::Frf(a) => frf::run(a),
        Command::Identify(a) => identify::run(a),
        Command::Codegen(a) => codegen::run(a),
        Command::Reidentify(a) => reidentify::run(a),
        Command::Run(a) => run::run(a),
        Command::Fleet(a) => fleet::run(a),
    }
}
