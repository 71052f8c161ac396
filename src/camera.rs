//! Pinhole camera: intrinsics, projection and back-projection.
//!
//! Camera frame: x right, y down, z forward (metres). Pixel (row v, column u) is centred
//! at (u, v) and a point p projects to u = fx·x/z + cx, v = fy·y/z + cy.

use crate::error::{ensure, ensure_positive, Error, Result};
use nalgebra::Vector3;

/// Focal length per pixel of image width of [`Camera::nominal`].
pub const NOMINAL_FOCAL_PER_WIDTH: f64 = 0.9;

/// Names of the sensors [`Camera::preset`] knows.
pub const PRESETS: &[&str] = &[
    "kinect-v1",
    "kinect-v1-qvga",
    "kinect-v2",
    "azure-kinect",
    "realsense-d435",
    "itop",
];

/// Pinhole intrinsics plus the image size they belong to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: usize,
    pub height: usize,
}

impl Camera {
    /// A validated camera: focal lengths positive, image non-empty, principal point
    /// within a generous margin of the image (a centre far outside is a unit mistake).
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64, width: usize, height: usize) -> Result<Self> {
        ensure_positive(fx, "fx")?;
        ensure_positive(fy, "fy")?;
        ensure(width > 0 && height > 0, "width/height", || {
            format!("image size must be positive, got {width}x{height}")
        })?;
        ensure(
            width <= 1 << 15 && height <= 1 << 15,
            "width/height",
            || format!("image size {width}x{height} is unreasonably large"),
        )?;
        let (w, h) = (width as f64, height as f64);
        ensure(
            cx.is_finite() && cx > -0.5 * w && cx < 1.5 * w,
            "cx",
            || format!("principal point cx={cx} does not fit an image {width} pixels wide"),
        )?;
        ensure(
            cy.is_finite() && cy > -0.5 * h && cy < 1.5 * h,
            "cy",
            || format!("principal point cy={cy} does not fit an image {height} pixels high"),
        )?;
        Ok(Camera {
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        })
    }

    /// A camera for an image of `width`×`height` whose intrinsics are unknown: the
    /// principal point at the centre and a focal length of 0.9·width pixels (a 58°
    /// horizontal field of view, as the Kinect v1, ITOP and most structured-light and
    /// time-of-flight depth cameras have within ±15 %).
    pub fn nominal(width: usize, height: usize) -> Result<Self> {
        let f = NOMINAL_FOCAL_PER_WIDTH * width as f64;
        Camera::new(
            f,
            f,
            0.5 * (width as f64 - 1.0),
            0.5 * (height as f64 - 1.0),
            width,
            height,
        )
    }

    /// The camera of a common depth sensor by name (one of [`PRESETS`]; case and `_`
    /// versus `-` do not matter). These are nominal intrinsics: a device's own
    /// calibration differs by a few pixels, and is better when you have it.
    pub fn preset(name: &str) -> Result<Self> {
        let key = name.trim().to_ascii_lowercase().replace('_', "-");
        let pinhole = |f: f64, cx: f64, cy: f64, width: usize, height: usize| Camera {
            fx: f,
            fy: f,
            cx,
            cy,
            width,
            height,
        };
        Ok(match key.as_str() {
            "kinect-v1" => Camera::kinect_v1(),
            "kinect-v1-qvga" => Camera::kinect_v1_qvga(),
            // The depth (IR) camera at 512×424; the factory intrinsics libfreenect2 reads
            // from two devices are f = 368.1 and 365.4 px, principal point (261, 203–206)
            // (github.com/OpenKinect/libfreenect2/issues/41).
            "kinect-v2" => pinhole(365.4, 260.9, 205.6, 512, 424),
            // Depth mode NFOV unbinned, 640×576: the factory calibration the Azure Kinect
            // SDK reports (k4a_calibration_t, depth camera) is f ≈ 504 px with the
            // principal point within a few pixels of the centre.
            "azure-kinect" => pinhole(504.0, 319.5, 287.5, 640, 576),
            // The depth stream at 640×480: `rs-enumerate-devices -c` reports f = 384.2 px,
            // principal point (319.5, 236.4), 79.6°×64.0° (github.com/realsenseai/
            // realsense-ros/issues/2788). At 848×480 and 1280×720 f is about 424 and 640 px.
            "realsense-d435" => pinhole(384.2, 319.5, 236.4, 640, 480),
            "itop" => Camera::itop(),
            _ => {
                return Err(Error::invalid(
                    "name",
                    format!(
                        "unknown camera preset {name:?}; the presets are {}",
                        PRESETS.join(", ")
                    ),
                ))
            }
        })
    }

    /// Kinect v1 depth camera at 640×480. f = 580 px: the IR camera's calibrated focal
    /// length (Burrus' Kinect calibration gives 594/591 px, the OpenNI driver assumes
    /// 575.8 px); 525 px, which the TUM RGB-D benchmark uses, is the colour camera's, for
    /// depth registered to colour.
    pub fn kinect_v1() -> Self {
        Camera {
            fx: 580.0,
            fy: 580.0,
            cx: 319.5,
            cy: 239.5,
            width: 640,
            height: 480,
        }
    }

    /// Kinect v1 depth camera downsampled to 320×240.
    pub fn kinect_v1_qvga() -> Self {
        Camera {
            fx: 290.0,
            fy: 290.0,
            cx: 159.5,
            cy: 119.5,
            width: 320,
            height: 240,
        }
    }

    /// The ITOP data set's camera (320×240, f = 1/0.0035 ≈ 285.71 px), also used by the
    /// shared synthetic sequences.
    pub fn itop() -> Self {
        Camera {
            fx: 285.71,
            fy: 285.71,
            cx: 159.5,
            cy: 119.5,
            width: 320,
            height: 240,
        }
    }

    /// The same camera for an image resampled by `factor` (0.5 = half resolution).
    pub fn scaled(&self, factor: f64) -> Result<Self> {
        ensure_positive(factor, "factor")?;
        let width = ((self.width as f64) * factor).round().max(1.0) as usize;
        let height = ((self.height as f64) * factor).round().max(1.0) as usize;
        // A factor so large that the scaled camera is not one is the factor's fault.
        Camera::new(
            self.fx * factor,
            self.fy * factor,
            (self.cx + 0.5) * factor - 0.5,
            (self.cy + 0.5) * factor - 0.5,
            width,
            height,
        )
        .map_err(|e| Error::invalid("factor", format!("{factor} gives no camera: {e}")))
    }

    /// Checks that an image of `height`×`width` belongs to this camera.
    pub fn check_image(&self, name: &str, height: usize, width: usize) -> Result<()> {
        ensure(height == self.height && width == self.width, name, || {
            format!(
                "image is {height}x{width} (HxW) but the camera is {}x{}",
                self.height, self.width
            )
        })
    }

    /// Pixel coordinates (u, v) of a camera-frame point; None behind the camera.
    #[inline]
    pub fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        if p.z <= 0.0 {
            return None;
        }
        Some((self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }

    /// The camera-frame point at pixel (u, v) with depth z.
    #[inline]
    pub fn back_project(&self, u: f64, v: f64, z: f64) -> Vector3<f64> {
        Vector3::new((u - self.cx) * z / self.fx, (v - self.cy) * z / self.fy, z)
    }

    /// Unit viewing ray through pixel (u, v).
    #[inline]
    pub fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        Vector3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn project_inverts_back_project() {
        let cam = Camera::new(300.0, 310.0, 150.0, 120.0, 320, 240).unwrap();
        for &(u, v, z) in &[(0.0, 0.0, 1.0), (319.0, 239.0, 4.5), (12.5, 200.25, 0.3)] {
            let p = cam.back_project(u, v, z);
            let (u2, v2) = cam.project(&p).unwrap();
            assert!((u - u2).abs() < 1e-9 && (v - v2).abs() < 1e-9);
            assert!((p.z - z).abs() < 1e-12);
        }
        assert!(cam.project(&Vector3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn rejects_nonsense() {
        assert!(Camera::new(0.0, 1.0, 1.0, 1.0, 10, 10).is_err());
        assert!(Camera::new(f64::NAN, 1.0, 1.0, 1.0, 10, 10).is_err());
        assert!(Camera::new(1.0, 1.0, 1.0, 1.0, 0, 10).is_err());
        assert!(Camera::new(500.0, 500.0, 5000.0, 1.0, 10, 10).is_err());
        let e = Camera::new(500.0, 500.0, 5.0, -100.0, 10, 10).unwrap_err();
        assert!(e.to_string().starts_with("cy:"));
    }

    #[test]
    fn presets_by_name() {
        for name in PRESETS {
            let cam = Camera::preset(name).unwrap();
            let ok = Camera::new(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height);
            assert_eq!(ok.unwrap(), cam, "{name}");
        }
        assert_eq!(Camera::preset("Kinect_V1").unwrap(), Camera::kinect_v1());
        assert_eq!(Camera::preset("itop").unwrap(), Camera::itop());
        let d435 = Camera::preset("realsense-d435").unwrap();
        assert_eq!((d435.width, d435.height), (640, 480));
        let e = Camera::preset("kinect-v3").unwrap_err().to_string();
        assert!(e.starts_with("name:") && e.contains("azure-kinect"), "{e}");
    }

    #[test]
    fn scaling_keeps_rays() {
        let cam = Camera::kinect_v1();
        let half = cam.scaled(0.5).unwrap();
        assert_eq!((half.width, half.height), (320, 240));
        // The centre of full-res pixel block (2u..2u+1) maps to half-res pixel u.
        let r1 = cam.ray(100.5, 60.5);
        let r2 = half.ray(50.0, 30.0);
        assert!((r1 - r2).norm() < 1e-9);
        // A factor that gives no camera is named, not the camera's fields.
        for factor in [1e308, 1e10, 0.0, f64::NAN] {
            let e = cam.scaled(factor).unwrap_err().to_string();
            assert!(e.starts_with("factor:"), "{e}");
        }
    }
}
