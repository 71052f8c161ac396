//! The working resolution: images from high-resolution sensors are reduced by a whole
//! factor before the pipeline runs, and its per-pixel results are brought back to the
//! input's pixel grid. The camera frame is the same at both resolutions, so poses and
//! joints need no conversion.

use crate::camera::Camera;
use crate::error::Result;

/// How an input image maps to the working one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkingResolution {
    /// Each working pixel covers `factor`×`factor` input pixels.
    pub factor: usize,
    /// The input camera and the working one.
    pub input: Camera,
    pub working: Camera,
}

impl WorkingResolution {
    /// The factor nearest `focal / working_focal` (at least 1) for `camera`'s focal
    /// length, and the working camera: same field of view, pixel centres mapped as
    /// u' = (u + 0.5) / factor − 0.5.
    pub fn for_camera(camera: &Camera, working_focal: f64) -> Result<Self> {
        let focal = camera.fx.min(camera.fy);
        let by_focal = (focal / working_focal).round().max(1.0) as usize;
        // Never below 32 pixels a side.
        let limit = (camera.width.min(camera.height) / 32).max(1);
        let factor = by_focal.min(limit);
        let working = if factor == 1 {
            *camera
        } else {
            let f = factor as f64;
            Camera::new(
                camera.fx / f,
                camera.fy / f,
                (camera.cx + 0.5) / f - 0.5,
                (camera.cy + 0.5) / f - 0.5,
                camera.width / factor,
                camera.height / factor,
            )?
        };
        Ok(WorkingResolution {
            factor,
            input: *camera,
            working,
        })
    }

    /// The working depth image (and the index of the input pixel each working pixel
    /// took its depth from): per block, the lower median of the readings (a depth the
    /// sensor measured, not a blend across an edge), 0 where the block has none. The
    /// identity (no copy of the indices) when the factor is 1.
    pub fn depth(&self, depth: &[f32]) -> (Vec<f32>, Vec<u32>) {
        if self.factor == 1 {
            return (depth.to_vec(), Vec::new());
        }
        let (f, w) = (self.factor, self.input.width);
        let (ww, wh) = (self.working.width, self.working.height);
        let mut out = vec![0.0f32; ww * wh];
        let mut source = vec![u32::MAX; ww * wh];
        let mut block: Vec<(f32, u32)> = Vec::with_capacity(f * f);
        for r in 0..wh {
            for c in 0..ww {
                block.clear();
                for dr in 0..f {
                    let row = (r * f + dr) * w + c * f;
                    for dc in 0..f {
                        let z = depth[row + dc];
                        if z > 0.0 {
                            block.push((z, (row + dc) as u32));
                        }
                    }
                }
                if block.is_empty() {
                    continue;
                }
                let mid = (block.len() - 1) / 2;
                let (z, i) = *block
                    .select_nth_unstable_by(mid, |a, b| a.0.total_cmp(&b.0))
                    .1;
                out[r * ww + c] = z;
                source[r * ww + c] = i;
            }
        }
        (out, source)
    }

    /// A mask of the input size at the working resolution: each working pixel takes the
    /// mask at the input pixel its depth came from (`source`), or, where its block had
    /// no reading, whether most of the block is in the mask.
    pub fn mask(&self, mask: &[bool], source: &[u32]) -> Vec<bool> {
        if self.factor == 1 {
            return mask.to_vec();
        }
        let (f, w) = (self.factor, self.input.width);
        let ww = self.working.width;
        source
            .iter()
            .enumerate()
            .map(|(k, &i)| {
                if i != u32::MAX {
                    return mask[i as usize];
                }
                let (r, c) = (k / ww, k % ww);
                let inside = (0..f * f)
                    .filter(|&d| mask[(r * f + d / f) * w + c * f + d % f])
                    .count();
                2 * inside > f * f
            })
            .collect()
    }

    /// A per-pixel image of the working size brought to the input size: each input
    /// pixel takes its block's value; pixels beyond the last whole block take `fill`.
    pub fn upsample<T: Copy>(&self, image: &[T], fill: T) -> Vec<T> {
        if self.factor == 1 {
            return image.to_vec();
        }
        let (f, w, h) = (self.factor, self.input.width, self.input.height);
        let (ww, wh) = (self.working.width, self.working.height);
        let mut out = vec![fill; w * h];
        for row in 0..(wh * f).min(h) {
            let src = &image[(row / f) * ww..][..ww];
            let dst = &mut out[row * w..][..ww * f];
            for (c, v) in dst.iter_mut().enumerate() {
                *v = src[c / f];
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_kinect_image_is_halved_and_an_itop_one_kept() {
        let r = WorkingResolution::for_camera(&Camera::kinect_v1(), 300.0).unwrap();
        assert_eq!(r.factor, 2);
        assert_eq!((r.working.width, r.working.height), (320, 240));
        assert_eq!(r.working.fx, 290.0);
        // The centre of the image stays the centre.
        assert_eq!(r.working.cx, (319.5 + 0.5) / 2.0 - 0.5);
        let same = WorkingResolution::for_camera(&Camera::itop(), 300.0).unwrap();
        assert_eq!(same.factor, 1);
        assert_eq!(same.working, Camera::itop());
    }

    #[test]
    fn a_point_projects_to_the_same_block() {
        let r = WorkingResolution::for_camera(&Camera::kinect_v1(), 300.0).unwrap();
        let p = nalgebra::Vector3::new(0.31, -0.2, 2.7);
        let (u, v) = r.input.project(&p).unwrap();
        let (uw, vw) = r.working.project(&p).unwrap();
        assert!((uw - ((u + 0.5) / 2.0 - 0.5)).abs() < 1e-9);
        assert!((vw - ((v + 0.5) / 2.0 - 0.5)).abs() < 1e-9);
    }

    #[test]
    fn blocks_take_the_lower_median_reading_and_masks_follow_it() {
        let camera = Camera::new(600.0, 600.0, 1.5, 1.5, 4, 4).unwrap();
        let r = WorkingResolution {
            factor: 2,
            input: camera,
            working: Camera::new(300.0, 300.0, 0.5, 0.5, 2, 2).unwrap(),
        };
        #[rustfmt::skip]
        let depth = [
            1.0, 3.0,   0.0, 0.0,
            2.0, 4.0,   0.0, 5.0,
            0.0, 0.0,   9.0, 8.0,
            0.0, 0.0,   7.0, 1.0,
        ];
        let (d, src) = r.depth(&depth);
        assert_eq!(d, vec![2.0, 5.0, 0.0, 7.0]);
        assert_eq!(src, vec![4, 7, u32::MAX, 14]);
        #[rustfmt::skip]
        let mask = [
            false, false,   true, true,
            true,  false,   true, false,
            true,  true,    false, false,
            true,  false,   false, true,
        ];
        assert_eq!(r.mask(&mask, &src), vec![true, false, true, false]);
        let up = r.upsample(&[1i16, 2, 3, 4], -1);
        assert_eq!(up, vec![1, 1, 2, 2, 1, 1, 2, 2, 3, 3, 4, 4, 3, 3, 4, 4]);
    }
}
