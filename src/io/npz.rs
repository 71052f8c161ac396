//! numpy's `.npz` archives: a zip file of `.npy` arrays, one entry `<key>.npy` per
//! array (`numpy.savez` stores them, `numpy.savez_compressed` deflates them). The
//! `zip` crate reads and writes the archive; [`super::npy`] the arrays inside.
//!
//! Every entry is checked before any array is read: its `.npy` header parses, it holds
//! no Python objects, and its size is what its header's shape and dtype need. Errors
//! name the file and say what it is not (`what`: "a template database", "a depth
//! sequence", ...).

use super::npy::{self, Kind};
use super::{existing, io_error, path_str};
use crate::error::{Error, Result};
use std::io::{BufReader, BufWriter, Read};
use std::path::Path;

/// An entry of an archive: its key, its `.npy` header and, when asked for, its data.
#[derive(Debug, Clone)]
pub struct Entry {
    pub key: String,
    pub header: npy::Header,
    pub data: Option<Vec<u8>>,
}

impl Entry {
    /// The entry as an array, when its data was read.
    pub fn into_array(self) -> Option<npy::Array> {
        let npy::Header {
            dtype,
            shape,
            fortran,
            ..
        } = self.header;
        Some(npy::Array {
            dtype,
            shape,
            fortran,
            data: self.data?,
        })
    }
}

/// Reads the arrays of the archive at `path`, in the archive's order: all of them, or
/// those whose key is in `keys`. `what` names what the file should be in errors.
pub fn read(path: &Path, what: &str, keys: Option<&[String]>) -> Result<Vec<(String, npy::Array)>> {
    let wanted = |key: &str| keys.is_none_or(|keys| keys.iter().any(|k| k == key));
    let entries = read_entries(path, what, &wanted)?;
    Ok(entries
        .into_iter()
        .filter_map(|e| Some((e.key.clone(), e.into_array()?)))
        .collect())
}

/// Every entry of the archive at `path` with its header, each checked as [`read`]
/// checks it; the data of those for whose key `wanted` is true (the others' data is
/// not read, so a caller learns an array's shape and dtype without its bytes).
pub fn read_entries(path: &Path, what: &str, wanted: &dyn Fn(&str) -> bool) -> Result<Vec<Entry>> {
    existing(path, what)?;
    let not = |why: String| Error::file(path_str(path), format!("not {what} ({why})"));
    let file = std::fs::File::open(path).map_err(|e| io_error(path, "read", e))?;
    let mut zip = zip::ZipArchive::new(BufReader::new(file))
        .map_err(|_| not("not a zip archive of numpy arrays".into()))?;
    let mut out = Vec::new();
    for k in 0..zip.len() {
        let mut entry = zip.by_index(k).map_err(|e| not(e.to_string()))?;
        let name = entry.name().map_err(|e| not(e.to_string()))?;
        let Some(key) = name.strip_suffix(".npy").map(str::to_string) else {
            continue;
        };
        let entry_err =
            |why: &str| Error::file(path_str(path), format!("entry '{key}' {why}; not {what}"));
        let header =
            npy::read_header(&mut entry).map_err(|m| entry_err(&format!("is bad: {m}")))?;
        if header.dtype.kind == Kind::Object {
            return Err(entry_err("holds Python objects"));
        }
        if header.data_offset.checked_add(header.data_bytes) != Some(entry.size()) {
            return Err(entry_err(&format!(
                "is truncated or corrupt (shape {} needs {} bytes)",
                npy::shape_text(&header.shape),
                header.data_bytes
            )));
        }
        let data = if wanted(&key) {
            let data = npy::read_data(&mut entry, &header)
                .map_err(|m| entry_err(&format!("is unreadable: {m}")))?;
            // Reading on to the end checks the entry's checksum.
            let mut rest = Vec::new();
            entry
                .read_to_end(&mut rest)
                .map_err(|e| entry_err(&format!("is corrupt: {e}")))?;
            Some(data)
        } else {
            None
        };
        out.push(Entry { key, header, data });
    }
    Ok(out)
}

/// Writes `arrays` (key, array) as an uncompressed archive, as `numpy.savez` does: to
/// a temporary file beside `path` first, synced, then renamed to it, so that a reader
/// never sees half a file.
pub fn write(path: &Path, arrays: &[(&str, &npy::Array)]) -> Result<()> {
    let Some(name) = path.file_name() else {
        return Err(Error::invalid(
            "path",
            format!("{:?} names no file", path_str(path)),
        ));
    };
    let mut tmp_name = name.to_os_string();
    tmp_name.push(format!(".{}.tmp", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    let written = write_archive(&tmp, arrays).and_then(|()| std::fs::rename(&tmp, path));
    written.map_err(|e| {
        std::fs::remove_file(&tmp).ok();
        io_error(path, "write", e)
    })
}

fn write_archive(path: &Path, arrays: &[(&str, &npy::Array)]) -> std::io::Result<()> {
    let mut zip = zip::ZipWriter::new(BufWriter::new(std::fs::File::create(path)?));
    for (key, array) in arrays {
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored)
            .large_file(array.data.len() > u32::MAX as usize / 2);
        zip.start_file(format!("{key}.npy"), options)?;
        npy::write_to(&mut zip, array)?;
    }
    let file = zip.finish()?.into_inner().map_err(|e| e.into_error())?;
    // On disk before the rename, so that a crash leaves the old file or the new one.
    file.sync_all()
}

#[cfg(test)]
mod tests {
    use super::super::npy::{Array, Dtype};
    use super::super::tests::temp_dir;
    use super::*;

    fn arrays() -> Vec<(&'static str, Array)> {
        vec![
            (
                "depth",
                Array::of(
                    Dtype::F32,
                    vec![2, 1, 2],
                    &[1.0f32, 2.0, 3.0, f32::NAN],
                    f32::to_le_bytes,
                ),
            ),
            (
                "counts",
                Array::of(Dtype::I64, vec![3], &[1i64, -2, 3], i64::to_le_bytes),
            ),
            (
                "version",
                Array::of(Dtype::I64, vec![], &[7i64], i64::to_le_bytes),
            ),
            ("hash", Array::text("00ff")),
        ]
    }

    #[test]
    fn round_trip_is_exact() {
        let dir = temp_dir("npz");
        let p = dir.join("a.npz");
        let a = arrays();
        let refs: Vec<(&str, &Array)> = a.iter().map(|(k, v)| (*k, v)).collect();
        write(&p, &refs).unwrap();
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            1,
            "no temporary file left"
        );
        let back = read(&p, "an archive", None).unwrap();
        assert_eq!(back.len(), 4);
        for ((k, v), (bk, bv)) in a.iter().zip(&back) {
            assert_eq!((*k, v), (bk.as_str(), bv));
        }
        let some = read(&p, "an archive", Some(&["hash".to_string()])).unwrap();
        assert_eq!(some.len(), 1);
        assert_eq!(some[0].1.data, b"0\0\0\x000\0\0\0f\0\0\0f\0\0\0");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn hostile_archives_are_clear_errors() {
        let dir = temp_dir("npz-hostile");
        let p = dir.join("a.npz");
        let a = arrays();
        let refs: Vec<(&str, &Array)> = a.iter().map(|(k, v)| (*k, v)).collect();
        write(&p, &refs).unwrap();
        let good = std::fs::read(&p).unwrap();
        let q = dir.join("bad.npz");
        let check = |bytes: &[u8], want: &str| {
            std::fs::write(&q, bytes).unwrap();
            let e = read(&q, "a test archive", None).unwrap_err().to_string();
            assert!(
                e.contains("bad.npz") && e.contains("not a test archive"),
                "{e}"
            );
            assert!(e.contains(want), "{want}: {e}");
        };
        check(b"", "not a zip archive");
        check(&good[..good.len() / 2], "not a zip archive");
        check(b"PK\x03\x04 not really", "not a zip archive");
        // An object array.
        let obj = Array {
            dtype: Dtype::parse("|O").unwrap(),
            shape: vec![1],
            fortran: false,
            data: vec![0; 8],
        };
        write(&q, &[("o", &obj)]).unwrap();
        let e = read(&q, "x", None).unwrap_err().to_string();
        assert!(e.contains("entry 'o' holds Python objects; not x"), "{e}");
        // A header claiming more data than the entry holds.
        let short = Array {
            data: vec![0; 4],
            ..Array::of(Dtype::F32, vec![1 << 40], &[0f32], f32::to_le_bytes)
        };
        write(&q, &[("s", &short)]).unwrap();
        let e = read(&q, "x", None).unwrap_err().to_string();
        assert!(e.contains("entry 's' is truncated or corrupt"), "{e}");
        // A flipped byte in the data: the checksum fails.
        let mut flipped = good.clone();
        let at = good
            .windows(4)
            .position(|w| w == [0, 0, 0x80, 0x3f])
            .unwrap();
        flipped[at + 3] ^= 1;
        check(&flipped, "corrupt");
        assert!(matches!(
            read(&dir.join("none.npz"), "x", None),
            Err(Error::NotFound { .. })
        ));
        std::fs::remove_dir_all(&dir).ok();
    }
}
