//! Ratios that may be undefined (0 / 0 is not a number, as in py-motmetrics): JSON has no NaN,
//! so they are written as `null`.

/// Serializes a finite ratio as a number and anything else as `null`.
pub fn serialize_ratio<S: serde::Serializer>(value: &f64, serializer: S) -> Result<S::Ok, S::Error> {
    if value.is_finite() { serializer.serialize_f64(*value) } else { serializer.serialize_none() }
}

/// Serializes each ratio of a list as [`serialize_ratio`] does.
pub fn serialize_ratios<S: serde::Serializer>(values: &[f64], serializer: S) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeSeq;
    let mut seq = serializer.serialize_seq(Some(values.len()))?;
    for v in values {
        seq.serialize_element(&v.is_finite().then_some(*v))?;
    }
    seq.end()
}
