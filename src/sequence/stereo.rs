//! The rectified stereo pairs of a folder, as `depthpose estimate-stereo` reads them:
//! either in subfolders `left/` and `right/` (the same file names; the empty scene
//! `background.png` in each) or side by side, each left image's name containing `left`
//! and its partner's the same name with `right` in its place (the empty scene
//! `left_bg.png` and `right_bg.png`).

use crate::error::{Error, Result};
use crate::io::path_str;
use std::path::{Path, PathBuf};

/// Suffixes of the images a folder's pairs are read from.
pub const IMAGE_SUFFIXES: [&str; 8] = [
    ".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm",
];

/// A left image and its right partner.
pub type Pair = (PathBuf, PathBuf);

/// The pairs of the folder `dir`, sorted by the left image's name, and its
/// empty-scene pair when both of its files exist: an error for a folder without pairs
/// or with a left image whose right partner is missing.
pub fn folder_pairs(dir: &Path) -> Result<(Vec<Pair>, Option<Pair>)> {
    let (left_dir, right_dir) = (dir.join("left"), dir.join("right"));
    let (pairs, bg): (Vec<Pair>, Pair) = if left_dir.is_dir() && right_dir.is_dir() {
        let pairs = images(&left_dir)?
            .into_iter()
            .filter(|f| stem(f) != "background")
            .filter_map(|f| {
                let right = right_dir.join(f.file_name()?);
                Some((f, right))
            })
            .collect();
        let bg = (
            left_dir.join("background.png"),
            right_dir.join("background.png"),
        );
        (pairs, bg)
    } else {
        let pairs = images(dir)?
            .into_iter()
            .filter(|f| {
                let stem = stem(f);
                stem.to_ascii_lowercase().contains("left") && stem != "left_bg"
            })
            .filter_map(|f| {
                let name = f.file_name()?.to_string_lossy().into_owned();
                // The last "left" of the name, in any case, becomes "right".
                let at = name.to_ascii_lowercase().rfind("left")?;
                let right = f.with_file_name(format!("{}right{}", &name[..at], &name[at + 4..]));
                Some((f, right))
            })
            .collect();
        (pairs, (dir.join("left_bg.png"), dir.join("right_bg.png")))
    };
    if pairs.is_empty() {
        return Err(Error::file(
            path_str(dir),
            "no stereo pairs inside (subfolders left/ and right/, or images named *left* \
             beside *right*)",
        ));
    }
    if let Some((_, r)) = pairs.iter().find(|(_, r)| !r.exists()) {
        let name = r.file_name().unwrap_or_default().to_string_lossy();
        return Err(Error::file(
            path_str(dir),
            format!("{name}, the right image of a pair, is missing"),
        ));
    }
    let bg = (bg.0.exists() && bg.1.exists()).then_some(bg);
    Ok((pairs, bg))
}

/// The stem of a file's name.
fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The entries of `dir` with an image suffix (any case), sorted.
fn images(dir: &Path) -> Result<Vec<PathBuf>> {
    let list_err = |e: std::io::Error| Error::file(path_str(dir), format!("cannot list: {e}"));
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(list_err)? {
        let path = entry.map_err(list_err)?.path();
        let suffix = path
            .extension()
            .map(|e| format!(".{}", e.to_string_lossy().to_lowercase()));
        if suffix.is_some_and(|s| IMAGE_SUFFIXES.contains(&s.as_str())) {
            out.push(path);
        }
    }
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::tests::temp_dir;

    fn touch(dir: &Path, names: &[&str]) {
        for n in names {
            std::fs::write(dir.join(n), b"").unwrap();
        }
    }

    #[test]
    fn pairs_side_by_side_and_in_subfolders() {
        let dir = temp_dir("stereo-pairs");
        touch(
            &dir,
            &[
                "b_Left.png",
                "b_right.png",
                "a_left.png",
                "a_right.png",
                "x.txt",
            ],
        );
        let (pairs, bg) = folder_pairs(&dir).unwrap();
        assert_eq!(pairs[0], (dir.join("a_left.png"), dir.join("a_right.png")));
        assert_eq!(pairs[1], (dir.join("b_Left.png"), dir.join("b_right.png")));
        assert!(bg.is_none());
        touch(&dir, &["left_bg.png", "right_bg.png"]);
        let (pairs, bg) = folder_pairs(&dir).unwrap();
        assert_eq!(pairs.len(), 2);
        assert_eq!(bg.unwrap().1, dir.join("right_bg.png"));
        touch(&dir, &["c_left.png"]);
        let e = folder_pairs(&dir).unwrap_err().to_string();
        assert!(
            e.ends_with("c_right.png, the right image of a pair, is missing"),
            "{e}"
        );

        let sub = dir.join("sub");
        for side in ["left", "right"] {
            std::fs::create_dir_all(sub.join(side)).unwrap();
            touch(&sub.join(side), &["1.png", "background.png"]);
        }
        let (pairs, bg) = folder_pairs(&sub).unwrap();
        assert_eq!(
            pairs,
            vec![(sub.join("left/1.png"), sub.join("right/1.png"))]
        );
        assert_eq!(bg.unwrap().0, sub.join("left/background.png"));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_folder_without_pairs_is_an_error() {
        let dir = temp_dir("stereo-none");
        touch(&dir, &["a.png"]);
        let e = folder_pairs(&dir).unwrap_err().to_string();
        assert!(e.contains("no stereo pairs inside"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
