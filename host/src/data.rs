//! In-memory measured logs: uniformly sampled input and output channels.
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// One named, uniformly sampled signal.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// Column or variable name it came from.
    pub name: String,
    /// Samples, in the signal's physical units.
    pub data: Vec<f64>,
}

/// One experiment: input and output channels sharing one sample time.
///
/// Invariants (established by the readers in [`crate::io`]): every channel has the same length
/// `len() >= 1`, all samples are finite, `ts > 0`.
#[derive(Debug, Clone, PartialEq)]
pub struct Log {
    /// Where it came from (file path); used in every error and report.
    pub path: PathBuf,
    /// Sample time in seconds.
    pub ts: f64,
    /// Input channels (u), at least one.
    pub inputs: Vec<Channel>,
    /// Output channels (y), at least one.
    pub outputs: Vec<Channel>,
    /// Non-fatal findings made while reading (e.g. suspected clipping), human-readable.
    pub warnings: Vec<String>,
}

impl Log {
    /// A single-input single-output log with channels named `u` and `y`, no warnings (the
    /// caller guarantees the [`Log`] invariants: equal lengths, finite samples, `ts > 0`).
    pub fn siso(path: impl Into<PathBuf>, ts: f64, u: Vec<f64>, y: Vec<f64>) -> Log {
        Log {
            path: path.into(),
            ts,
            inputs: vec![Channel {
                name: "u".into(),
                data: u,
            }],
            outputs: vec![Channel {
                name: "y".into(),
                data: y,
            }],
            warnings: Vec::new(),
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.inputs.first().map_or(0, |c| c.data.len())
    }
    /// True when the log holds no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Sample rate in Hz.
    pub fn fs(&self) -> f64 {
        1.0 / self.ts
    }
    /// First input channel's samples (SISO convenience).
    pub fn u(&self) -> &[f64] {
        &self.inputs[0].data
    }
    /// First output channel's samples (SISO convenience).
    pub fn y(&self) -> &[f64] {
        &self.outputs[0].data
    }
}

/// Operating point and preprocessing of an identified model (see [`crate::operating_point`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OperatingPoint {
    /// Input values the model's input is a deviation from, one per input (log units).
    pub u0: Vec<f64>,
    /// Output values the model's output is a deviation from, one per output (log units).
    pub y0: Vec<f64>,
    /// Offset removal applied before identification: `mean`, `trend` or `none`.
    pub detrend: String,
    /// Decimation factor applied after offset removal (1 = none).
    pub decimation: usize,
    /// Sample rate of the raw logs before decimation, Hz.
    pub fs_raw_hz: f64,
}

impl OperatingPoint {
    /// `u0` for input `j` (0 when no offset was removed).
    pub fn input_offset(&self, j: usize) -> f64 {
        self.u0.get(j).copied().unwrap_or(0.0)
    }

    /// `y0` for output `i` (0 when no offset was removed).
    pub fn output_offset(&self, i: usize) -> f64 {
        self.y0.get(i).copied().unwrap_or(0.0)
    }

    /// `true` when any input or output offset is non-zero.
    pub fn has_offsets(&self) -> bool {
        self.u0.iter().chain(&self.y0).any(|v| *v != 0.0)
    }
}
