//! Images: 16-bit depth PNG/TIFF, float TIFF, and gray images for stereo. Decoding
//! uses the `image` crate (PNG, TIFF, JPEG only) and, for one-channel float TIFF, the
//! `tiff` crate.

use super::{check_depth_scale, check_size, existing, path_str, Image};
use crate::error::{brief, Error, Result};
use image::{DynamicImage, ImageDecoder, ImageError, ImageReader};
use std::path::Path;

fn decode_error(path: &Path, e: ImageError) -> Error {
    match e {
        ImageError::Limits(l) => Error::resource_limit(
            path_str(path),
            format!("decoding needs more memory than allowed ({})", plain(&l)),
        ),
        ImageError::Unsupported(u) => {
            Error::file(path_str(path), format!("unsupported image: {}", plain(&u)))
        }
        e => Error::file(
            path_str(path),
            format!("corrupt or truncated image: {}", plain(&e)),
        ),
    }
}

/// A decoder's message without the Rust debug output some of them append (`ChunkType {
/// type: IHDR, .. }`): cut at the first brace or line break, at most 160 characters.
fn plain(e: &dyn std::fmt::Display) -> String {
    let text = e.to_string();
    let cut = text.find(['{', '\n']).unwrap_or(text.len());
    let mut out: String = text[..cut].chars().take(160).collect();
    while out.ends_with([' ', ':', ',']) {
        out.pop();
    }
    out
}

fn open(path: &Path) -> Result<DynamicImage> {
    existing(path, "an image file")?;
    if let Some(img) = read_gray_float_tiff(path)? {
        return Ok(img);
    }
    let reader = ImageReader::open(path)
        .map_err(|e| Error::file(path_str(path), format!("cannot open: {e}")))?
        .with_guessed_format()
        .map_err(|e| Error::file(path_str(path), format!("cannot read: {e}")))?;
    if reader.format().is_none() {
        return Err(Error::file(
            path_str(path),
            "not a PNG, TIFF or JPEG image (unknown format)",
        ));
    }
    let decoder = reader.into_decoder().map_err(|e| decode_error(path, e))?;
    let (width, height) = decoder.dimensions();
    check_size(path, width.into(), height.into())?;
    DynamicImage::from_decoder(decoder).map_err(|e| decode_error(path, e))
}

/// A TIFF of one floating-point channel (32 or 64 bits), which the `image` crate does
/// not decode, as a [`DynamicImage::ImageRgb32F`] of equal channels (None for any
/// other file).
fn read_gray_float_tiff(path: &Path) -> Result<Option<DynamicImage>> {
    use tiff::decoder::{Decoder, DecodingResult};
    let mut magic = [0u8; 4];
    {
        use std::io::Read;
        let mut f = std::fs::File::open(path)
            .map_err(|e| Error::file(path_str(path), format!("cannot open: {e}")))?;
        if f.read_exact(&mut magic).is_err() {
            return Ok(None);
        }
    }
    if magic != *b"II*\0" && magic != *b"MM\0*" {
        return Ok(None);
    }
    let file = std::fs::File::open(path)
        .map_err(|e| Error::file(path_str(path), format!("cannot open: {e}")))?;
    let corrupt = |e: tiff::TiffError| match e {
        tiff::TiffError::LimitsExceeded => {
            Error::resource_limit(path_str(path), "decoding needs more memory than allowed")
        }
        e => Error::file(
            path_str(path),
            format!("corrupt or truncated image: {}", plain(&e)),
        ),
    };
    let Ok(mut dec) = Decoder::new(std::io::BufReader::new(file)) else {
        return Ok(None); // let the image crate report it
    };
    let gray = matches!(dec.colortype(), Ok(tiff::ColorType::Gray(32 | 64)));
    let (width, height) = dec.dimensions().map_err(corrupt)?;
    if !gray {
        return Ok(None);
    }
    check_size(path, width.into(), height.into())?;
    let values: Vec<f32> = match dec.read_image().map_err(corrupt)? {
        DecodingResult::F32(v) => v,
        DecodingResult::F64(v) => v.into_iter().map(|x| x as f32).collect(),
        // 32-bit integer gray: a float reader has no scale for it.
        _ => return Ok(None),
    };
    let n = width as usize * height as usize;
    if values.len() < n {
        return Err(Error::file(path_str(path), "truncated image data"));
    }
    let rgb: Vec<f32> = values[..n].iter().flat_map(|&v| [v, v, v]).collect();
    let buf = image::ImageBuffer::<image::Rgb<f32>, _>::from_raw(width, height, rgb)
        .ok_or_else(|| Error::file(path_str(path), "inconsistent image size"))?;
    Ok(Some(DynamicImage::ImageRgb32F(buf)))
}

/// Whether a float image's three channels are equal (a gray image read by
/// [`read_gray_float_tiff`] or stored as colour).
fn is_gray(buf: &image::Rgb32FImage) -> bool {
    buf.pixels()
        .all(|p| p[0].to_bits() == p[1].to_bits() && p[1].to_bits() == p[2].to_bits())
}

/// Reads a depth image: 16-bit gray PNG/TIFF (integer units times `scale` metres, so
/// millimetres with the default 0.001) or a one-channel 32/64-bit float TIFF (metres,
/// `scale` ignored). An 8-bit or colour image is refused: it cannot hold depth.
/// Float depth must not be negative or infinite (NaN and 0 mean "no reading").
pub fn read_depth_image(path: &Path, scale: f64) -> Result<Image> {
    check_depth_scale(scale)?;
    let img = open(path)?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    let data: Vec<f32> = match img {
        DynamicImage::ImageLuma16(buf) => buf
            .into_raw()
            .into_iter()
            .map(|v| (v as f64 * scale) as f32)
            .collect(),
        DynamicImage::ImageRgb32F(buf) if is_gray(&buf) => {
            let d: Vec<f32> = buf.pixels().map(|p| p[0]).collect();
            if let Some(k) = d.iter().position(|v| *v < 0.0 || v.is_infinite()) {
                return Err(Error::file(
                    path_str(path),
                    format!(
                        "depth holds {} at row {}, column {} (depth is >= 0 metres; NaN or 0 \
                         mean no reading)",
                        d[k],
                        k / width.max(1),
                        k % width.max(1)
                    ),
                ));
            }
            d
        }
        DynamicImage::ImageRgb32F(_) | DynamicImage::ImageRgba32F(_) => {
            return Err(Error::file(
                path_str(path),
                "a colour float image is not a depth image",
            ))
        }
        DynamicImage::ImageLuma8(_) | DynamicImage::ImageLumaA8(_) => {
            return Err(Error::file(
                path_str(path),
                "an 8-bit image cannot hold depth; depth PNGs are 16-bit (millimetres)",
            ))
        }
        other => {
            return Err(Error::file(
                path_str(path),
                format!(
                    "a {} image is not a depth image (need 16-bit gray or float)",
                    color_name(other.color())
                ),
            ))
        }
    };
    Ok(Image {
        data,
        height,
        width,
    })
}

/// A colour type as a message names it.
fn color_name(c: image::ColorType) -> &'static str {
    use image::ColorType as C;
    match c {
        C::L8 => "8-bit gray",
        C::La8 => "8-bit gray with alpha",
        C::Rgb8 => "8-bit RGB",
        C::Rgba8 => "8-bit RGBA",
        C::L16 => "16-bit gray",
        C::La16 => "16-bit gray with alpha",
        C::Rgb16 => "16-bit RGB",
        C::Rgba16 => "16-bit RGBA",
        C::Rgb32F => "float RGB",
        C::Rgba32F => "float RGBA",
        _ => "colour",
    }
}

/// Reads any PNG/TIFF/JPEG as gray float32: integer images scaled to [0, 1] by their
/// type's maximum, float images as stored, colour converted by luminance.
pub fn read_gray(path: &Path) -> Result<Image> {
    let img = open(path)?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    let data: Vec<f32> = match img {
        DynamicImage::ImageLuma8(b) => b.into_raw().into_iter().map(|v| v as f32 / 255.0).collect(),
        DynamicImage::ImageLuma16(b) => b
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 65535.0)
            .collect(),
        DynamicImage::ImageRgb32F(b) if is_gray(&b) => b.pixels().map(|p| p[0]).collect(),
        other => {
            let rgb = other.into_rgb32f();
            rgb.pixels()
                .map(|p| 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2])
                .collect()
        }
    };
    Ok(Image {
        data,
        height,
        width,
    })
}

/// Reads a float TIFF (e.g. Middlebury ground-truth disparity) as stored.
pub fn read_float(path: &Path) -> Result<Image> {
    let img = open(path)?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    let data = match img {
        DynamicImage::ImageRgb32F(b) => b.pixels().map(|p| p[0]).collect(),
        DynamicImage::ImageRgba32F(b) => b.pixels().map(|p| p[0]).collect(),
        other => other
            .into_luma16()
            .into_raw()
            .into_iter()
            .map(|v| v as f32)
            .collect(),
    };
    Ok(Image {
        data,
        height,
        width,
    })
}

/// Writes depth (metres) as a 16-bit PNG in units of `scale` metres. 0 and NaN (no
/// reading) are written as 0. A depth the file cannot store is refused, not clipped:
/// negative or infinite, above 65535 units (65.535 m in millimetres), or so small
/// that it would round to 0 units and read back as "no reading".
pub fn write_depth_png(
    path: &Path,
    depth: &[f32],
    height: usize,
    width: usize,
    scale: f64,
) -> Result<()> {
    check_depth_scale(scale)?;
    let (w, h) = (u32::try_from(width), u32::try_from(height));
    if depth.len() != height.saturating_mul(width) || height == 0 || width == 0 {
        return Err(Error::invalid(
            "depth",
            format!(
                "{} values do not make a {height}x{width} image",
                depth.len()
            ),
        ));
    }
    let (Ok(w), Ok(h)) = (w, h) else {
        return Err(Error::resource_limit(
            "depth",
            format!("an image of {height}x{width} pixels is too large for a PNG"),
        ));
    };
    check_size(path, w.into(), h.into())?;
    let mut raw = Vec::with_capacity(depth.len());
    for (k, &z) in depth.iter().enumerate() {
        if z.is_nan() || z == 0.0 {
            raw.push(0);
            continue;
        }
        let v = (z as f64 / scale).round();
        if !(z > 0.0 && v >= 1.0 && v <= u16::MAX as f64) {
            let why = if z < 0.0 || z.is_infinite() {
                "depth must be >= 0 and finite (0 or NaN for no reading)".to_string()
            } else if v < 1.0 {
                format!(
                    "it rounds to 0 units of {} m, which reads back as no reading",
                    brief(scale)
                )
            } else {
                format!(
                    "a 16-bit PNG stores at most 65535 units of {} m = {} m; pass a larger \
                     scale or write .npy/.pfm (float metres)",
                    brief(scale),
                    brief(u16::MAX as f64 * scale)
                )
            };
            return Err(Error::invalid(
                "depth",
                format!(
                    "{} m at row {}, column {} cannot be stored: {why}",
                    brief(z as f64),
                    k / width,
                    k % width
                ),
            ));
        }
        raw.push(v as u16);
    }
    let buf = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, raw)
        .ok_or_else(|| Error::invalid("depth", "inconsistent image size"))?;
    buf.save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| Error::file(path_str(path), format!("cannot write: {e}")))
}

/// Writes an 8-bit RGB picture (row-major, 3 bytes a pixel) as PNG.
pub fn write_rgb_png(path: &Path, rgb: &[u8], height: usize, width: usize) -> Result<()> {
    let size = height.checked_mul(width).and_then(|p| p.checked_mul(3));
    if size != Some(rgb.len()) || height == 0 || width == 0 {
        return Err(Error::invalid(
            "image",
            format!(
                "{} bytes do not make a {height}x{width} RGB image",
                rgb.len()
            ),
        ));
    }
    let (Ok(w), Ok(h)) = (u32::try_from(width), u32::try_from(height)) else {
        return Err(Error::resource_limit(
            "image",
            format!("an image of {height}x{width} pixels is too large for a PNG"),
        ));
    };
    check_size(path, w.into(), h.into())?;
    image::save_buffer_with_format(
        path,
        rgb,
        w,
        h,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .map_err(|e| Error::file(path_str(path), format!("cannot write: {e}")))
}

#[cfg(test)]
mod tests {
    use super::super::tests::{fuzz_cases, temp_dir};
    use super::super::MAX_IMAGE_PIXELS;
    use super::*;

    #[test]
    fn depth_png_round_trip() {
        let dir = temp_dir("png");
        let p = dir.join("d.png");
        let depth = vec![0.0, 1.234, 2.5, f32::NAN, 65.535, 3.0];
        write_depth_png(&p, &depth, 2, 3, 0.001).unwrap();
        let back = read_depth_image(&p, 0.001).unwrap();
        assert_eq!((back.height, back.width), (2, 3));
        let want = [0.0, 1.234, 2.5, 0.0, 65.535, 3.0];
        for (a, b) in back.data.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
        // An 8-bit picture is refused as depth but reads as gray.
        let q = dir.join("g.png");
        write_rgb_png(&q, &[255u8; 18], 2, 3).unwrap();
        assert!(read_depth_image(&q, 0.001)
            .unwrap_err()
            .to_string()
            .contains("not a depth image"));
        let g = read_gray(&q).unwrap();
        assert!(g.data.iter().all(|&v| (v - 1.0).abs() < 1e-5));
        // Truncated file.
        let bytes = std::fs::read(&p).unwrap();
        let t = dir.join("t.png");
        std::fs::write(&t, &bytes[..bytes.len() / 2]).unwrap();
        assert!(read_depth_image(&t, 0.001)
            .unwrap_err()
            .to_string()
            .contains("corrupt"));
        assert!(matches!(
            read_depth_image(&dir.join("missing.png"), 0.001),
            Err(Error::NotFound { .. })
        ));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn depth_png_refuses_what_it_cannot_store() {
        let dir = temp_dir("refuse");
        let p = dir.join("d.png");
        for (z, what) in [
            (65.6, "65535 units"),
            (0.0004, "rounds to 0"),
            (-1.0, ">= 0"),
        ] {
            let e = write_depth_png(&p, &[1.0, z], 1, 2, 0.001).unwrap_err();
            assert!(e.to_string().contains(what), "{z}: {e}");
        }
        assert!(write_depth_png(&p, &[f32::INFINITY], 1, 1, 0.001).is_err());
        // A larger scale stores it; NaN is written as 0 (no reading).
        write_depth_png(&p, &[65.6, f32::NAN], 1, 2, 0.01).unwrap();
        let back = read_depth_image(&p, 0.01).unwrap();
        assert!((back.data[0] - 65.6).abs() < 1e-4 && back.data[1] == 0.0);
        for scale in [0.0, -1.0, 1e-9, 10.0, f64::NAN] {
            assert!(write_depth_png(&p, &[1.0], 1, 1, scale).is_err(), "{scale}");
            assert!(read_depth_image(&p, scale).is_err(), "{scale}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn gray_float_tiff_is_depth() {
        let dir = temp_dir("tiff");
        let p = dir.join("d.tif");
        let depth = [0.0f32, 1.5, f32::NAN, 2.25, 7.0, 0.5];
        write_gray_f32_tiff(&p, &depth, 3, 2);
        for img in [
            read_depth_image(&p, 0.001).unwrap(),
            read_float(&p).unwrap(),
        ] {
            assert_eq!((img.height, img.width), (2, 3));
            for (a, b) in img.data.iter().zip(depth) {
                assert!(a == &b || (a.is_nan() && b.is_nan()), "{a} vs {b}");
            }
        }
        assert_eq!(read_gray(&p).unwrap().data[1], 1.5);
        write_gray_f32_tiff(&p, &[1.0, -2.0], 2, 1);
        assert!(read_depth_image(&p, 0.001)
            .unwrap_err()
            .to_string()
            .contains("-2"));
        std::fs::remove_dir_all(&dir).ok();
    }

    fn write_gray_f32_tiff(path: &Path, data: &[f32], width: u32, height: u32) {
        let f = std::fs::File::create(path).unwrap();
        let mut enc = tiff::encoder::TiffEncoder::new(f).unwrap();
        enc.write_image::<tiff::encoder::colortype::Gray32Float>(width, height, data)
            .unwrap();
    }

    /// Valid files of every kind the readers take, as bytes: 16-bit PNG, 8-bit RGB PNG,
    /// 16-bit TIFF, float TIFF.
    fn seed_files(dir: &Path) -> Vec<Vec<u8>> {
        let depth: Vec<f32> = (0..12).map(|k| 0.5 + 0.25 * k as f32).collect();
        let p = dir.join("seed.png");
        write_depth_png(&p, &depth, 3, 4, 0.001).unwrap();
        let mut out = vec![std::fs::read(&p).unwrap()];
        write_rgb_png(&p, &[7u8; 36], 3, 4).unwrap();
        out.push(std::fs::read(&p).unwrap());
        let t = dir.join("seed.tif");
        let f = std::fs::File::create(&t).unwrap();
        let raw: Vec<u16> = (0..12).map(|k| 500 + 100 * k).collect();
        tiff::encoder::TiffEncoder::new(f)
            .unwrap()
            .write_image::<tiff::encoder::colortype::Gray16>(4, 3, &raw)
            .unwrap();
        out.push(std::fs::read(&t).unwrap());
        write_gray_f32_tiff(&t, &depth, 4, 3);
        out.push(std::fs::read(&t).unwrap());
        out
    }

    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(fuzz_cases(64)))]

        /// Corrupt, truncated and random files: every reader returns an image whose
        /// size matches its data, or an error; none panics or allocates beyond the
        /// limits (a header claiming a huge image is refused before decoding).
        #[test]
        fn readers_survive_corrupt_files(
            seed in 0usize..4,
            edits in proptest::collection::vec((any::<u16>(), any::<u8>()), 0..12),
            cut in proptest::option::of(any::<u16>()),
            random in proptest::option::of(proptest::collection::vec(any::<u8>(), 0..300)),
        ) {
            let dir = temp_dir("fuzz");
            let mut bytes = match random {
                Some(r) => r,
                None => seed_files(&dir).swap_remove(seed),
            };
            for (at, value) in edits {
                if !bytes.is_empty() {
                    let k = at as usize % bytes.len();
                    bytes[k] = value;
                }
            }
            if let Some(c) = cut {
                bytes.truncate(c as usize % (bytes.len() + 1));
            }
            for name in ["f.png", "f.tif"] {
                let p = dir.join(name);
                std::fs::write(&p, &bytes).unwrap();
                for r in [read_depth_image(&p, 0.001), read_gray(&p), read_float(&p)] {
                    match r {
                        Ok(img) => {
                            prop_assert_eq!(img.data.len(), img.height * img.width);
                            prop_assert!(img.height * img.width <= MAX_IMAGE_PIXELS);
                        }
                        Err(Error::File { .. } | Error::ResourceLimit { .. }) => {}
                        Err(e) => prop_assert!(false, "unexpected error {e:?}"),
                    }
                }
            }
            std::fs::remove_dir_all(&dir).ok();
        }

        /// What the PNG writer accepts reads back to within half a unit; what it
        /// refuses is beyond its range.
        #[test]
        fn depth_png_round_trips_or_refuses(
            depth in proptest::collection::vec(
                prop_oneof![Just(0.0f32), Just(f32::NAN), 0.0f32..70.0, 0.0f32..0.001],
                1..40,
            ),
            scale in prop_oneof![Just(0.001), 1e-4f64..0.01],
        ) {
            let dir = temp_dir("roundtrip");
            let p = dir.join("d.png");
            let w = depth.len();
            match write_depth_png(&p, &depth, 1, w, scale) {
                Ok(()) => {
                    let back = read_depth_image(&p, scale).unwrap();
                    for (&a, &z) in back.data.iter().zip(&depth) {
                        let want = if z.is_nan() { 0.0 } else { z as f64 };
                        prop_assert!((a as f64 - want).abs() <= 0.5 * scale + 1e-6 * want);
                    }
                }
                Err(Error::InvalidArgument { name, .. }) => {
                    prop_assert_eq!(name, "depth");
                    let unstorable = |z: f32| {
                        let v = (z as f64 / scale).round();
                        z > 0.0 && !(1.0..=65535.0).contains(&v)
                    };
                    prop_assert!(depth.iter().any(|&z| unstorable(z)));
                }
                Err(e) => prop_assert!(false, "unexpected error {e:?}"),
            }
            std::fs::remove_dir_all(&dir).ok();
        }
    }
}
