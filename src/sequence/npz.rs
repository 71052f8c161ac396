//! A depth sequence in one `.npz`, the layout the synthetic data and the shared data
//! sets use: `depth` (T, H, W) uint16 (units of the depth scale) or float (metres),
//! `intrinsics` [fx, fy, cx, cy], and optional `background` (H, W), `joints`
//! (T, 15, 3) and `fps`.
//!
//! [`open`] reads every array but `depth`, whose header alone gives the frame count
//! and size; [`frames`] reads `depth` when the frames are asked for.

use super::{stem, Kind, Sequence, Values};
use crate::error::{brief, Error, Result};
use crate::io::npy::{self, Kind as DtypeKind};
use crate::io::{check_size, npz, path_str};
use std::path::Path;

/// What the errors call the file.
const WHAT: &str = "a depth sequence";

/// Whether a dtype holds depth: uint16 units or float metres.
fn is_depth(dtype: npy::Dtype) -> bool {
    dtype.kind == DtypeKind::Float || dtype.kind == DtypeKind::Uint && dtype.size == 2
}

/// The error of a `depth` (or `background`) array of another dtype.
fn not_depth(path: &Path, dtype: npy::Dtype) -> Error {
    Error::file(
        path_str(path),
        format!("depth must be uint16 or float, got {}", dtype.name()),
    )
}

/// A float as Python prints it: `nan`, `inf`, `-1.0`, `0.5` (shortened as [`brief`]
/// shortens it).
fn python_float(v: f64) -> String {
    match brief(v) {
        _ if v.is_nan() => "nan".into(),
        _ if v.is_infinite() => if v > 0.0 { "inf" } else { "-inf" }.into(),
        s if s.contains(['.', 'e']) => s,
        s => s + ".0",
    }
}

/// Opens the `.npz` at `path`: its frame count and size from the `depth` header, and
/// the other arrays. `depth_scale` converts a uint16 `background` to metres.
pub fn open(path: &Path, depth_scale: f64) -> Result<Sequence> {
    let entries = npz::read_entries(path, WHAT, &|key| key != "depth")?;
    let file_err = |m: String| Error::file(path_str(path), m);
    let Some(depth) = entries.iter().find(|e| e.key == "depth") else {
        let mut keys: Vec<String> = entries.iter().map(|e| format!("'{}'", e.key)).collect();
        keys.sort();
        return Err(file_err(format!(
            "no 'depth' array (keys: [{}])",
            keys.join(", ")
        )));
    };
    let array = |key: &str| {
        entries
            .iter()
            .find(|e| e.key == key)
            .and_then(|e| e.clone().into_array())
    };
    let gt_joints = match array("joints") {
        None => None,
        Some(a) => Some(Values {
            data: a.to_f64().ok_or_else(|| {
                file_err(format!("'joints' must be numbers, got {}", a.dtype.name()))
            })?,
            shape: a.shape,
        }),
    };
    let fps = match array("fps") {
        None => 30.0,
        Some(a) => match a.to_f64().as_deref() {
            Some(&[fps]) => fps,
            _ => {
                return Err(file_err(format!(
                    "'fps' must be one number, got {} of shape {}",
                    a.dtype.name(),
                    npy::shape_text(&a.shape)
                )))
            }
        },
    };
    let shape = &depth.header.shape;
    let &[n, h, w] = &shape[..] else {
        let why = if shape.len() == 2 {
            format!(
                "is one frame {}; expected (T, H, W)",
                npy::shape_text(shape)
            )
        } else {
            format!("must be (T, H, W), got {}", npy::shape_text(shape))
        };
        return Err(file_err(format!("'depth' {why}")));
    };
    if n == 0 {
        return Err(file_err(format!(
            "'depth' must be (T, H, W), got {}",
            npy::shape_text(shape)
        )));
    }
    check_size(path, w as u64, h as u64)?;
    if !is_depth(depth.header.dtype) {
        return Err(not_depth(path, depth.header.dtype));
    }
    if !(fps.is_finite() && fps > 0.0) {
        return Err(file_err(format!(
            "'fps' must be a positive number, got {}",
            python_float(fps)
        )));
    }
    let background = match array("background") {
        None => None,
        Some(a) => Some(Values {
            data: a
                .depth_values(depth_scale, 0..a.len())
                .ok_or_else(|| not_depth(path, a.dtype))?,
            shape: a.shape,
        }),
    };
    Ok(Sequence {
        name: stem(path),
        kind: Kind::Npz,
        n_frames: n,
        shape: (h, w),
        npz_intrinsics: array("intrinsics"),
        background,
        gt_joints,
        fps,
        ..Sequence::empty(path, depth_scale)
    })
}

/// Frames [start, stop) of a `.npz` sequence as `f32` metres, (k, H, W), read from
/// its `depth` (which must still be the shape [`open`] found).
pub fn frames(seq: &Sequence, start: usize, stop: usize) -> Result<Values<f32>> {
    let path = &seq.path;
    let mut arrays = npz::read(path, WHAT, Some(&["depth".to_string()]))?;
    let Some((_, depth)) = arrays.pop() else {
        return Err(Error::file(path_str(path), "no 'depth' array"));
    };
    let (h, w) = seq.shape;
    if depth.shape.len() != 3 || depth.shape[1..] != [h, w] || depth.shape[0] < stop {
        return Err(Error::file(
            path_str(path),
            format!(
                "'depth' is {}, not the ({}, {h}, {w}) it was when opened",
                npy::shape_text(&depth.shape),
                seq.n_frames
            ),
        ));
    }
    let data = depth
        .depth_values(seq.depth_scale, start * h * w..stop * h * w)
        .ok_or_else(|| not_depth(path, depth.dtype))?;
    Ok(Values {
        data,
        shape: vec![stop - start, h, w],
    })
}

#[cfg(test)]
mod tests {
    use super::super::{open as open_any, Options};
    use super::*;
    use crate::io::npy::{Array, Dtype};
    use crate::io::tests::temp_dir;

    fn depth_u16(t: usize, h: usize, w: usize) -> Array {
        let values: Vec<u16> = (0..t * h * w).map(|k| 1000 + k as u16).collect();
        Array::of(
            Dtype::parse("<u2").unwrap(),
            vec![t, h, w],
            &values,
            u16::to_le_bytes,
        )
    }

    fn write(path: &Path, arrays: &[(&str, Array)]) {
        let refs: Vec<(&str, &Array)> = arrays.iter().map(|(k, a)| (*k, a)).collect();
        npz::write(path, &refs).unwrap();
    }

    #[test]
    fn a_sequence_round_trips_through_the_npz_writer() {
        let dir = temp_dir("seq-npz");
        let p = dir.join("walk.npz");
        let intrinsics = Array::of(
            Dtype::F64,
            vec![4],
            &[60.0, 61.0, 3.5, 2.5],
            f64::to_le_bytes,
        );
        let joints: Vec<f32> = (0..3 * 15 * 3).map(|k| k as f32).collect();
        let bg: Vec<u16> = vec![4000; 6];
        write(
            &p,
            &[
                ("depth", depth_u16(3, 2, 3)),
                ("intrinsics", intrinsics),
                (
                    "joints",
                    Array::of(Dtype::F32, vec![3, 15, 3], &joints, f32::to_le_bytes),
                ),
                (
                    "background",
                    Array::of(
                        Dtype::parse("<u2").unwrap(),
                        vec![2, 3],
                        &bg,
                        u16::to_le_bytes,
                    ),
                ),
                (
                    "fps",
                    Array::of(Dtype::I64, vec![], &[15i64], i64::to_le_bytes),
                ),
            ],
        );
        let seq = open_any(&p, &Options::default()).unwrap();
        assert_eq!((seq.kind, seq.name.as_str()), (Kind::Npz, "walk"));
        assert_eq!((seq.n_frames, seq.shape, seq.fps), (3, (2, 3), 15.0));
        assert_eq!(seq.intrinsics().unwrap(), Some([60.0, 61.0, 3.5, 2.5]));
        assert_eq!(seq.gt_joints.as_ref().unwrap().shape, vec![3, 15, 3]);
        assert_eq!(seq.gt_joints.as_ref().unwrap().data[7], 7.0);
        let bg = seq.background.as_ref().unwrap();
        assert_eq!((bg.shape.clone(), bg.data[0]), (vec![2, 3], 4.0));
        let f = seq.frames(1, Some(3)).unwrap();
        assert_eq!(f.shape, vec![2, 2, 3]);
        // uint16 units times the scale, in f32 as numpy computes them.
        assert_eq!(f.data[0], 1006.0 * 0.001f32);
        assert_eq!(f.data[11], 1017.0 * 0.001f32);
        assert!(seq.files.is_empty());
        assert_eq!(seq.frame_name(2), format!("{}[2]", path_str(&p)));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn hostile_archives_are_clear_errors() {
        let dir = temp_dir("seq-npz-hostile");
        let p = dir.join("h.npz");
        let check = |arrays: &[(&str, Array)], want: &str| {
            write(&p, arrays);
            let e = open_any(&p, &Options::default()).unwrap_err();
            assert!(matches!(e, Error::File { .. }), "{e}");
            let e = e.to_string();
            assert!(e.contains("h.npz") && e.contains(want), "{want}: {e}");
        };
        let ones = |shape: Vec<usize>| {
            let n = shape.iter().product::<usize>();
            Array::of(Dtype::F32, shape, &vec![1f32; n], f32::to_le_bytes)
        };
        check(
            &[("depth_", ones(vec![1, 2, 2]))],
            "no 'depth' array (keys: ['depth_'])",
        );
        check(
            &[("depth", ones(vec![2, 2]))],
            "'depth' is one frame (2, 2); expected (T, H, W)",
        );
        check(
            &[("depth", ones(vec![0, 2, 2]))],
            "'depth' must be (T, H, W), got (0, 2, 2)",
        );
        check(
            &[("depth", ones(vec![4]))],
            "'depth' must be (T, H, W), got (4,)",
        );
        let ints = Array::of(Dtype::I64, vec![1, 1, 2], &[1i64, 2], i64::to_le_bytes);
        check(
            &[("depth", ints)],
            "depth must be uint16 or float, got int64",
        );
        for (fps, want) in [(0.0, "got 0.0"), (f64::NAN, "got nan"), (-1.0, "got -1.0")] {
            let fps = Array::of(Dtype::F64, vec![], &[fps], f64::to_le_bytes);
            check(&[("depth", depth_u16(1, 2, 2)), ("fps", fps)], want);
        }
        check(
            &[("depth", depth_u16(1, 2, 2)), ("fps", ones(vec![2]))],
            "'fps' must be one number, got float32 of shape (2,)",
        );
        check(
            &[("depth", depth_u16(1, 2, 2)), ("fps", Array::text("x"))],
            "'fps' must be one number",
        );
        let huge = Array {
            data: vec![],
            ..Array::of(
                Dtype::F32,
                vec![1, 1 << 12, 1 << 12],
                &[0f32; 0],
                f32::to_le_bytes,
            )
        };
        write(&p, &[("depth", huge)]);
        let e = open_any(&p, &Options::default()).unwrap_err();
        assert!(
            matches!(e, Error::File { .. } | Error::ResourceLimit { .. }),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
