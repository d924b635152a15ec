//! CSV through `serde`: each file's rows are a `Serialize` record type, written by
//! [`to_bytes`] (or, with columns only known at run time, [`to_bytes_with`]). The helpers keep
//! the columns as halftrace always wrote them: numbers in Rust's `Display` form (`1` for 1.0,
//! where `csv` would write `1.0`), fixed decimals where a column has them.

use serde::{Serialize, Serializer};
use std::fmt::Display;

/// A value in its `Display` form.
pub fn display<T: Display, S: Serializer>(v: &T, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(v)
}

/// `Some` value in its `Display` form, `None` empty.
pub fn opt_display<T: Display, S: Serializer>(v: &Option<T>, s: S) -> Result<S::Ok, S::Error> {
    match v {
        Some(v) => s.collect_str(v),
        None => s.serialize_str(""),
    }
}

/// A number with `D` decimals.
pub fn fixed<const D: usize, S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&format!("{v:.D$}"))
}

/// `Some` number with `D` decimals, `None` empty.
pub fn opt_fixed<const D: usize, S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
    match v {
        Some(v) => fixed::<D, S>(v, s),
        None => s.serialize_str(""),
    }
}

/// A CSV file of `records` (a header from the record type's field names).
pub fn to_bytes<R: Serialize>(records: impl IntoIterator<Item = R>) -> anyhow::Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in records {
        w.serialize(r)?;
    }
    w.into_inner().map_err(|e| anyhow::anyhow!("{e}"))
}

/// A CSV file of `header`, then `records` each followed by its `extra` cells (columns that
/// only the rows decide, such as the drivers' own statistics).
pub fn to_bytes_with<R: Serialize>(
    header: &[String],
    records: impl IntoIterator<Item = (R, Vec<String>)>,
) -> anyhow::Result<Vec<u8>> {
    let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(Vec::new());
    w.write_record(header)?;
    for r in records {
        w.serialize(r)?;
    }
    w.into_inner().map_err(|e| anyhow::anyhow!("{e}"))
}

/// The header a record type gives (its field names, renames applied), from one record.
pub fn header_of<R: Serialize>(record: R) -> Vec<String> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let _ = w.serialize(record);
    let bytes = w.into_inner().unwrap_or_default();
    let text = String::from_utf8_lossy(&bytes);
    let mut r = csv::ReaderBuilder::new().has_headers(false).from_reader(text.as_bytes());
    r.records().next().and_then(Result::ok).map(|h| h.iter().map(String::from).collect()).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize)]
    struct R {
        #[serde(rename = "B")]
        b: usize,
        #[serde(serialize_with = "display")]
        x: f64,
        #[serde(serialize_with = "opt_display")]
        y: Option<f64>,
        #[serde(serialize_with = "fixed::<3, _>")]
        s: f64,
    }

    #[test]
    fn columns_keep_their_display_form() {
        let rows = [R { b: 4, x: 1.0, y: None, s: 0.12345 }, R { b: 8, x: 0.5, y: Some(2.0), s: 3.0 }];
        let text = String::from_utf8(to_bytes(rows.iter()).unwrap()).unwrap();
        assert_eq!(text, "B,x,y,s\n4,1,,0.123\n8,0.5,2,3.000\n");
        let mut header = header_of(&rows[0]);
        header.push("stat: a,b".into());
        let with = to_bytes_with(&header, [(&rows[0], vec!["7".to_string()])]).unwrap();
        assert_eq!(String::from_utf8(with).unwrap(), "B,x,y,s,\"stat: a,b\"\n4,1,,0.123,7\n");
        assert_eq!(header_of(&rows[0]), ["B", "x", "y", "s"]);
    }
}
