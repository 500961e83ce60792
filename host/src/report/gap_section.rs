//! The report's "Gap diagnosis" section (`gap.html`): what [`crate::pipeline::gap_stage`]
//! found — the verdict with its effects and shares, how far the gap shrinks against the noise
//! floor, and the full diagnosis as `ferrosid gap` prints it.
use super::{append, filters};
use crate::error::Result;
use crate::pipeline::gap_stage::GapStage;
use askama::Template;

#[derive(Template)]
#[template(path = "report/gap.html")]
struct Gap<'a> {
    stage: &'a GapStage,
}

/// Appends the section for `stage` to `h`.
pub(crate) fn render(h: &mut String, stage: &GapStage) -> Result<()> {
    append(h, &Gap { stage })
}
