//! Filters of the report templates (askama looks them up as `filters::<name>` from the
//! module that defines a template).
use crate::pipeline::fmt_num;

/// A number a template can format: `f64` or a reference to one (askama passes either).
pub(crate) trait Number {
    /// The value.
    fn value(&self) -> f64;
}

impl Number for f64 {
    fn value(&self) -> f64 {
        *self
    }
}

impl<T: Number + ?Sized> Number for &T {
    fn value(&self) -> f64 {
        (**self).value()
    }
}

/// `{{ x|num }}`: a number as the report and receipts print it ([`fmt_num`]).
#[askama::filter_fn]
pub(crate) fn num<T: Number>(v: T, _: &dyn askama::Values) -> askama::Result<String> {
    Ok(fmt_num(v.value()))
}

/// `{{ x|with_unit(unit) }}`: a receipt number with its unit, the dimensionless unit "1" left
/// out ([`super::with_unit`]).
#[askama::filter_fn]
pub(crate) fn with_unit<T: Number, U: AsRef<str>>(
    v: T,
    _: &dyn askama::Values,
    unit: U,
) -> askama::Result<String> {
    Ok(super::with_unit(v.value(), unit.as_ref()))
}
