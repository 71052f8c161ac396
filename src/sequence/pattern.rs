//! Glob patterns of frame files inside a folder, as Python's `pathlib.Path.glob`
//! reads them: components separated by `/`, each matched against names with `*` (any
//! run of characters), `?` (one character) and `[...]` (one character of a set,
//! ranges `a-z`, `[!...]` for its complement); a component `**` matches any number of
//! folders, none included.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// The paths inside `dir` whose path relative to it matches `pattern`, sorted, each
/// once.
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
    let parts: Vec<&str> = pattern.split('/').filter(|p| !p.is_empty()).collect();
    let mut out = Vec::new();
    walk(dir, &parts, &mut out);
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

/// Adds to `out` the paths under `dir` that the components `parts` match.
fn walk(dir: &Path, parts: &[&str], out: &mut Vec<PathBuf>) {
    let Some((&first, rest)) = parts.split_first() else {
        out.push(dir.to_path_buf());
        return;
    };
    if first == "**" {
        walk(dir, rest, out);
        for sub in entries(dir).into_iter().filter(|p| p.is_dir()) {
            walk(&sub, parts, out);
        }
        return;
    }
    for path in entries(dir) {
        let name: Vec<char> = path
            .file_name()
            .map(|n| n.to_string_lossy().chars().collect())
            .unwrap_or_default();
        let chars: Vec<char> = first.chars().collect();
        if matches(&chars, &name) && (rest.is_empty() || path.is_dir()) {
            walk(&path, rest, out);
        }
    }
}

/// The entries of `dir` (none when it cannot be listed, as `glob` skips it).
fn entries(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .map(|it| it.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default()
}

/// Whether the name `name` matches the one-component pattern `pat`.
fn matches(pat: &[char], name: &[char]) -> bool {
    let Some((&p, pat_rest)) = pat.split_first() else {
        return name.is_empty();
    };
    match p {
        '*' => (0..=name.len()).any(|k| matches(pat_rest, &name[k..])),
        '?' => !name.is_empty() && matches(pat_rest, &name[1..]),
        '[' => match (class(pat_rest), name.split_first()) {
            (Some((set, negated, after)), Some((&c, name_rest))) => {
                in_set(set, c) != negated && matches(&pat_rest[after..], name_rest)
            }
            (Some(_), None) => false,
            // An unclosed `[` is itself.
            (None, _) => name.first() == Some(&'[') && matches(pat_rest, &name[1..]),
        },
        c => name.first() == Some(&c) && matches(pat_rest, &name[1..]),
    }
}

/// The character set that starts `pat` (just after its `[`): its characters and
/// ranges, whether it is negated (`!`), and how many characters of `pat` it takes
/// with its `]`; `None` when no `]` closes it (a `]` first in the set is one of its
/// characters).
fn class(pat: &[char]) -> Option<(&[char], bool, usize)> {
    let negated = pat.first() == Some(&'!');
    let start = usize::from(negated);
    let from = start + usize::from(pat.get(start) == Some(&']'));
    let end = from + pat.get(from..)?.iter().position(|&c| c == ']')?;
    Some((&pat[start..end], negated, end + 1))
}

/// Whether `c` is in the set `set` (characters and ranges `a-z`).
fn in_set(set: &[char], c: char) -> bool {
    let mut k = 0;
    while k < set.len() {
        if k + 2 < set.len() && set[k + 1] == '-' {
            if set[k] <= c && c <= set[k + 2] {
                return true;
            }
            k += 3;
        } else {
            if set[k] == c {
                return true;
            }
            k += 1;
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(pat: &str, name: &str) -> bool {
        let p: Vec<char> = pat.chars().collect();
        let n: Vec<char> = name.chars().collect();
        matches(&p, &n)
    }

    #[test]
    fn names_match_as_fnmatch_matches_them() {
        assert!(m("*.png", "f001.png") && !m("*.png", "f001.png.txt"));
        assert!(m("f?0*", "f00") && !m("f?", "f"));
        assert!(m("f[0-2].png", "f1.png") && !m("f[0-2].png", "f3.png"));
        assert!(m("f[!0-2].png", "f3.png") && !m("f[!0-2].png", "f1.png"));
        assert!(m("[]a]", "]") && m("[]a]", "a") && !m("[]a]", "b"));
        assert!(m("a[b", "a[b") && !m("a[b", "ab"));
        assert!(m("*", "") && m("**", "abc") && !m("", "a"));
        assert_eq!(quoted("f*.png"), "'f*.png'");
        assert_eq!(quoted("it's"), "\"it's\"");
    }

    #[test]
    fn patterns_walk_folders() {
        let dir = crate::io::tests::temp_dir("seq-glob");
        std::fs::create_dir_all(dir.join("a/b")).unwrap();
        for f in ["x.png", "a/y.png", "a/b/z.png", "a/b/w.txt"] {
            std::fs::write(dir.join(f), b"").unwrap();
        }
        let names = |pattern: &str| -> Vec<String> {
            glob(&dir, pattern)
                .unwrap()
                .iter()
                .map(|p| p.strip_prefix(&dir).unwrap().to_string_lossy().into_owned())
                .collect()
        };
        assert_eq!(names("*.png"), ["x.png"]);
        assert_eq!(names("a/*.png"), ["a/y.png"]);
        assert_eq!(names("**/*.png"), ["a/b/z.png", "a/y.png", "x.png"]);
        assert_eq!(names("*/b/*"), ["a/b/w.txt", "a/b/z.png"]);
        assert!(glob(&dir, "").is_err() && glob(&dir, "/x").is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
