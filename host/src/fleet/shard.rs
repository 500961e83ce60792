//! Splitting a fleet across machines without Python: `ferrosid fleet DIR --shard K/N` runs the
//! K-th of N disjoint shards of the units (a batch scheduler's array job: Slurm
//! `--array=1-N`, a Kubernetes indexed Job), each writing its own summary, and
//! `ferrosid fleet merge` combines the shard summaries into the summary of the whole fleet.
//!
//! Units are dealt round-robin in serial-number order: unit i (0-based, sorted) belongs to
//! shard (i mod N) + 1, so shards differ in size by at most one unit and a run of similar
//! serial numbers (one production batch) is spread over all shards. A shard summary carries
//! [`ShardInfo`] (K, N and the number of units in the whole fleet); the merge checks that
//! every shard 1..=N is present exactly once, that the shards agree on the fleet (layout,
//! signal units, unit count) and that no serial number appears twice, then recomputes the
//! distributions and outliers from the units, exactly as an unsharded run does.
use super::{FleetSummary, UnitResult, FLEET_SCHEMA, FLEET_SUMMARY_FILE};
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Most shards a fleet may be split into.
pub const MAX_SHARDS: usize = 100_000;

/// The K-th of N shards (1 <= K <= N).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// K, 1-based.
    pub index: usize,
    /// N.
    pub count: usize,
}

impl Shard {
    /// Parses `K/N` (e.g. `3/8`; 1 <= K <= N <= [`MAX_SHARDS`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `--shard` and what is wrong.
    pub fn parse(s: &str) -> Result<Shard> {
        let bad = |why: &str| {
            Error::InvalidArgument(format!(
                "--shard {:?}: {why} (expected K/N with 1 <= K <= N <= {MAX_SHARDS}, e.g. 2/4)",
                crate::error::excerpt(s)
            ))
        };
        let (k, n) = s.split_once('/').ok_or_else(|| bad("no '/'"))?;
        let k: usize = k
            .trim()
            .parse()
            .map_err(|_| bad("K is not a whole number"))?;
        let n: usize = n
            .trim()
            .parse()
            .map_err(|_| bad("N is not a whole number"))?;
        if n == 0 || n > MAX_SHARDS {
            return Err(bad("N out of range"));
        }
        if k == 0 || k > n {
            return Err(bad("K out of range"));
        }
        Ok(Shard { index: k, count: n })
    }

    /// The serial numbers of this shard among all of them (sorted as given).
    pub fn select(&self, serials: &[String]) -> Vec<String> {
        serials
            .iter()
            .enumerate()
            .filter(|(i, _)| i % self.count == self.index - 1)
            .map(|(_, s)| s.clone())
            .collect()
    }

    /// The record of this shard in its summary, for a fleet of `units_total` units.
    pub fn info(&self, units_total: usize) -> ShardInfo {
        ShardInfo {
            index: self.index,
            count: self.count,
            units_total,
        }
    }
}

/// Which shard a summary covers (the `shard` field of a shard's `fleet.json`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShardInfo {
    /// K, 1-based.
    pub index: usize,
    /// N.
    pub count: usize,
    /// Units in the whole fleet (all shards).
    pub units_total: usize,
}

/// Reads a shard summary: a `fleet.json` file, or a directory holding one (a shard's `--out`).
///
/// # Errors
/// [`Error::Io`] for an unreadable file, [`Error::Data`] for a file that is not a fleet
/// summary (the message says what is wrong).
pub fn read_summary(path: &Path) -> Result<FleetSummary> {
    let file: PathBuf = if path.is_dir() {
        path.join(FLEET_SUMMARY_FILE)
    } else {
        path.to_path_buf()
    };
    let text = crate::io::input::read_json_text(&file)?;
    // serde_json's `float_roundtrip` (host/Cargo.toml) reads every number back to the f64
    // that was written: the merge equals the unsharded run bit for bit.
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| Error::Parse {
        file: file.clone(),
        line: e.line(),
        msg: format!("not JSON: {e}"),
    })?;
    let schema = v.get("schema").and_then(|s| s.as_str()).unwrap_or("");
    if schema != FLEET_SCHEMA {
        return Err(Error::Data {
            file,
            msg: format!(
                "not a fleet summary: schema {:?}, expected {FLEET_SCHEMA:?} (the fleet.json \
                 of `ferrosid fleet --shard K/N --out DIR`)",
                crate::error::excerpt(schema)
            ),
        });
    }
    serde_json::from_value(v).map_err(|e| Error::Data {
        file,
        msg: format!("fleet summary with a missing or malformed field: {e}"),
    })
}

/// Combines the summaries of all N shards of one fleet (`paths[i]` names `shards[i]` in
/// errors) into the summary of the whole fleet, equal to the summary of an unsharded run.
///
/// # Errors
/// [`Error::Data`] naming the file when a summary is not a shard, belongs to another split or
/// fleet (N, layout, signal units or unit count differ), repeats a shard or a serial number,
/// or when shards are missing.
pub fn merge_summaries(paths: &[PathBuf], shards: Vec<FleetSummary>) -> Result<FleetSummary> {
    let data = |i: usize, msg: String| Error::Data {
        file: paths.get(i).cloned().unwrap_or_default(),
        msg,
    };
    let Some(first) = shards.first() else {
        return Err(Error::InvalidArgument(
            "fleet merge: no shard summaries given".into(),
        ));
    };
    let info0 = first.shard.ok_or_else(|| {
        data(
            0,
            "not a shard summary (no `shard` field): it already covers a whole fleet".into(),
        )
    })?;
    let mut seen: Vec<Option<usize>> = vec![None; info0.count];
    let mut units: Vec<UnitResult> = Vec::with_capacity(info0.units_total);
    for (i, s) in shards.iter().enumerate() {
        let info = s.shard.ok_or_else(|| {
            data(
                i,
                "not a shard summary (no `shard` field): it already covers a whole fleet".into(),
            )
        })?;
        if info.count != info0.count || info.units_total != info0.units_total {
            return Err(data(
                i,
                format!(
                    "shard {}/{} of a fleet of {} units does not belong with shard {}/{} of a \
                     fleet of {} units ({})",
                    info.index,
                    info.count,
                    info.units_total,
                    info0.index,
                    info0.count,
                    info0.units_total,
                    paths[0].display()
                ),
            ));
        }
        if s.layout != first.layout
            || s.output_unit != first.output_unit
            || s.input_unit != first.input_unit
        {
            return Err(data(
                i,
                format!(
                    "layout or signal units ({:?}, {}/{}) differ from {} ({:?}, {}/{}): not the \
                     same fleet",
                    s.layout,
                    s.output_unit,
                    s.input_unit,
                    paths[0].display(),
                    first.layout,
                    first.output_unit,
                    first.input_unit
                ),
            ));
        }
        let slot = &mut seen[info.index - 1];
        if let Some(j) = *slot {
            return Err(data(
                i,
                format!(
                    "shard {}/{} given twice (also {})",
                    info.index,
                    info.count,
                    paths[j].display()
                ),
            ));
        }
        *slot = Some(i);
        units.extend(s.units.iter().cloned());
    }
    let missing: Vec<String> = seen
        .iter()
        .enumerate()
        .filter(|(_, s)| s.is_none())
        .map(|(k, _)| format!("{}/{}", k + 1, info0.count))
        .collect();
    if !missing.is_empty() {
        return Err(data(
            0,
            format!("shards missing from the merge: {}", missing.join(", ")),
        ));
    }
    units.sort_by(|a, b| a.serial.cmp(&b.serial));
    if let Some(w) = units.windows(2).find(|w| w[0].serial == w[1].serial) {
        return Err(data(
            0,
            format!("unit {:?} appears in two shards", w[0].serial),
        ));
    }
    if units.len() != info0.units_total {
        return Err(data(
            0,
            format!(
                "the shards hold {} units, the fleet has {}",
                units.len(),
                info0.units_total
            ),
        ));
    }
    Ok(FleetSummary::new(
        first.layout,
        units,
        &first.output_unit,
        &first.input_unit,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_syntax_and_round_robin() {
        assert_eq!(Shard::parse("2/3").unwrap(), Shard { index: 2, count: 3 });
        for bad in ["0/3", "4/3", "1/0", "x/2", "2", "1/2/3", ""] {
            let e = Shard::parse(bad).unwrap_err().to_string();
            assert!(e.contains("--shard"), "{bad}: {e}");
        }
        let all: Vec<String> = (0..7).map(|i| format!("SN{i}")).collect();
        let parts: Vec<Vec<String>> = (1..=3)
            .map(|k| Shard { index: k, count: 3 }.select(&all))
            .collect();
        assert_eq!(parts[0], ["SN0", "SN3", "SN6"]);
        assert_eq!(parts[1], ["SN1", "SN4"]);
        assert_eq!(parts[2], ["SN2", "SN5"]);
        // More shards than units: the extra shards are empty.
        assert!(Shard { index: 9, count: 9 }.select(&all).is_empty());
    }
}
