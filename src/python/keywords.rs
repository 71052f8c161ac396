//! Keyword-only settings grouped into typed structs.
//!
//! A binding with many keyword-only settings takes them as `**kwargs` and reads them
//! into structs declared with [`keywords!`]: each field has its type and its default,
//! and a name no group knows raises the `TypeError` Python raises for an unexpected
//! keyword argument. The binding's `text_signature` lists the names with their
//! defaults, so `inspect.signature`, `help` and the stub test (`mypy.stubtest`) see
//! the signature a user calls.

use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Declares a struct of keyword arguments: `name: Type = default` per field. The
/// struct gets `Default` (every field's default), `NAMES` (its keyword names),
/// `take(kwargs)` (the fields given in `kwargs`, the defaults for the others; names of
/// other groups are left to [`check_names`]) and `parse(function, kwargs)` (`take`
/// where the group holds all of `function`'s keywords). A struct with a `'py`
/// lifetime may hold Python objects.
macro_rules! keywords {
    (
        $(#[$meta:meta])*
        struct $name:ident<$py:lifetime> {
            $($(#[$fmeta:meta])* $field:ident: $ty:ty = $default:expr),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        pub(crate) struct $name<$py> {
            $($(#[$fmeta])* pub $field: $ty,)+
        }
        impl<$py> Default for $name<$py> {
            fn default() -> Self {
                Self { $($field: $default,)+ }
            }
        }
        impl<$py> $name<$py> {
            $crate::python::keywords::keywords!(@take [] $py, $($field),+);
        }
    };
    (
        $(#[$meta:meta])*
        struct $name:ident {
            $($(#[$fmeta:meta])* $field:ident: $ty:ty = $default:expr),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        pub(crate) struct $name {
            $($(#[$fmeta])* pub $field: $ty,)+
        }
        impl Default for $name {
            fn default() -> Self {
                Self { $($field: $default,)+ }
            }
        }
        impl $name {
            $crate::python::keywords::keywords!(@take ['py] 'py, $($field),+);
        }
    };
    (@take [$($generic:lifetime)?] $py:lifetime, $($field:ident),+) => {
        /// The keyword names of this group.
        pub const NAMES: &'static [&'static str] = &[$(stringify!($field)),+];

        /// The fields given in `kwargs`, the defaults for the others.
        pub fn take<$($generic)?>(
            kwargs: Option<&pyo3::Bound<$py, pyo3::types::PyDict>>,
        ) -> pyo3::PyResult<Self> {
            use pyo3::types::PyDictMethods;
            let mut out = Self::default();
            if let Some(kwargs) = kwargs {
                $(
                    if let Some(value) = kwargs.get_item(stringify!($field))? {
                        out.$field = pyo3::types::PyAnyMethods::extract(&value)
                            .map_err(Into::<pyo3::PyErr>::into)?;
                    }
                )+
            }
            Ok(out)
        }

        /// [`Self::take`] where this group holds all the keywords `function` takes.
        pub fn parse<$($generic)?>(
            function: &str,
            kwargs: Option<&pyo3::Bound<$py, pyo3::types::PyDict>>,
        ) -> pyo3::PyResult<Self> {
            $crate::python::keywords::check_names(function, kwargs, &[Self::NAMES])?;
            Self::take(kwargs)
        }
    };
}
pub(crate) use keywords;

/// Refuses a keyword in `kwargs` that none of `groups` (each a struct's `NAMES`)
/// knows, as Python does: `TypeError: function() got an unexpected keyword argument
/// 'name'`.
pub(crate) fn check_names(
    function: &str,
    kwargs: Option<&Bound<'_, PyDict>>,
    groups: &[&[&str]],
) -> PyResult<()> {
    let Some(kwargs) = kwargs else {
        return Ok(());
    };
    for key in kwargs.keys() {
        let key: String = key.extract()?;
        if !groups.iter().any(|g| g.contains(&key.as_str())) {
            return Err(PyTypeError::new_err(format!(
                "{function}() got an unexpected keyword argument '{key}'"
            )));
        }
    }
    Ok(())
}
