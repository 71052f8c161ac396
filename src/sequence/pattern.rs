//! Glob patterns of frame files inside a folder, as Python's `pathlib.Path.glob`
//! reads them: components separated by `/`, each matched against names with `*` (any
//! run of characters), `?` (one character) and `[...]` (one character of a set,
//! ranges `a-z`, `[!...]` for its complement); a component `**` matches any number of
//! folders, none included. The matching is the `glob` crate's.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// The paths inside `dir` whose path relative to it matches `pattern`, sorted, each
/// once. Entries that cannot be read are skipped, as `pathlib` skips them.
pub fn glob(dir: &Path, pattern: &str) -> Result<Vec<PathBuf>> {
    if pattern.is_empty() || pattern.starts_with('/') {
        return Err(Error::invalid(
            "pattern",
            format!(
                "expected a glob relative to the folder, got {}",
                quoted(pattern)
            ),
        ));
    }
    let full = format!(
        "{}/{pattern}",
        glob::Pattern::escape(&dir.to_string_lossy())
    );
    let options = glob::MatchOptions {
        case_sensitive: true,
        require_literal_separator: true,
        // `pathlib` matches names starting with a dot too.
        require_literal_leading_dot: false,
    };
    let found = glob::glob_with(&full, options).map_err(|e| {
        Error::invalid(
            "pattern",
            format!("{} is not a glob pattern: {}", quoted(pattern), e.msg),
        )
    })?;
    let mut out: Vec<PathBuf> = found.filter_map(|p| p.ok()).collect();
    out.sort();
    out.dedup();
    Ok(out)
}

/// A pattern as Python's `repr` of a string quotes it.
pub fn quoted(pattern: &str) -> String {
    if pattern.contains('\'') && !pattern.contains('"') {
        format!("\"{pattern}\"")
    } else {
        format!("'{}'", pattern.replace('\'', "\\'"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_are_quoted_as_python_quotes_them() {
        assert_eq!(quoted("f*.png"), "'f*.png'");
        assert_eq!(quoted("it's"), "\"it's\"");
    }

    #[test]
    fn patterns_walk_folders() {
        let dir = crate::io::tests::temp_dir("seq-glob");
        std::fs::create_dir_all(dir.join("a/b")).unwrap();
        for f in [
            "x.png",
            "f1.png",
            "f3.png",
            "a/y.png",
            "a/b/z.png",
            "a/b/w.txt",
        ] {
            std::fs::write(dir.join(f), b"").unwrap();
        }
        let names = |pattern: &str| -> Vec<String> {
            glob(&dir, pattern)
                .unwrap()
                .iter()
                .map(|p| p.strip_prefix(&dir).unwrap().to_string_lossy().into_owned())
                .collect()
        };
        assert_eq!(names("*.png"), ["f1.png", "f3.png", "x.png"]);
        assert_eq!(names("f?.png"), ["f1.png", "f3.png"]);
        assert_eq!(names("f[0-2].png"), ["f1.png"]);
        assert_eq!(names("f[!0-2].png"), ["f3.png"]);
        assert_eq!(names("a/*.png"), ["a/y.png"]);
        assert_eq!(
            names("**/*.png"),
            ["a/b/z.png", "a/y.png", "f1.png", "f3.png", "x.png"]
        );
        assert_eq!(names("*/b/*"), ["a/b/w.txt", "a/b/z.png"]);
        assert!(glob(&dir, "").is_err() && glob(&dir, "/x").is_err());
        assert!(glob(&dir, "a[b").is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
