//! Numbers, flags, strings and paths, read lazily so that the error names the
//! argument, and short sequences of them.

use super::arrays::{f64_array, i64_array};
use super::{invalid, too_large, type_name, wrong_type, MAX_ARRAY_ELEMENTS};
use crate::error::brief;
use numpy::PyUntypedArray;
use pyo3::exceptions::PyOverflowError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyFloat};
use std::convert::Infallible;
use std::path::PathBuf;

/// What a scalar argument turned out to be.
#[derive(Clone, Debug)]
enum Scalar {
    Int(i128),
    /// An integer beyond i128 (its sign).
    HugeInt {
        negative: bool,
    },
    Float(f64),
    /// Not a number: the type's name.
    Other(String),
}

fn is_bool(obj: &Bound<PyAny>) -> bool {
    obj.is_instance_of::<PyBool>() || type_name(obj) == "bool" || type_name(obj) == "bool_"
}

fn scalar(obj: &Bound<PyAny>) -> Scalar {
    if is_bool(obj) {
        return Scalar::Other("bool".into());
    }
    // SAFETY: a valid object pointer; PyIndex_Check only reads its type.
    let index = unsafe { pyo3::ffi::PyIndex_Check(obj.as_ptr()) } != 0;
    if index {
        match obj.extract::<i128>() {
            Ok(v) => return Scalar::Int(v),
            Err(e) if e.is_instance_of::<PyOverflowError>(obj.py()) => {
                return Scalar::HugeInt {
                    negative: obj.lt(0).unwrap_or(false),
                }
            }
            Err(_) => {} // e.g. a 0-d float array: read as a float below
        }
    }
    if obj.is_instance_of::<PyFloat>() || obj.hasattr("__float__").unwrap_or(false) {
        if let Ok(v) = obj.extract::<f64>() {
            return Scalar::Float(v);
        }
    }
    Scalar::Other(type_name(obj))
}

fn huge(negative: bool) -> &'static str {
    if negative {
        "an integer below -2**127"
    } else {
        "an integer of 2**127 or more"
    }
}

/// An integer argument (Python `int`, numpy integer) of any size; see the methods for
/// the ranges.
#[derive(Clone, Debug)]
pub struct Int(Scalar);

impl Int {
    /// A default value.
    pub const fn new(v: i128) -> Self {
        Int(Scalar::Int(v))
    }

    /// The integer, or an error naming `name`.
    pub fn get(&self, name: &str) -> PyResult<i128> {
        match &self.0 {
            Scalar::Int(v) => Ok(*v),
            Scalar::HugeInt { negative } => Err(invalid(
                name,
                format!("got {}, far outside the range allowed", huge(*negative)),
            )),
            Scalar::Float(v) => Err(wrong_type(
                name,
                "an integer",
                &format!("float {}", brief(*v)),
            )),
            Scalar::Other(t) => Err(wrong_type(name, "an integer", t)),
        }
    }

    /// A value in `lo..=hi`.
    pub fn in_range(&self, lo: i128, hi: i128, name: &str) -> PyResult<i128> {
        match &self.0 {
            Scalar::HugeInt { negative } => Err(invalid(
                name,
                format!("must be an integer in {lo}..={hi}, got {}", huge(*negative)),
            )),
            _ => {
                let v = self.get(name)?;
                if (lo..=hi).contains(&v) {
                    Ok(v)
                } else {
                    Err(invalid(
                        name,
                        format!("must be an integer in {lo}..={hi}, got {v}"),
                    ))
                }
            }
        }
    }

    /// A non-negative integer (a count, a size, an index).
    pub fn count(&self, name: &str) -> PyResult<usize> {
        self.at_least(0, name)
    }

    /// An integer of at least `min`.
    pub fn at_least(&self, min: usize, name: &str) -> PyResult<usize> {
        let what = || format!("must be an integer >= {min}");
        match &self.0 {
            Scalar::HugeInt { negative } => Err(invalid(
                name,
                format!("{}, got {}", what(), huge(*negative)),
            )),
            _ => {
                let v = self.get(name)?;
                usize::try_from(v)
                    .ok()
                    .filter(|&u| u >= min)
                    .ok_or_else(|| invalid(name, format!("{}, got {v}", what())))
            }
        }
    }

    /// An RNG seed: an integer in 0..2**64.
    pub fn seed(&self, name: &str) -> PyResult<u64> {
        Ok(self.in_range(0, i128::from(u64::MAX), name)? as u64)
    }
}

/// A real-number argument (Python/numpy floats and integers).
#[derive(Clone, Debug)]
pub struct Real(Scalar);

impl Real {
    /// A default value.
    pub const fn new(v: f64) -> Self {
        Real(Scalar::Float(v))
    }

    /// The number as given (NaN and ±inf included: the callee checks its range).
    pub fn get(&self, name: &str) -> PyResult<f64> {
        match &self.0 {
            Scalar::Float(v) => Ok(*v),
            Scalar::Int(v) => Ok(*v as f64),
            Scalar::HugeInt { negative } => Err(invalid(
                name,
                format!("got {}, beyond any sensible value", huge(*negative)),
            )),
            Scalar::Other(t) => Err(wrong_type(name, "a number", t)),
        }
    }

    /// The number in single precision (as given: the callee checks its range; a value
    /// beyond the float32 range becomes ±inf).
    pub fn get_f32(&self, name: &str) -> PyResult<f32> {
        Ok(self.get(name)? as f32)
    }
}

/// A `bool` argument (Python or numpy bool; integers are refused).
#[derive(Clone, Debug)]
pub struct Flag(Result<bool, String>);

impl Flag {
    /// A default value.
    pub const fn new(v: bool) -> Self {
        Flag(Ok(v))
    }

    /// The flag, or an error naming `name`.
    pub fn get(&self, name: &str) -> PyResult<bool> {
        self.0
            .clone()
            .map_err(|t| wrong_type(name, "True or False", &t))
    }

    /// An optional flag (None: `None`), or an error naming `name`.
    pub fn optional(flag: Option<&Flag>, name: &str) -> PyResult<Option<bool>> {
        flag.map(|f| {
            f.0.clone()
                .map_err(|t| wrong_type(name, "True, False or None", &t))
        })
        .transpose()
    }
}

/// A `str` argument.
#[derive(Clone, Debug)]
pub struct Text(Result<String, String>);

impl Text {
    /// The string, or an error naming `name`.
    pub fn get(&self, name: &str) -> PyResult<&str> {
        match &self.0 {
            Ok(s) => Ok(s),
            Err(t) => Err(wrong_type(name, "a string", t)),
        }
    }
}

/// A file path argument (`str` or `os.PathLike`).
#[derive(Clone, Debug)]
pub struct PathArg(Result<PathBuf, String>);

impl PathArg {
    /// The path, or an error naming `name`.
    pub fn get(&self, name: &str) -> PyResult<PathBuf> {
        self.0
            .clone()
            .map_err(|t| wrong_type(name, "a path (str or os.PathLike)", &t))
    }
}

macro_rules! lazy_argument {
    ($ty:ident, |$obj:ident| $body:expr) => {
        impl<'a, 'py> FromPyObject<'a, 'py> for $ty {
            type Error = Infallible;
            fn extract(obj: pyo3::Borrowed<'a, 'py, PyAny>) -> Result<Self, Infallible> {
                let $obj: &Bound<'py, PyAny> = &obj;
                Ok($body)
            }
        }
    };
}

lazy_argument!(Int, |obj| Int(scalar(obj)));
lazy_argument!(Real, |obj| Real(scalar(obj)));
lazy_argument!(Flag, |obj| Flag(if is_bool(obj) {
    obj.is_truthy().map_err(|_| type_name(obj))
} else {
    Err(type_name(obj))
}));
lazy_argument!(Text, |obj| Text(
    obj.extract::<String>().map_err(|_| type_name(obj))
));
lazy_argument!(PathArg, |obj| PathArg(
    obj.extract::<PathBuf>().map_err(|_| type_name(obj))
));

/// A list of real numbers (any sequence of numbers, or a 1-D array).
pub fn reals(obj: &Bound<PyAny>, name: &str, len: Option<usize>) -> PyResult<Vec<f64>> {
    let values: Vec<f64> = if obj.cast::<PyUntypedArray>().is_ok() {
        f64_array(obj, name, Some(1), false)?.data
    } else {
        let Ok(seq) = obj.try_iter() else {
            return Err(wrong_type(name, "a sequence of numbers", &type_name(obj)));
        };
        let mut out = Vec::new();
        for (i, item) in seq.enumerate() {
            if i >= MAX_ARRAY_ELEMENTS {
                return Err(too_large(name, "too many values (MAX_ARRAY_ELEMENTS)"));
            }
            let item = item?;
            out.push(Real(scalar(&item)).get(&format!("{name}[{i}]"))?);
        }
        out
    };
    if let Some(n) = len {
        if values.len() != n {
            return Err(invalid(
                name,
                format!("needs {n} values, got {}", values.len()),
            ));
        }
    }
    Ok(values)
}

/// Exactly `N` integers from a tuple, list or other sequence (`what` describes it).
pub fn ints<const N: usize>(obj: &Bound<PyAny>, name: &str, what: &str) -> PyResult<[Int; N]> {
    let items: Vec<Int> = match obj.try_iter() {
        Ok(seq) if obj.cast::<pyo3::types::PyString>().is_err() => seq
            .take(N + 1)
            .map(|item| item.map(|i| Int(scalar(&i))))
            .collect::<PyResult<_>>()?,
        _ => return Err(wrong_type(name, what, &type_name(obj))),
    };
    let n = items.len();
    items.try_into().map_err(|_| {
        invalid(
            name,
            format!(
                "expected {what}, got {}",
                if n > N {
                    "more values".to_string()
                } else {
                    format!("{n} values")
                }
            ),
        )
    })
}

/// A list of non-negative integers (any sequence of integers, or a 1-D array).
pub fn counts(obj: &Bound<PyAny>, name: &str) -> PyResult<Vec<usize>> {
    if obj.cast::<PyUntypedArray>().is_ok() {
        let a = i64_array(obj, name, Some(1))?;
        return a
            .data
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                usize::try_from(v).map_err(|_| {
                    invalid(
                        name,
                        format!("must hold non-negative integers, got {v} at {i}"),
                    )
                })
            })
            .collect();
    }
    let Ok(seq) = obj.try_iter() else {
        return Err(wrong_type(name, "a sequence of integers", &type_name(obj)));
    };
    let mut out = Vec::new();
    for (i, item) in seq.enumerate() {
        if i >= MAX_ARRAY_ELEMENTS {
            return Err(too_large(name, "too many values (MAX_ARRAY_ELEMENTS)"));
        }
        out.push(Int(scalar(&item?)).count(&format!("{name}[{i}]"))?);
    }
    Ok(out)
}

/// A pixel connectivity argument: 4 or 8.
pub fn connectivity(value: &Int) -> PyResult<crate::cloud::Connectivity> {
    let n = value.get("connectivity")?;
    u32::try_from(n)
        .ok()
        .and_then(|n| crate::cloud::Connectivity::from_int(n).ok())
        .ok_or_else(|| invalid("connectivity", format!("must be 4 or 8, got {n}")))
}
