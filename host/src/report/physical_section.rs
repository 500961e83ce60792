//! The report's "Physical parameters" section (`physical.html`): the grey-box fit of the
//! `[physical]` structure ([`crate::pipeline::physical_stage`]) — each parameter with its
//! unit, value, interval and status (estimated from the data, known because given, or
//! undetermined by the data).
use super::{append, filters};
use crate::error::Result;
use crate::greybox::ParameterStatus;
use crate::pipeline::physical_stage::PhysicalOutcome;
use askama::Template;

#[derive(Template)]
#[template(path = "report/physical.html")]
struct Physical<'a> {
    physical: &'a PhysicalOutcome,
}

/// Writes the section (a note when the pipeline file has no `[physical]` section).
pub(crate) fn render(h: &mut String, physical: &PhysicalOutcome) -> Result<()> {
    append(h, &Physical { physical })
}
