//! JSON lines: one JSON value a line, as `json.dumps` writes it (`", "` and `": "`
//! between items, non-ASCII characters escaped, NaN and infinities as `NaN`,
//! `Infinity` and `-Infinity`, which Python's and JavaScript's readers take).

use crate::error::{Error, Result};
use std::fmt::Write as _;
use std::path::Path;

/// A JSON value.
#[derive(Debug, Clone, PartialEq)]
pub enum Json {
    Null,
    Bool(bool),
    Int(i128),
    Number(f64),
    Text(String),
    List(Vec<Json>),
    /// Keys in order.
    Object(Vec<(String, Json)>),
}

impl Json {
    /// The value as one line of JSON.
    pub fn to_line(&self) -> String {
        let mut out = String::new();
        self.write(&mut out);
        out
    }

    fn write(&self, out: &mut String) {
        match self {
            Json::Null => out.push_str("null"),
            Json::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
            Json::Int(i) => {
                let _ = write!(out, "{i}");
            }
            Json::Number(x) => number(*x, out),
            Json::Text(s) => text(s, out),
            Json::List(items) => {
                out.push('[');
                for (k, item) in items.iter().enumerate() {
                    if k > 0 {
                        out.push_str(", ");
                    }
                    item.write(out);
                }
                out.push(']');
            }
            Json::Object(items) => {
                out.push('{');
                for (k, (key, item)) in items.iter().enumerate() {
                    if k > 0 {
                        out.push_str(", ");
                    }
                    text(key, out);
                    out.push_str(": ");
                    item.write(out);
                }
                out.push('}');
            }
        }
    }
}

/// A float as Python's `repr` writes it: the shortest digits that read back, with a
/// decimal point or an exponent (`1.0`, `1e-05`, `1e+300`).
fn number(x: f64, out: &mut String) {
    if x.is_nan() {
        out.push_str("NaN");
    } else if x.is_infinite() {
        out.push_str(if x > 0.0 { "Infinity" } else { "-Infinity" });
    } else if x != 0.0 && (x.abs() >= 1e16 || x.abs() < 1e-4) {
        let s = format!("{x:e}");
        let (mantissa, exp) = s.split_once('e').unwrap_or((&s, "0"));
        let (sign, digits) = exp.strip_prefix('-').map_or(("+", exp), |d| ("-", d));
        let _ = write!(out, "{mantissa}e{sign}{digits:0>2}");
    } else {
        let _ = write!(out, "{x:?}");
    }
}

/// A string in double quotes, escaped as `json.dumps` escapes it (ASCII only).
fn text(s: &str, out: &mut String) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            '\u{8}' => out.push_str("\\b"),
            '\u{c}' => out.push_str("\\f"),
            ' '..='~' => out.push(c),
            _ => {
                let mut units = [0u16; 2];
                for u in c.encode_utf16(&mut units) {
                    let _ = write!(out, "\\u{u:04x}");
                }
            }
        }
    }
    out.push('"');
}

/// Writes one line per record.
pub fn write_jsonl(path: &Path, records: &[Json]) -> Result<()> {
    let mut out = String::new();
    for r in records {
        r.write(&mut out);
        out.push('\n');
    }
    std::fs::write(path, out)
        .map_err(|e| Error::file(path.display().to_string(), format!("cannot write: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_what_json_dumps_writes() {
        let record = Json::Object(vec![
            ("frame".into(), Json::Int(0)),
            (
                "pose".into(),
                Json::List(vec![
                    Json::Number(0.1),
                    Json::Number(1e-5),
                    Json::Number(f64::NAN),
                    Json::Number(1.0),
                    Json::Number(-0.0),
                ]),
            ),
            ("s".into(), Json::Text("é\"x\n😀".into())),
            ("b".into(), Json::Bool(true)),
            ("n".into(), Json::Null),
            ("big".into(), Json::Number(1e300)),
            ("inf".into(), Json::Number(f64::NEG_INFINITY)),
        ]);
        assert_eq!(
            record.to_line(),
            "{\"frame\": 0, \"pose\": [0.1, 1e-05, NaN, 1.0, -0.0], \"s\": \
             \"\\u00e9\\\"x\\n\\ud83d\\ude00\", \"b\": true, \"n\": null, \"big\": 1e+300, \
             \"inf\": -Infinity}"
        );
        let mut s = String::new();
        number(1.5e16, &mut s);
        assert_eq!(s, "1.5e+16");
    }
}
