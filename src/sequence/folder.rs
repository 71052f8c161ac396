//! A depth sequence as a folder of frames, one depth image a file, in the order of
//! their names. The frames' size is that of most of the first three readable frames,
//! so that one stray image of another size is a failed frame, not the size. An
//! optional `background.png` beside the frames is the empty scene, not a frame.

use super::{pattern, Kind, Options, Sequence, Values};
use crate::error::{Error, Result};
use crate::io::{self, path_str};
use std::path::{Path, PathBuf};

/// Suffixes of the files a folder's frames are read from (without a pattern).
pub const FRAME_SUFFIXES: [&str; 6] = [".png", ".tif", ".tiff", ".npy", ".pfm", ".u16"];

/// The file of the empty scene in a folder of frames.
pub const BACKGROUND: &str = "background.png";

/// Opens the folder `dir`: its frame files (those `options.pattern` matches, or those
/// of a depth-image suffix), their size and its background.
pub fn open(dir: &Path, options: &Options) -> Result<Sequence> {
    let file_err = |m: String| Error::file(path_str(dir), m);
    let mut files = match options.pattern {
        Some(p) => {
            let files: Vec<PathBuf> = pattern::glob(dir, p)?
                .into_iter()
                .filter(|f| f.is_file())
                .collect();
            if files.is_empty() {
                return Err(file_err(format!(
                    "no file inside matches {}",
                    pattern::quoted(p)
                )));
            }
            files
        }
        None => frame_files(dir)?,
    };
    files.sort();
    if files.is_empty() {
        return Err(file_err(format!(
            "no depth frames ({}) inside",
            FRAME_SUFFIXES.join(", ")
        )));
    }
    files.retain(|f| f.file_name().is_none_or(|n| n != BACKGROUND));
    if files.is_empty() {
        return Err(file_err(format!("no depth frames besides {BACKGROUND}")));
    }
    let shape = frame_shape(&files, options.depth_scale, dir)?;
    let bg_file = dir.join(BACKGROUND);
    let background = if bg_file.exists() {
        let bg = io::read_depth(&bg_file, options.depth_scale, None)?;
        Some(Values {
            shape: vec![bg.height, bg.width],
            data: bg.data,
        })
    } else {
        None
    };
    Ok(Sequence {
        name: dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        kind: Kind::Folder,
        n_frames: files.len(),
        shape,
        background,
        files,
        ..Sequence::empty(dir, options.depth_scale)
    })
}

/// The entries of `dir` with a depth-image suffix (any case).
fn frame_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| Error::file(path_str(dir), format!("cannot list: {e}")))?;
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::file(path_str(dir), format!("cannot list: {e}")))?;
        let path = entry.path();
        let suffix = path
            .extension()
            .map(|e| format!(".{}", e.to_string_lossy().to_lowercase()));
        if suffix.is_some_and(|s| FRAME_SUFFIXES.contains(&s.as_str())) {
            files.push(path);
        }
    }
    Ok(files)
}

/// The size (height, width) of a folder's frames: that of most of its first three
/// readable files (the first of equally many on a tie); an error naming the first
/// failure when none can be read.
fn frame_shape(files: &[PathBuf], scale: f64, dir: &Path) -> Result<(usize, usize)> {
    let mut first_error: Option<Error> = None;
    let mut shapes: Vec<(usize, usize)> = Vec::new();
    for f in files {
        match io::read_depth(f, scale, None) {
            Ok(d) => shapes.push((d.height, d.width)),
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
        if shapes.len() == 3 {
            break;
        }
    }
    let count = |s: &(usize, usize)| shapes.iter().filter(|t| *t == s).count();
    // The first of the most frequent: max_by_key keeps the last of equals, so the
    // shapes are searched from the end.
    match shapes.iter().rev().max_by_key(|s| count(s)) {
        Some(&s) => Ok(s),
        None => Err(Error::file(
            path_str(dir),
            format!(
                "none of its {} depth frames can be read (first: {})",
                files.len(),
                first_error.map(|e| e.to_string()).unwrap_or_default()
            ),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::super::open as open_any;
    use super::*;
    use crate::io::tests::temp_dir;
    use crate::io::Image;

    fn frame(value: f32, height: usize, width: usize) -> Image {
        Image {
            data: vec![value; height * width],
            height,
            width,
        }
    }

    #[test]
    fn a_corrupt_frame_and_one_of_another_size_are_those_frames_errors() {
        let dir = temp_dir("seq-folder");
        for k in 0..5 {
            let d = if k == 3 {
                frame(1.0, 3, 2)
            } else {
                frame(1.0 + k as f32, 2, 3)
            };
            io::write_depth(&dir.join(format!("f{k:03}.png")), &d, 0.001).unwrap();
        }
        std::fs::write(dir.join("f001.png"), b"\x89PNG not really").unwrap();
        io::write_depth(&dir.join(BACKGROUND), &frame(4.0, 2, 3), 0.001).unwrap();
        std::fs::write(dir.join("notes.txt"), b"not a frame").unwrap();
        let seq = open_any(&dir, &Options::default()).unwrap();
        assert_eq!(
            (seq.kind, seq.n_frames, seq.shape),
            (Kind::Folder, 5, (2, 3))
        );
        assert_eq!(seq.background.as_ref().unwrap().data, vec![4.0; 6]);
        assert_eq!(seq.files[4], dir.join("f004.png"));
        for k in [0, 2, 4] {
            assert_eq!(seq.frame(k).unwrap().data, vec![1.0 + k as f32; 6]);
        }
        let e = seq.frame(1).unwrap_err().to_string();
        assert!(e.contains("f001.png"), "{e}");
        let e = seq.frame(3).unwrap_err().to_string();
        assert!(
            e.ends_with("f003.png: frame is 2x3 pixels, the sequence is 3x2"),
            "{e}"
        );
        assert!(seq.frames(0, Some(1)).is_ok());
        assert!(seq
            .frames(0, Some(2))
            .unwrap_err()
            .to_string()
            .contains("f001.png"));
        // A pattern picks the frames; a matched file that is no image is a failed frame.
        let txt = Options {
            pattern: Some("*.txt"),
            ..Options::default()
        };
        let e = open_any(&dir, &txt).unwrap_err().to_string();
        assert!(e.contains("none of its 1 depth frames can be read"), "{e}");
        let some = Options {
            pattern: Some("f00[0-2].png"),
            ..Options::default()
        };
        assert_eq!(open_any(&dir, &some).unwrap().n_frames, 3);
        let none = Options {
            pattern: Some("*.tif"),
            ..Options::default()
        };
        let e = open_any(&dir, &none).unwrap_err().to_string();
        assert!(e.ends_with("no file inside matches '*.tif'"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn folders_without_frames_are_clear_errors() {
        let dir = temp_dir("seq-folder-empty");
        let e = open_any(&dir, &Options::default()).unwrap_err().to_string();
        assert!(e.contains("no depth frames (.png, .tif"), "{e}");
        io::write_depth(&dir.join(BACKGROUND), &frame(4.0, 2, 3), 0.001).unwrap();
        let e = open_any(&dir, &Options::default()).unwrap_err().to_string();
        assert!(e.ends_with("no depth frames besides background.png"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn the_size_is_that_of_most_of_the_first_three_frames() {
        let files: Vec<PathBuf> = Vec::new();
        let e = frame_shape(&files, 0.001, Path::new("x")).unwrap_err();
        assert!(e.to_string().contains("none of its 0 depth frames"), "{e}");
        let dir = temp_dir("seq-folder-shape");
        let sizes = [(2, 3), (3, 2), (3, 2), (2, 3)];
        let files: Vec<PathBuf> = sizes
            .iter()
            .enumerate()
            .map(|(k, &(h, w))| {
                let f = dir.join(format!("{k}.pfm"));
                io::write_depth(&f, &frame(1.0, h, w), 0.001).unwrap();
                f
            })
            .collect();
        assert_eq!(frame_shape(&files, 0.001, &dir).unwrap(), (3, 2));
        assert_eq!(frame_shape(&files[..2], 0.001, &dir).unwrap(), (2, 3));
        std::fs::remove_dir_all(&dir).ok();
    }
}
