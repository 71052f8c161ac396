//! Stereo matching (Growing Correspondence Seeds) and disparity → depth, for Python.

use super::convert::{
    array_like, f32_array, f64_array, image_f32, invalid, to_numpy, Arr, Flag, Int, Real, Text,
};
use super::native;
use crate::stereo::{
    depth_from_disparity as depth_of, gray_from_rgb, match_stereo_seeded, Seed, Similarity,
    StereoConfig,
};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

type F32Array<'py> = Bound<'py, PyArrayDyn<f32>>;

/// A gray image (H, W) from a gray (H, W), (H, W, 1) or colour (H, W, 3|4) array of any
/// numeric dtype; colour by luma, alpha ignored.
pub(super) fn gray_image(obj: &Bound<PyAny>, name: &str) -> PyResult<Arr<f32>> {
    let a = image_f32(obj, name)?;
    match a.shape.as_slice() {
        [_, _] => Ok(a),
        [h, w, 1] => Ok(Arr {
            data: a.data,
            shape: vec![*h, *w],
        }),
        [h, w, c @ (3 | 4)] => {
            let rgb: Vec<f32> = a
                .data
                .chunks_exact(*c)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect();
            Ok(Arr {
                data: gray_from_rgb(&rgb),
                shape: vec![*h, *w],
            })
        }
        s => Err(invalid(
            name,
            format!("expected a gray (H, W) or colour (H, W, 3) image, got shape {s:?}"),
        )),
    }
}

fn similarity_of(name: &str) -> PyResult<Similarity> {
    match name {
        "mncc" => Ok(Similarity::Mncc),
        "ncc" => Ok(Similarity::Ncc),
        other => Err(invalid(
            "similarity",
            format!(
                "must be 'mncc' or 'ncc', got {}",
                crate::error::brief_text(other)
            ),
        )),
    }
}

/// Seeds (N, 3) as rows (x, y, d), rounded to whole pixels.
fn seeds_of(obj: &Bound<PyAny>) -> PyResult<Vec<Seed>> {
    let a = f64_array(obj, "seeds", Some(2), true)?;
    if a.shape[1] != 3 {
        return Err(invalid(
            "seeds",
            format!("expected shape (N, 3) of rows (x, y, d), got {:?}", a.shape),
        ));
    }
    a.data
        .chunks_exact(3)
        .enumerate()
        .map(|(i, r)| {
            if r.iter().any(|&v| !(-0.5..=1e9).contains(&v)) {
                return Err(invalid(
                    "seeds",
                    format!(
                        "seed {i} = ({}, {}, {}) is not a pixel (x, y, d >= 0)",
                        crate::error::brief(r[0]),
                        crate::error::brief(r[1]),
                        crate::error::brief(r[2])
                    ),
                ));
            }
            Ok(Seed {
                x: r[0].round() as usize,
                y: r[1].round() as usize,
                d: r[2].round() as usize,
            })
        })
        .collect()
}

/// Disparity (H, W) float32 (NaN unmatched), and with `return_confidence` the
/// confidence (the correlation of each accepted match, NaN unmatched), of a rectified
/// pair by Growing Correspondence Seeds. Lists are read as `numpy.asarray` reads them.
#[pyfunction]
#[pyo3(name = "match", signature = (left, right, *, max_disparity=None, window=Int::new(5),
    threshold=None, num_seeds=None, seeds=None, seed=Int::new(0),
    return_confidence=Flag::new(false), lr_check=Flag::new(false), subpixel=Flag::new(true),
    fill_gaps=Flag::new(true), min_segment=None, similarity=None, half_occlusion=Flag::new(true),
    seed_distinctness=None, min_texture=None),
    text_signature = "(left, right, *, max_disparity=None, window=5, threshold=None, \
    num_seeds=None, seeds=None, seed=0, return_confidence=False, lr_check=False, subpixel=True, \
    fill_gaps=True, min_segment=None, similarity='mncc', half_occlusion=True, \
    seed_distinctness=None, min_texture=None)")]
#[allow(clippy::too_many_arguments)]
fn stereo_match<'py>(
    py: Python<'py>,
    left: &Bound<'py, PyAny>,
    right: &Bound<'py, PyAny>,
    max_disparity: Option<Int>,
    window: Int,
    threshold: Option<Real>,
    num_seeds: Option<Int>,
    seeds: Option<&Bound<'py, PyAny>>,
    seed: Int,
    return_confidence: Flag,
    lr_check: Flag,
    subpixel: Flag,
    fill_gaps: Flag,
    min_segment: Option<Int>,
    similarity: Option<Text>,
    half_occlusion: Flag,
    seed_distinctness: Option<Real>,
    min_texture: Option<Real>,
) -> PyResult<Bound<'py, PyAny>> {
    let d = StereoConfig::default();
    let real = |v: Option<Real>, default: f32, name: &str| -> PyResult<f32> {
        v.map_or(Ok(default), |v| v.get_f32(name))
    };
    let count = |v: Option<Int>, name: &str| v.map(|v| v.count(name)).transpose();
    let similarity = match &similarity {
        Some(s) => similarity_of(s.get("similarity")?)?,
        None => Similarity::Mncc,
    };
    let config = StereoConfig {
        window: window.count("window")?,
        threshold: real(threshold, d.threshold, "threshold")?,
        num_seeds: count(num_seeds, "num_seeds")?.unwrap_or(d.num_seeds),
        max_disparity: count(max_disparity, "max_disparity")?,
        seed_distinctness: real(seed_distinctness, d.seed_distinctness, "seed_distinctness")?,
        min_texture: real(min_texture, d.min_texture, "min_texture")?,
        similarity,
        lr_check: lr_check.get("lr_check")?,
        subpixel: subpixel.get("subpixel")?,
        fill_gaps: fill_gaps.get("fill_gaps")?,
        min_segment: count(min_segment, "min_segment")?.unwrap_or(d.min_segment),
        half_occlusion: half_occlusion.get("half_occlusion")?,
        rng_seed: seed.seed("seed")?,
    };
    let return_confidence = return_confidence.get("return_confidence")?;
    let l = gray_image(&array_like(left, "left")?, "left")?;
    let r = gray_image(&array_like(right, "right")?, "right")?;
    if l.shape != r.shape {
        return Err(invalid(
            "right",
            format!("shape {:?} does not match left {:?}", r.shape, l.shape),
        ));
    }
    let user = match seeds {
        Some(s) => seeds_of(&array_like(s, "seeds")?)?,
        None => Vec::new(),
    };
    let (h, w) = (l.shape[0], l.shape[1]);
    let res = native(py, || {
        match_stereo_seeded(&l.data, &r.data, h, w, &config, &user)
    })?;
    let disparity = to_numpy(py, res.disparity, &[h, w])?.into_any();
    if !return_confidence {
        return Ok(disparity);
    }
    let confidence = to_numpy(py, res.confidence, &[h, w])?.into_any();
    Ok(pyo3::types::PyTuple::new(py, [disparity, confidence])?.into_any())
}

/// Depth in metres Z = baseline · focal / (d + doffs), 0 where there is no disparity.
/// A depth beyond the float32 range (a disparity within ~1e-38 of −doffs) is refused.
#[pyfunction]
#[pyo3(signature = (disparity, focal, baseline, doffs=Real::new(0.0)),
       text_signature = "(disparity, focal, baseline, doffs=0.0)")]
fn depth_from_disparity<'py>(
    py: Python<'py>,
    disparity: &Bound<'py, PyAny>,
    focal: Real,
    baseline: Real,
    doffs: Real,
) -> PyResult<F32Array<'py>> {
    let (focal, baseline) = (focal.get("focal")?, baseline.get("baseline")?);
    let doffs = doffs.get("doffs")?;
    let d = f32_array(
        &array_like(disparity, "disparity")?,
        "disparity",
        Some(2),
        false,
    )?;
    let z = native(py, || depth_of(&d.data, focal, baseline, doffs))?;
    if let Some(k) = z.iter().position(|v| !v.is_finite()) {
        let w = d.shape[1];
        return Err(invalid(
            "disparity",
            format!(
                "the depth at row {}, column {} (disparity {}) is beyond the float32 range",
                k / w,
                k % w,
                crate::error::brief(d.data[k] as f64)
            ),
        ));
    }
    to_numpy(py, z, &d.shape)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(stereo_match, m)?)?;
    m.add_function(wrap_pyfunction!(depth_from_disparity, m)?)?;
    Ok(())
}
