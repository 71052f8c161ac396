//! The one error type of the crate. The Python bindings map each variant to a
//! `depthpose.DepthPoseError` subclass (all of them `ValueError`s); a missing file is
//! also a `FileNotFoundError` there.

use std::borrow::Cow;
use thiserror::Error;

/// Everything that can go wrong in depthpose.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum Error {
    /// An argument has the wrong shape, type, range or content. `name` is the argument.
    #[error("{name}: {message}")]
    InvalidArgument { name: String, message: String },
    /// A file is unreadable or not in the expected format.
    #[error("{path}: {message}")]
    File { path: String, message: String },
    /// A file (or folder) that does not exist.
    #[error("{path}: no such file")]
    NotFound { path: String },
    /// The input holds no usable body (no valid depth, empty foreground, ...).
    #[error("{0}")]
    NoBody(String),
    /// An input, or the result it asks for, exceeds one of depthpose's size limits;
    /// `name` is the argument, `message` names the limit.
    #[error("{name}: {message}")]
    ResourceLimit { name: String, message: String },
}

/// Shorthand used across the crate.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// An invalid argument, naming it. Long numbers in `message` are shortened (see
    /// [`brief_numbers`]).
    pub fn invalid(name: impl Into<String>, message: impl Into<String>) -> Self {
        Error::InvalidArgument {
            name: name.into(),
            message: brief_numbers(&message.into()).into_owned(),
        }
    }

    /// A problem with a file.
    pub fn file(path: impl Into<String>, message: impl Into<String>) -> Self {
        Error::File {
            path: path.into(),
            message: message.into(),
        }
    }

    /// A file that does not exist.
    pub fn not_found(path: impl Into<String>) -> Self {
        Error::NotFound { path: path.into() }
    }

    /// An argument beyond a size limit; `message` names the limit.
    pub fn resource_limit(name: impl Into<String>, message: impl Into<String>) -> Self {
        Error::ResourceLimit {
            name: name.into(),
            message: brief_numbers(&message.into()).into_owned(),
        }
    }
}

/// Fails with an `InvalidArgument` naming `name` unless `ok` holds.
pub fn ensure(ok: bool, name: &str, message: impl FnOnce() -> String) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(Error::invalid(name, message()))
    }
}

/// Fails unless `value` is finite and strictly positive.
pub fn ensure_positive(value: f64, name: &str) -> Result<()> {
    ensure(value.is_finite() && value > 0.0, name, || {
        format!("must be a finite positive number, got {}", brief(value))
    })
}

/// A number as a message prints it: the shortest decimal that reads back to `value`
/// (an `f32` as written, not widened), in exponent form when that is shorter than plain
/// digits (1e300, not 301 digits).
pub fn brief(value: impl std::fmt::Display + std::fmt::LowerExp) -> String {
    let plain = format!("{value}");
    let exp = format!("{value:e}");
    if plain.len() > exp.len() + 2 {
        exp
    } else {
        plain
    }
}

/// A string given by the user as a message quotes it: at most 40 characters.
pub fn brief_text(text: &str) -> String {
    let mut chars = text.chars();
    let head: String = chars.by_ref().take(40).collect();
    if chars.next().is_some() {
        format!("{head:?}... ({} characters)", text.chars().count())
    } else {
        format!("{head:?}")
    }
}

/// Digits in a row beyond which [`brief_numbers`] shortens a number (an i128 has at
/// most 39).
const LONG_NUMBER: usize = 40;

/// `message` with every number of more than 40 digits (a float such as 1e300 printed
/// in full) written in exponent form with four significant digits.
pub fn brief_numbers(message: &str) -> Cow<'_, str> {
    let bytes = message.as_bytes();
    let mut out = String::new();
    let mut copied = 0;
    let mut i = 0;
    while i < bytes.len() {
        if !bytes[i].is_ascii_digit() {
            i += 1;
            continue;
        }
        // A number: digits, optionally a fraction.
        let start = i;
        while i < bytes.len() && bytes[i].is_ascii_digit() {
            i += 1;
        }
        if i + 1 < bytes.len() && bytes[i] == b'.' && bytes[i + 1].is_ascii_digit() {
            i += 1;
            while i < bytes.len() && bytes[i].is_ascii_digit() {
                i += 1;
            }
        }
        let digits = message[start..i].bytes().filter(u8::is_ascii_digit).count();
        if digits > LONG_NUMBER {
            if let Ok(v) = message[start..i].parse::<f64>() {
                out.push_str(&message[copied..start]);
                out.push_str(&format!("{v:.3e}"));
                copied = i;
            }
        }
    }
    if copied == 0 {
        Cow::Borrowed(message)
    } else {
        out.push_str(&message[copied..]);
        Cow::Owned(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_print_briefly() {
        assert_eq!(brief(1e300), "1e300");
        assert_eq!(brief(5e-324), "5e-324");
        assert_eq!(brief(2.5), "2.5");
        assert_eq!(brief(-0.001), "-0.001");
        assert_eq!(brief(65536.0), "65536");
        assert_eq!(brief(f64::NAN), "NaN");
        let long = format!("got {} at 3", 1e300);
        assert_eq!(brief_numbers(&long), "got 1.000e300 at 3");
        let i128_max = "got 170141183460469231731687303715884105727";
        assert_eq!(brief_numbers(i128_max), i128_max);
        assert_eq!(brief_numbers(&format!("got {}", 2e40)), "got 2.000e40");
        assert!(matches!(brief_numbers("frame 12 of 300"), Cow::Borrowed(_)));
        assert_eq!(brief_text("ncc"), "\"ncc\"");
        assert!(brief_text(&"x".repeat(10_000)).len() < 70);
        let e = Error::invalid("x", format!("must be small, got {}", 1e308));
        assert!(e.to_string().len() < 40, "{e}");
    }
}
