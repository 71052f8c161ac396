//! Depth sequences on disk: a `.npz` in the shared layout ([`npz`]), a folder of depth
//! frames ([`folder`], its optional glob [`pattern`]), or one depth image.
//!
//! [`open`] reads what a sequence's files say about it (its size, frame count,
//! background, ground-truth joints, frame rate, the intrinsics a `.npz` holds); the
//! frames are read on demand, [`Sequence::frames`] for a range and [`Sequence::frame`]
//! for one frame of a folder, so that one corrupt, truncated or odd-sized frame is
//! that frame's error, not the sequence's. The camera is the caller's to resolve
//! (from the intrinsics given, the ones a `.npz` holds, or a camera given).
//!
//! [`stereo`] finds the rectified stereo pairs of a folder, for the stereo sequences.

pub mod folder;
pub mod npz;
pub mod pattern;
pub mod stereo;

use crate::error::{Error, Result};
use crate::io::{self, path_str, Image};
use std::path::{Path, PathBuf};

/// What a sequence is on disk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A `.npz` holding `depth` (T, H, W).
    Npz,
    /// A folder of depth frames, one file each.
    Folder,
    /// One depth image: a sequence of one frame.
    Image,
}

impl Kind {
    /// The kind as Python names it: `"npz"`, `"folder"` or `"image"`.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Npz => "npz",
            Kind::Folder => "folder",
            Kind::Image => "image",
        }
    }
}

/// Values and their shape, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Values<T> {
    pub data: Vec<T>,
    pub shape: Vec<usize>,
}

/// How [`open`] reads a sequence.
#[derive(Debug, Clone, Copy)]
pub struct Options<'a> {
    /// Metres per integer unit of the depth files, in
    /// [[`io::MIN_DEPTH_SCALE`], [`io::MAX_DEPTH_SCALE`]].
    pub depth_scale: f64,
    /// For a folder, a glob of the frame files to read ([`pattern::glob`]); `None`
    /// for every file with a depth-image suffix ([`folder::FRAME_SUFFIXES`]).
    pub pattern: Option<&'a str>,
}

impl Default for Options<'_> {
    fn default() -> Self {
        Options {
            depth_scale: 0.001,
            pattern: None,
        }
    }
}

/// A depth sequence: what its files say about it; its frames are read on demand.
#[derive(Debug, Clone)]
pub struct Sequence {
    pub path: PathBuf,
    /// The folder's name or the file's stem.
    pub name: String,
    pub kind: Kind,
    pub n_frames: usize,
    /// (height, width) of every frame.
    pub shape: (usize, usize),
    /// Metres per integer unit of the depth files.
    pub depth_scale: f64,
    /// The `intrinsics` array a `.npz` holds, as it is (checked by
    /// [`Sequence::intrinsics`] when used).
    pub npz_intrinsics: Option<io::npy::Array>,
    /// The empty scene in metres: a folder's `background.png`, a `.npz`'s
    /// `background`.
    pub background: Option<Values<f32>>,
    /// The ground-truth joints a `.npz` holds (`joints`), as float64.
    pub gt_joints: Option<Values<f64>>,
    /// Frames a second (a `.npz`'s `fps`, else 30).
    pub fps: f64,
    /// The frame files of a folder (sorted by name) or the image; empty for a `.npz`.
    pub files: Vec<PathBuf>,
}

/// Opens the sequence at `path`: a `.npz` ([`npz::open`]), a folder of depth frames
/// ([`folder::open`]) or one depth image.
pub fn open(path: &Path, options: &Options) -> Result<Sequence> {
    io::check_depth_scale(options.depth_scale)?;
    if !path.exists() {
        return Err(Error::not_found(path_str(path)));
    }
    if path.is_dir() {
        return folder::open(path, options);
    }
    let is_npz = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    if is_npz {
        return npz::open(path, options.depth_scale);
    }
    let first = io::read_depth(path, options.depth_scale, None)?;
    Ok(Sequence {
        name: stem(path),
        kind: Kind::Image,
        n_frames: 1,
        shape: (first.height, first.width),
        files: vec![path.to_path_buf()],
        ..Sequence::empty(path, options.depth_scale)
    })
}

/// The stem of a file's name ("" without one), as messages and results name it.
fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

impl Sequence {
    /// A sequence of no frames at `path`, for the openers to fill in.
    fn empty(path: &Path, depth_scale: f64) -> Sequence {
        Sequence {
            path: path.to_path_buf(),
            name: String::new(),
            kind: Kind::Image,
            n_frames: 0,
            shape: (0, 0),
            depth_scale,
            npz_intrinsics: None,
            background: None,
            gt_joints: None,
            fps: 30.0,
            files: Vec::new(),
        }
    }

    /// The frame range [start, stop): `stop` (at most the frame count, which `None`
    /// stands for) not before `start`.
    pub fn range(&self, start: usize, stop: Option<usize>) -> Result<(usize, usize)> {
        let stop = stop.unwrap_or(self.n_frames).min(self.n_frames);
        if start > stop {
            return Err(Error::invalid(
                "start/stop",
                format!("bad frame range [{start}, {stop})"),
            ));
        }
        Ok((start, stop))
    }

    /// Depth frames [start, stop) as `f32` metres, (k, H, W): the first frame that
    /// cannot be read is the error.
    pub fn frames(&self, start: usize, stop: Option<usize>) -> Result<Values<f32>> {
        let (start, stop) = self.range(start, stop)?;
        let (h, w) = self.shape;
        if self.kind == Kind::Npz {
            return npz::frames(self, start, stop);
        }
        let mut data = Vec::with_capacity((stop - start) * h * w);
        for k in start..stop {
            data.extend(self.frame(k)?.data);
        }
        Ok(Values {
            data,
            shape: vec![stop - start, h, w],
        })
    }

    /// Frame `k` of a folder or an image, read from its file: an error for a file
    /// that cannot be read or that is not of the sequence's size.
    pub fn frame(&self, k: usize) -> Result<Image> {
        let Some(file) = self.files.get(k) else {
            return Err(Error::invalid(
                "k",
                format!("frame {k} of a sequence of {} files", self.files.len()),
            ));
        };
        let d = io::read_depth(file, self.depth_scale, None)?;
        let (h, w) = self.shape;
        if (d.height, d.width) != (h, w) {
            return Err(Error::file(
                path_str(file),
                format!(
                    "frame is {}x{} pixels, the sequence is {w}x{h}",
                    d.width, d.height
                ),
            ));
        }
        Ok(d)
    }

    /// How messages name frame `k`: its file, or its index in the `.npz`.
    pub fn frame_name(&self, k: i64) -> String {
        match usize::try_from(k).ok().and_then(|k| self.files.get(k)) {
            Some(f) => path_str(f),
            None => format!("{}[{k}]", path_str(&self.path)),
        }
    }

    /// The camera intrinsics [fx, fy, cx, cy] a `.npz` holds, if any: an error for an
    /// array that is not four finite numbers.
    pub fn intrinsics(&self) -> Result<Option<[f64; 4]>> {
        let Some(a) = &self.npz_intrinsics else {
            return Ok(None);
        };
        let values = a.to_f64().ok_or_else(|| {
            Error::invalid(
                "intrinsics",
                format!("expected numbers, got {}", a.dtype.name()),
            )
        })?;
        intrinsics_of(&values).map(Some)
    }
}

/// [fx, fy, cx, cy] from four finite numbers.
pub fn intrinsics_of(values: &[f64]) -> Result<[f64; 4]> {
    let &[fx, fy, cx, cy] = values else {
        return Err(Error::invalid(
            "intrinsics",
            format!("need [fx, fy, cx, cy], got {} values", values.len()),
        ));
    };
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "intrinsics",
            format!("must be finite numbers, got {v}"),
        ));
    }
    Ok([fx, fy, cx, cy])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::tests::temp_dir;

    #[test]
    fn one_image_is_a_sequence_of_one_frame() {
        let dir = temp_dir("seq-image");
        let p = dir.join("one.pfm");
        let img = Image {
            data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            height: 2,
            width: 3,
        };
        io::write_depth(&p, &img, 0.001).unwrap();
        let seq = open(&p, &Options::default()).unwrap();
        assert_eq!(
            (seq.kind, seq.n_frames, seq.shape),
            (Kind::Image, 1, (2, 3))
        );
        assert_eq!(seq.name, "one");
        assert_eq!(seq.frames(0, None).unwrap().data, img.data);
        assert_eq!(seq.frames(1, None).unwrap().shape, vec![0, 2, 3]);
        let e = seq.frames(2, Some(1)).unwrap_err().to_string();
        assert_eq!(e, "start/stop: bad frame range [2, 1)");
        assert_eq!(seq.frame_name(0), path_str(&p));
        assert_eq!(seq.frame_name(-1), format!("{}[-1]", path_str(&p)));
        assert!(matches!(
            open(&dir.join("none.png"), &Options::default()),
            Err(Error::NotFound { .. })
        ));
        let bad = Options {
            depth_scale: 2.0,
            pattern: None,
        };
        assert!(open(&p, &bad)
            .unwrap_err()
            .to_string()
            .starts_with("scale:"));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn intrinsics_are_four_finite_numbers() {
        assert_eq!(
            intrinsics_of(&[1.0, 2.0, 3.0, 4.0]).unwrap(),
            [1.0, 2.0, 3.0, 4.0]
        );
        let e = intrinsics_of(&[1.0, 2.0]).unwrap_err().to_string();
        assert_eq!(e, "intrinsics: need [fx, fy, cx, cy], got 2 values");
        let e = intrinsics_of(&[1.0, f64::NAN, 3.0, 4.0]).unwrap_err();
        assert!(e.to_string().contains("finite"), "{e}");
    }
}
