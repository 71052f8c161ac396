//! Stereo matching (Growing Correspondence Seeds) and disparity → depth, for Python.

use super::arrays::{count, count_opt, f32_array, f64_array, seed as arg_seed, to_numpy, Arr};
use super::native;
use crate::stereo::{
    depth_from_disparity as depth_of, gray_from_rgb, match_stereo_seeded, Seed, Similarity,
    StereoConfig,
};
use crate::Error;
use numpy::PyArrayDyn;
use pyo3::prelude::*;

type F32Array<'py> = Bound<'py, PyArrayDyn<f32>>;

/// A gray image (H, W) from a gray (H, W), (H, W, 1) or colour (H, W, 3|4) array of any
/// numeric dtype; colour by luma, alpha ignored.
fn gray_image(obj: &Bound<PyAny>, name: &str) -> PyResult<Arr<f32>> {
    let a = f32_array(obj, name, None, true)?;
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
        s => Err(Error::invalid(
            name,
            format!("expected a gray (H, W) or colour (H, W, 3) image, got shape {s:?}"),
        )
        .into()),
    }
}

fn similarity_of(name: &str) -> PyResult<Similarity> {
    match name {
        "mncc" => Ok(Similarity::Mncc),
        "ncc" => Ok(Similarity::Ncc),
        other => Err(Error::invalid(
            "similarity",
            format!("must be 'mncc' or 'ncc', got {other:?}"),
        )
        .into()),
    }
}

/// Seeds (N, 3) as rows (x, y, d), rounded to whole pixels.
fn seeds_of(obj: &Bound<PyAny>) -> PyResult<Vec<Seed>> {
    let a = f64_array(obj, "seeds", Some(2), true)?;
    if a.shape[1] != 3 {
        return Err(Error::invalid(
            "seeds",
            format!("expected shape (N, 3) of rows (x, y, d), got {:?}", a.shape),
        )
        .into());
    }
    a.data
        .chunks_exact(3)
        .enumerate()
        .map(|(i, r)| {
            if r.iter().any(|&v| v < -0.5) {
                return Err(Error::invalid(
                    "seeds",
                    format!("seed {i} has a negative coordinate: {r:?}"),
                )
                .into());
            }
            Ok(Seed {
                x: r[0].round() as usize,
                y: r[1].round() as usize,
                d: r[2].round() as usize,
            })
        })
        .collect()
}

/// Disparity (H, W) float32 (NaN unmatched) and confidence (the correlation of each
/// accepted match, NaN unmatched) of a rectified pair by Growing Correspondence Seeds.
#[pyfunction]
#[pyo3(signature = (left, right, max_disparity=None, window=5, threshold=None, num_seeds=None,
    seeds=None, seed=0, lr_check=false, subpixel=true, fill_gaps=true, seed_distinctness=None,
    min_texture=None, min_segment=None, similarity="mncc"))]
#[allow(clippy::too_many_arguments)]
fn stereo_match<'py>(
    py: Python<'py>,
    left: &Bound<'py, PyAny>,
    right: &Bound<'py, PyAny>,
    max_disparity: Option<i128>,
    window: i128,
    threshold: Option<f32>,
    num_seeds: Option<i128>,
    seeds: Option<&Bound<'py, PyAny>>,
    seed: i128,
    lr_check: bool,
    subpixel: bool,
    fill_gaps: bool,
    seed_distinctness: Option<f32>,
    min_texture: Option<f32>,
    min_segment: Option<i128>,
    similarity: &str,
) -> PyResult<(F32Array<'py>, F32Array<'py>)> {
    let max_disparity = count_opt(max_disparity, "max_disparity")?;
    let window = count(window, "window")?;
    let num_seeds = count_opt(num_seeds, "num_seeds")?;
    let seed = arg_seed(seed, "seed")?;
    let min_segment = count_opt(min_segment, "min_segment")?;
    let l = gray_image(left, "left")?;
    let r = gray_image(right, "right")?;
    if l.shape != r.shape {
        return Err(Error::invalid(
            "right",
            format!("shape {:?} does not match left {:?}", r.shape, l.shape),
        )
        .into());
    }
    let user = seeds.map(seeds_of).transpose()?.unwrap_or_default();
    let d = StereoConfig::default();
    let config = StereoConfig {
        window,
        threshold: threshold.unwrap_or(d.threshold),
        num_seeds: num_seeds.unwrap_or(d.num_seeds),
        max_disparity,
        seed_distinctness: seed_distinctness.unwrap_or(d.seed_distinctness),
        min_texture: min_texture.unwrap_or(d.min_texture),
        similarity: similarity_of(similarity)?,
        lr_check,
        subpixel,
        fill_gaps,
        min_segment: min_segment.unwrap_or(d.min_segment),
        rng_seed: seed,
    };
    let (h, w) = (l.shape[0], l.shape[1]);
    let res = native(py, || {
        match_stereo_seeded(&l.data, &r.data, h, w, &config, &user)
    })?;
    Ok((
        to_numpy(py, res.disparity, &[h, w]),
        to_numpy(py, res.confidence, &[h, w]),
    ))
}

/// Depth in metres Z = baseline · focal / (d + doffs), 0 where there is no disparity.
#[pyfunction]
#[pyo3(signature = (disparity, focal, baseline, doffs=0.0))]
fn depth_from_disparity<'py>(
    py: Python<'py>,
    disparity: &Bound<'py, PyAny>,
    focal: f64,
    baseline: f64,
    doffs: f64,
) -> PyResult<F32Array<'py>> {
    let d = f32_array(disparity, "disparity", Some(2), false)?;
    let z = native(py, || depth_of(&d.data, focal, baseline, doffs))?;
    Ok(to_numpy(py, z, &d.shape))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(stereo_match, m)?)?;
    m.add_function(wrap_pyfunction!(depth_from_disparity, m)?)?;
    Ok(())
}
