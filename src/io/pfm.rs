//! Portable float maps (`.pfm`): the magic `Pf` (one channel) or `PF` (three), the
//! width, the height and a scale whose sign gives the byte order (negative: little
//! endian), separated by white space, then one white space character and the pixels
//! as 32-bit floats, bottom row first. Readers keep the first channel, top row first;
//! the writer writes one little-endian channel.

use super::{check_size, existing, io_error, path_str, Image};
use crate::error::{brief, Error, Result};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::Path;

/// Bytes of a file the header is read from: four short fields fit many times over.
const HEADER_BYTES: usize = 256;
/// Longest field of a header, in bytes.
const MAX_FIELD: usize = 64;

/// What a PFM header says.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Header {
    pub width: usize,
    pub height: usize,
    /// 1 (`Pf`) or 3 (`PF`).
    pub channels: usize,
    pub little_endian: bool,
    /// Where the pixels start.
    pub offset: usize,
}

/// The header at the start of `data`, or why it is not one (a message without the
/// file's name). The image's size is not checked against the limits here.
pub fn parse_header(data: &[u8]) -> std::result::Result<Header, String> {
    let mut fields: Vec<&[u8]> = Vec::with_capacity(4);
    let mut pos = 0;
    while fields.len() < 4 {
        while pos < data.len() && is_space(data[pos]) {
            pos += 1;
        }
        let start = pos;
        while pos < data.len() && !is_space(data[pos]) && pos - start < MAX_FIELD {
            pos += 1;
        }
        if pos == start || pos >= data.len() {
            return Err("truncated PFM header".into());
        }
        fields.push(&data[start..pos]);
    }
    let channels = match fields[0] {
        b"Pf" => 1,
        b"PF" => 3,
        magic => {
            let shown = String::from_utf8_lossy(&magic[..magic.len().min(8)]).into_owned();
            return Err(format!("not a PFM file (header {shown:?})"));
        }
    };
    let text = |f: &[u8]| String::from_utf8_lossy(f).into_owned();
    let (Ok(width), Ok(height), Ok(scale)) = (
        text(fields[1]).parse::<i64>(),
        text(fields[2]).parse::<i64>(),
        text(fields[3]).parse::<f64>(),
    ) else {
        return Err("corrupt PFM header".into());
    };
    if width <= 0 || height <= 0 || !scale.is_finite() || scale == 0.0 {
        return Err(format!(
            "corrupt PFM header (size {width}x{height}, scale {})",
            brief(scale)
        ));
    }
    Ok(Header {
        width: width as usize,
        height: height as usize,
        channels,
        little_endian: scale < 0.0,
        offset: pos + 1,
    })
}

/// White space as the header separates its fields.
fn is_space(b: u8) -> bool {
    b.is_ascii_whitespace() || b == 0x0b
}

/// Reads a PFM image: its first channel as `f32`, top row first. The header is
/// checked (and the size against [`super::MAX_IMAGE_PIXELS`]) before the pixels are
/// read.
pub fn read(path: &Path) -> Result<Image> {
    let len = existing(path, "an image file")?;
    let mut f = std::fs::File::open(path).map_err(|e| io_error(path, "read", e))?;
    let mut head = Vec::with_capacity(HEADER_BYTES);
    (&mut f)
        .take(HEADER_BYTES as u64)
        .read_to_end(&mut head)
        .map_err(|e| io_error(path, "read", e))?;
    let h = parse_header(&head).map_err(|m| Error::file(path_str(path), m))?;
    check_size(path, h.width as u64, h.height as u64)?;
    let count = h.width * h.height * h.channels;
    let available = len.saturating_sub(h.offset as u64) / 4;
    if available < count as u64 {
        return Err(Error::file(
            path_str(path),
            format!("truncated PFM ({available} of {count} values)"),
        ));
    }
    f.seek(SeekFrom::Start(h.offset as u64))
        .map_err(|e| io_error(path, "read", e))?;
    let mut raw = vec![0u8; 4 * count];
    f.read_exact(&mut raw)
        .map_err(|_| Error::file(path_str(path), "truncated PFM (the file shrank while read)"))?;
    let value = |k: usize| {
        let b: [u8; 4] = raw[4 * k..4 * k + 4].try_into().unwrap_or_default();
        if h.little_endian {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let mut data = Vec::with_capacity(h.width * h.height);
    for row in (0..h.height).rev() {
        data.extend((0..h.width).map(|col| value((row * h.width + col) * h.channels)));
    }
    Ok(Image {
        data,
        height: h.height,
        width: h.width,
    })
}

/// Writes a one-channel image as a little-endian PFM (`Pf`, scale -1), bottom row
/// first; NaN and infinities are stored as they are.
pub fn write(path: &Path, image: &Image) -> Result<()> {
    if image.height == 0 || image.width == 0 || image.data.len() != image.height * image.width {
        return Err(Error::invalid(
            "image",
            format!(
                "{} values do not make a non-empty {}x{} image",
                image.data.len(),
                image.height,
                image.width
            ),
        ));
    }
    check_size(path, image.width as u64, image.height as u64)?;
    let mut out = format!("Pf\n{} {}\n-1.0\n", image.width, image.height).into_bytes();
    out.reserve(4 * image.data.len());
    for row in image.data.chunks_exact(image.width).rev() {
        for v in row {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::File::create(path)
        .and_then(|mut f| f.write_all(&out))
        .map_err(|e| io_error(path, "write", e))
}

#[cfg(test)]
mod tests {
    use super::super::tests::{fuzz_cases, temp_dir};
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn round_trip_is_exact() {
        let dir = temp_dir("pfm");
        let p = dir.join("x.pfm");
        let img = Image {
            data: vec![1.5, f32::NAN, f32::INFINITY, -0.0, 1e-40, -7.25],
            height: 3,
            width: 2,
        };
        write(&p, &img).unwrap();
        assert!(std::fs::read(&p).unwrap().starts_with(b"Pf\n2 3\n-1.0\n"));
        let back = read(&p).unwrap();
        assert_eq!((back.height, back.width), (3, 2));
        for (a, b) in back.data.iter().zip(&img.data) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn colour_and_big_endian_files_read_their_first_channel() {
        let dir = temp_dir("pfm-colour");
        let p = dir.join("c.pfm");
        let mut bytes = b"PF 2 1 1.0\n".to_vec();
        for v in [1.0f32, 9.0, 9.0, 2.0, 9.0, 9.0] {
            bytes.extend_from_slice(&v.to_be_bytes());
        }
        std::fs::write(&p, &bytes).unwrap();
        assert_eq!(read(&p).unwrap().data, vec![1.0, 2.0]);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn hostile_headers_are_clear_errors() {
        for (head, want) in [
            (&b"Pf\n10 10\n"[..], "truncated PFM header"),
            (b"P6\n1 1\n-1.0\n", "not a PFM file"),
            (b"Pf\nten 10\n-1.0\n", "corrupt PFM header"),
            (b"Pf\n0 10\n-1.0\n", "size 0x10"),
            (b"Pf\n1 1\nnan\n", "scale NaN"),
            (b"Pf\n1 1\n0\n", "corrupt PFM header"),
        ] {
            let e = parse_header(head).unwrap_err();
            assert!(e.contains(want), "{head:?}: {e}");
        }
        let dir = temp_dir("pfm-hostile");
        let p = dir.join("h.pfm");
        std::fs::write(&p, b"Pf\n10 10\n-1.0\n\0\0\0\0\0\0\0\0\0\0\0\0").unwrap();
        let e = read(&p).unwrap_err().to_string();
        assert!(e.contains("truncated PFM (3 of 100 values)"), "{e}");
        std::fs::write(&p, b"Pf\n100000 100000\n-1.0\n").unwrap();
        assert!(matches!(read(&p), Err(Error::ResourceLimit { .. })));
        std::fs::remove_dir_all(&dir).ok();
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(fuzz_cases(256)))]

        /// Any bytes: a header whose fields are in range, or an error; no panic.
        #[test]
        fn header_parser_survives_any_bytes(data in proptest::collection::vec(any::<u8>(), 0..80)) {
            if let Ok(h) = parse_header(&data) {
                prop_assert!(h.width > 0 && h.height > 0 && h.offset <= data.len());
            }
        }

        /// Headers with numbers of any size: no panic, no overflow.
        #[test]
        fn header_numbers_of_any_size(w in any::<i64>(), h in any::<i64>(), s in any::<f64>()) {
            let text = format!("Pf\n{w} {h}\n{s}\n");
            if let Ok(head) = parse_header(text.as_bytes()) {
                prop_assert_eq!((head.width as i64, head.height as i64), (w, h));
            }
        }
    }
}
