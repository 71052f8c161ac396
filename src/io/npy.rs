//! numpy's array file format (`.npy`), after the format's specification
//! (`numpy.lib.format`, NEP 1): the magic `\x93NUMPY`, a major and minor version
//! byte, the header's length (2 bytes little-endian in version 1, 4 bytes in versions
//! 2 and 3), then the header, a Python dict literal with the keys `'descr'` (the
//! dtype), `'fortran_order'` and `'shape'`, padded with spaces and ended by a newline;
//! then the elements, in C or Fortran order.
//!
//! The header is parsed here, never evaluated: only a dict of those three keys with a
//! plain dtype string, a bool and a tuple of integers is accepted. Plain dtypes are
//! read (bool, integers, floats, complex, fixed-width strings, either byte order);
//! a Python-object array is recognised so that callers refuse it by name, and
//! structured dtypes are refused. Sizes are checked before anything is allocated.

use super::{check_depth, check_size, existing, io_error, path_str, Image};
use crate::error::{Error, Result};
use std::io::{Read, Write};
use std::path::Path;

/// The first bytes of every `.npy` file.
pub const MAGIC: &[u8; 6] = b"\x93NUMPY";
/// Longest header read, in bytes (numpy's own default limit).
pub const MAX_HEADER_BYTES: usize = 10_000;
/// Most dimensions of an array (numpy's limit).
const MAX_DIMS: usize = 64;

/// What kind of values a dtype holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Bool,
    Int,
    Uint,
    Float,
    Complex,
    /// Fixed-width UCS-4 strings (`U`), 4 bytes a character.
    Unicode,
    /// Fixed-width byte strings (`S`).
    Bytes,
    /// Python objects (`O`), which a file cannot hold without pickles.
    Object,
}

/// A plain dtype: its kind, its size in bytes and its byte order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dtype {
    pub kind: Kind,
    /// Bytes an element.
    pub size: usize,
    pub big_endian: bool,
}

impl Dtype {
    /// Little-endian `f32`, `f64` and `i64`, and 1-byte `u8`.
    pub const F32: Dtype = Dtype::little(Kind::Float, 4);
    pub const F64: Dtype = Dtype::little(Kind::Float, 8);
    pub const I64: Dtype = Dtype::little(Kind::Int, 8);

    const fn little(kind: Kind, size: usize) -> Dtype {
        Dtype {
            kind,
            size,
            big_endian: false,
        }
    }

    /// The dtype of a `descr` string such as `<f4`, `|b1`, `>u2` or `<U16`.
    pub fn parse(descr: &str) -> std::result::Result<Dtype, String> {
        let unsupported = || format!("unsupported dtype {descr:?}");
        let (order, rest) = match descr.as_bytes().first() {
            Some(b'<' | b'|') => (false, &descr[1..]),
            Some(b'>') => (true, &descr[1..]),
            Some(b'=') => (cfg!(target_endian = "big"), &descr[1..]),
            _ => (false, descr),
        };
        let code = rest.chars().next().ok_or_else(unsupported)?;
        let digits = &rest[code.len_utf8()..];
        if code == 'O' && (digits.is_empty() || digits == "8") {
            return Ok(Dtype::little(Kind::Object, 8));
        }
        if digits.is_empty() || digits.len() > 6 || !digits.bytes().all(|b| b.is_ascii_digit()) {
            return Err(unsupported());
        }
        let n: usize = digits.parse().map_err(|_| unsupported())?;
        let (kind, size) = match (code, n) {
            ('b', 1) => (Kind::Bool, 1),
            ('i', 1 | 2 | 4 | 8) => (Kind::Int, n),
            ('u', 1 | 2 | 4 | 8) => (Kind::Uint, n),
            ('f', 2 | 4 | 8) => (Kind::Float, n),
            ('c', 8 | 16) => (Kind::Complex, n),
            ('U', 1..) => (Kind::Unicode, 4 * n),
            ('S', 1..) => (Kind::Bytes, n),
            _ => return Err(unsupported()),
        };
        Ok(Dtype {
            kind,
            size,
            big_endian: order && size > 1 && kind != Kind::Bytes,
        })
    }

    /// The dtype as a header writes it (`<f4`, `|u1`, `<U16`).
    pub fn descr(&self) -> String {
        let (code, n) = match self.kind {
            Kind::Bool => ('b', self.size),
            Kind::Int => ('i', self.size),
            Kind::Uint => ('u', self.size),
            Kind::Float => ('f', self.size),
            Kind::Complex => ('c', self.size),
            Kind::Unicode => ('U', self.size / 4),
            Kind::Bytes => ('S', self.size),
            Kind::Object => ('O', 0),
        };
        let order = if self.big_endian {
            '>'
        } else if self.size == 1 || matches!(self.kind, Kind::Bytes | Kind::Object) {
            '|'
        } else {
            '<'
        };
        match self.kind {
            Kind::Object => "|O".into(),
            _ => format!("{order}{code}{n}"),
        }
    }

    /// The dtype as numpy names it in messages (`float32`, `uint16`, `>f4`, `<U16`).
    pub fn name(&self) -> String {
        let bits = 8 * self.size;
        match self.kind {
            _ if self.big_endian => self.descr(),
            Kind::Bool => "bool".into(),
            Kind::Int => format!("int{bits}"),
            Kind::Uint => format!("uint{bits}"),
            Kind::Float => format!("float{bits}"),
            Kind::Complex => format!("complex{bits}"),
            Kind::Object => "object".into(),
            Kind::Unicode | Kind::Bytes => self.descr(),
        }
    }
}

/// What a `.npy` header says.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    pub dtype: Dtype,
    pub shape: Vec<usize>,
    pub fortran: bool,
    /// Bytes of the elements (checked not to overflow).
    pub data_bytes: u64,
    /// Bytes from the start of the file to the elements.
    pub data_offset: u64,
}

/// An array as a file holds it: the elements' bytes in the file's order and dtype.
#[derive(Debug, Clone, PartialEq)]
pub struct Array {
    pub dtype: Dtype,
    pub shape: Vec<usize>,
    pub fortran: bool,
    pub data: Vec<u8>,
}

impl Array {
    /// A C-order little-endian array of `f32` values.
    pub fn from_f32(values: &[f32], height: usize, width: usize) -> Array {
        Array::of(Dtype::F32, vec![height, width], values, |v| v.to_le_bytes())
    }

    /// A C-order little-endian array of `shape` from values of any plain type (`bytes`
    /// gives one value's little-endian bytes).
    pub fn of<T: Copy, const N: usize>(
        dtype: Dtype,
        shape: Vec<usize>,
        values: &[T],
        bytes: impl Fn(T) -> [u8; N],
    ) -> Array {
        Array {
            dtype,
            shape,
            fortran: false,
            data: values.iter().flat_map(|&v| bytes(v)).collect(),
        }
    }

    /// A 0-d array holding `text` as numpy stores a Python `str` (UCS-4).
    pub fn text(text: &str) -> Array {
        let n = text.chars().count().max(1);
        let mut data: Vec<u8> = text
            .chars()
            .flat_map(|c| (c as u32).to_le_bytes())
            .collect();
        data.resize(4 * n, 0);
        Array {
            dtype: Dtype::little(Kind::Unicode, 4 * n),
            shape: vec![],
            fortran: false,
            data,
        }
    }
}

impl Array {
    /// Number of elements (the product of the shape).
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }

    /// Whether the array holds no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The data index of each C-order index (the last axis fastest): the index itself
    /// for C-order data, else its Fortran-order offset (the strides computed once).
    fn data_index(&self) -> impl Fn(usize) -> usize + '_ {
        let strides: Option<Vec<usize>> = (self.fortran && self.shape.len() > 1).then(|| {
            let mut stride = 1;
            self.shape
                .iter()
                .map(|&n| {
                    let s = stride;
                    stride *= n;
                    s
                })
                .collect()
        });
        move |k| match &strides {
            None => k,
            Some(strides) => {
                let (mut rest, mut at) = (k, 0);
                for (s, &n) in strides.iter().zip(&self.shape).rev() {
                    at += (rest % n.max(1)) * s;
                    rest /= n.max(1);
                }
                at
            }
        }
    }

    /// The element at data index `at` as 8 little-endian bytes, zero-extended; `None`
    /// past the end of the data.
    fn element(&self, at: usize) -> Option<[u8; 8]> {
        let d = self.dtype;
        let bytes = self.data.get(at * d.size..(at + 1) * d.size)?;
        let mut le = [0u8; 8];
        le.get_mut(..d.size)?.copy_from_slice(bytes);
        if d.big_endian {
            le[..d.size].reverse();
        }
        Some(le)
    }

    /// The elements in C order as `f64` (booleans and integers as numbers); `None`
    /// for text, complex numbers or data shorter than the shape needs.
    pub fn to_f64(&self) -> Option<Vec<f64>> {
        let d = self.dtype;
        if !matches!(d.kind, Kind::Bool | Kind::Int | Kind::Uint | Kind::Float) || d.size > 8 {
            return None;
        }
        let index = self.data_index();
        (0..self.len())
            .map(|k| {
                let le = self.element(index(k))?;
                Some(match (d.kind, d.size) {
                    (Kind::Float, 2) => f64::from(f16_to_f32(u16::from_le_bytes([le[0], le[1]]))),
                    (Kind::Float, 4) => f64::from(f32::from_le_bytes([le[0], le[1], le[2], le[3]])),
                    (Kind::Float, _) => f64::from_le_bytes(le),
                    (Kind::Int, n) => {
                        // Sign-extends an n-byte integer.
                        let shift = 64 - 8 * n as u32;
                        ((i64::from_le_bytes(le) << shift) >> shift) as f64
                    }
                    _ => u64::from_le_bytes(le) as f64,
                })
            })
            .collect()
    }

    /// Depth as `f32` metres, the C-order elements `range`: uint16 units of `scale`
    /// metres, or float metres; `None` for another dtype or data shorter than the
    /// shape needs.
    pub fn depth_values(&self, scale: f64, range: std::ops::Range<usize>) -> Option<Vec<f32>> {
        let d = self.dtype;
        let uint16 = d.kind == Kind::Uint && d.size == 2;
        if !(uint16 || d.kind == Kind::Float) || range.end > self.len() {
            return None;
        }
        let scale = scale as f32;
        let index = self.data_index();
        range
            .map(|k| {
                let le = self.element(index(k))?;
                Some(match d.size {
                    _ if uint16 => f32::from(u16::from_le_bytes([le[0], le[1]])) * scale,
                    2 => f16_to_f32(u16::from_le_bytes([le[0], le[1]])),
                    4 => f32::from_le_bytes([le[0], le[1], le[2], le[3]]),
                    _ => f64::from_le_bytes(le) as f32,
                })
            })
            .collect()
    }
}

/// The shape as Python prints a tuple: `(6, 8)`, `(3,)`, `()`.
pub fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => {
            let parts: Vec<String> = shape.iter().map(|n| n.to_string()).collect();
            format!("({})", parts.join(", "))
        }
    }
}

/// Reads the header at the start of `r`: the magic, the version, the length and the
/// dict. Errors are messages without the file's name.
pub fn read_header(r: &mut impl Read) -> std::result::Result<Header, String> {
    let mut prefix = [0u8; 8];
    r.read_exact(&mut prefix)
        .map_err(|_| "truncated .npy header".to_string())?;
    if &prefix[..6] != MAGIC {
        return Err("not a .npy file (no \\x93NUMPY magic)".into());
    }
    let len_bytes = match prefix[6] {
        1 => 2,
        2 | 3 => 4,
        v => return Err(format!("unsupported .npy version {v}.{}", prefix[7])),
    };
    let mut len = [0u8; 4];
    r.read_exact(&mut len[..len_bytes])
        .map_err(|_| "truncated .npy header".to_string())?;
    let len = u32::from_le_bytes(len) as usize;
    if len > MAX_HEADER_BYTES {
        return Err(format!(
            "a .npy header of {len} bytes is longer than {MAX_HEADER_BYTES}"
        ));
    }
    let mut text = vec![0u8; len];
    r.read_exact(&mut text)
        .map_err(|_| "truncated .npy header".to_string())?;
    let text = std::str::from_utf8(&text).map_err(|_| "a .npy header that is not text")?;
    let (dtype, fortran, shape) = parse_dict(text)?;
    let elements = shape.iter().try_fold(1u64, |n, &d| n.checked_mul(d as u64));
    let data_bytes = elements
        .and_then(|n| n.checked_mul(dtype.size as u64))
        .filter(|&b| b < 1 << 62)
        .ok_or_else(|| format!("shape {} is too large", shape_text(&shape)))?;
    Ok(Header {
        dtype,
        shape,
        fortran,
        data_bytes,
        data_offset: (6 + 2 + len_bytes + len) as u64,
    })
}

/// The header at the start of `bytes` (see [`read_header`]).
pub fn parse_header(bytes: &[u8]) -> std::result::Result<Header, String> {
    read_header(&mut &bytes[..])
}

/// The dtype, Fortran order and shape of a header's dict.
fn parse_dict(text: &str) -> std::result::Result<(Dtype, bool, Vec<usize>), String> {
    let bad = |why: &str| format!("bad .npy header ({why})");
    let mut p = Parser {
        s: text.as_bytes(),
        at: 0,
    };
    p.expect(b'{').map_err(|_| bad("not a dict"))?;
    let (mut descr, mut fortran, mut shape) = (None, None, None);
    loop {
        if p.eat(b'}') {
            break;
        }
        let key = p
            .string()
            .ok_or_else(|| bad("a key that is not a string"))?;
        p.expect(b':').map_err(|_| bad("no ':' after a key"))?;
        match key.as_str() {
            "descr" => {
                if p.peek() == Some(b'[') {
                    return Err("unsupported dtype (a structured array)".into());
                }
                let d = p.string().ok_or_else(|| bad("'descr' is not a string"))?;
                descr = Some(Dtype::parse(&d)?);
            }
            "fortran_order" => fortran = Some(p.boolean().ok_or_else(|| bad("'fortran_order'"))?),
            "shape" => shape = Some(p.tuple().ok_or_else(|| bad("'shape' is not a tuple"))?),
            _ => return Err(bad("an unknown key")),
        }
        if !p.eat(b',') {
            p.expect(b'}')
                .map_err(|_| bad("no ',' or '}' after a value"))?;
            break;
        }
    }
    if !p.rest_is_blank() {
        return Err(bad("text after the dict"));
    }
    match (descr, fortran, shape) {
        (Some(d), Some(f), Some(s)) => Ok((d, f, s)),
        _ => Err(bad("'descr', 'fortran_order' or 'shape' missing")),
    }
}

/// A cursor over the header's text.
struct Parser<'a> {
    s: &'a [u8],
    at: usize,
}

impl Parser<'_> {
    fn skip_blank(&mut self) {
        while self.at < self.s.len() && self.s[self.at].is_ascii_whitespace() {
            self.at += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.skip_blank();
        self.s.get(self.at).copied()
    }

    fn eat(&mut self, c: u8) -> bool {
        let found = self.peek() == Some(c);
        self.at += usize::from(found);
        found
    }

    fn expect(&mut self, c: u8) -> std::result::Result<(), ()> {
        self.eat(c).then_some(()).ok_or(())
    }

    fn rest_is_blank(&mut self) -> bool {
        self.peek().is_none()
    }

    /// A string in single or double quotes, without escapes.
    fn string(&mut self) -> Option<String> {
        let quote = self.peek().filter(|q| matches!(q, b'\'' | b'"'))?;
        let start = self.at + 1;
        let len = self.s[start..].iter().position(|&c| c == quote)?;
        self.at = start + len + 1;
        let text = std::str::from_utf8(&self.s[start..start + len]).ok()?;
        (!text.contains('\\')).then(|| text.to_string())
    }

    fn word(&mut self, word: &str) -> bool {
        self.skip_blank();
        let found = self.s[self.at..].starts_with(word.as_bytes());
        self.at += if found { word.len() } else { 0 };
        found
    }

    fn boolean(&mut self) -> Option<bool> {
        if self.word("True") {
            Some(true)
        } else if self.word("False") {
            Some(false)
        } else {
            None
        }
    }

    /// A tuple of non-negative integers: `()`, `(3,)`, `(2, 3)`, `(2, 3,)`.
    fn tuple(&mut self) -> Option<Vec<usize>> {
        if !self.eat(b'(') {
            return None;
        }
        let mut out = Vec::new();
        // Whether the last integer was followed by a comma: `(3)` is a number in
        // parentheses, `(3,)` a tuple.
        let mut comma = false;
        loop {
            if self.eat(b')') {
                return (out.len() != 1 || comma).then_some(out);
            }
            if !out.is_empty() && !comma {
                return None;
            }
            self.skip_blank();
            let start = self.at;
            while self.at < self.s.len() && self.s[self.at].is_ascii_digit() {
                self.at += 1;
            }
            let digits = std::str::from_utf8(&self.s[start..self.at]).ok()?;
            if digits.is_empty() || digits.len() > 19 || out.len() >= MAX_DIMS {
                return None;
            }
            out.push(digits.parse().ok()?);
            comma = self.eat(b',');
        }
    }
}

/// Reads the elements that follow a header from `r`: exactly `header.data_bytes`
/// bytes, an error if fewer follow. The buffer grows as data arrives, so a header
/// claiming more data than there is allocates no more than there is.
pub fn read_data(r: &mut impl Read, header: &Header) -> std::result::Result<Vec<u8>, String> {
    let want = header.data_bytes;
    let mut data = Vec::with_capacity(want.min(1 << 26) as usize);
    r.take(want)
        .read_to_end(&mut data)
        .map_err(|e| format!("unreadable data: {e}"))?;
    if (data.len() as u64) < want {
        return Err(format!(
            "truncated: shape {} needs {want} bytes of data, the file holds {}",
            shape_text(&header.shape),
            data.len()
        ));
    }
    Ok(data)
}

/// Writes `a` as a `.npy` (version 1.0, or 2.0 for a header too long for it).
pub fn write_to(w: &mut impl Write, a: &Array) -> std::io::Result<()> {
    let mut dict = format!(
        "{{'descr': '{}', 'fortran_order': {}, 'shape': {}, }}",
        a.dtype.descr(),
        if a.fortran { "True" } else { "False" },
        shape_text(&a.shape)
    );
    // The elements start on a multiple of 64 bytes, as numpy writes them.
    let prefix = if dict.len() + 11 < 65536 { 10 } else { 12 };
    let total = (prefix + dict.len() + 1).div_ceil(64) * 64;
    dict.push_str(&" ".repeat(total - prefix - dict.len() - 1));
    dict.push('\n');
    w.write_all(MAGIC)?;
    if prefix == 10 {
        w.write_all(&[1, 0])?;
        w.write_all(&(dict.len() as u16).to_le_bytes())?;
    } else {
        w.write_all(&[2, 0])?;
        w.write_all(&(dict.len() as u32).to_le_bytes())?;
    }
    w.write_all(dict.as_bytes())?;
    w.write_all(&a.data)
}

/// Writes `a` to the file at `path`.
pub fn write(path: &Path, a: &Array) -> Result<()> {
    let mut out = Vec::with_capacity(128 + a.data.len());
    write_to(&mut out, a).map_err(|e| io_error(path, "write", e))?;
    std::fs::write(path, out).map_err(|e| io_error(path, "write", e))
}

/// Reads a depth image from a `.npy`: (H, W) float (metres) or uint16 (units of
/// `scale` metres), in C or Fortran order. The header (dtype, shape, size against
/// [`super::MAX_IMAGE_PIXELS`]) is checked before the data is read.
pub fn read_depth(path: &Path, scale: f64) -> Result<Image> {
    let len = existing(path, "an image file")?;
    let file_err = |m: String| Error::file(path_str(path), m);
    let mut f =
        std::io::BufReader::new(std::fs::File::open(path).map_err(|e| io_error(path, "read", e))?);
    let h = read_header(&mut f).map_err(|m| file_err(format!("not a readable .npy file ({m})")))?;
    let shape = shape_text(&h.shape);
    if h.dtype.kind == Kind::Object {
        return Err(file_err("holds Python objects, not depth".into()));
    }
    let &[height, width] = &h.shape[..] else {
        return Err(file_err(format!(
            "expected a 2-D depth image, got shape {shape}"
        )));
    };
    check_size(path, width as u64, height as u64)?;
    if height * width == 0 {
        return Err(file_err(format!(
            "the depth image is empty (shape {shape})"
        )));
    }
    let d = h.dtype;
    if !(d.kind == Kind::Float || d.kind == Kind::Uint && d.size == 2) {
        return Err(file_err(format!(
            "depth must be float metres or uint16, got {}",
            d.name()
        )));
    }
    if len.saturating_sub(h.data_offset) < h.data_bytes {
        return Err(file_err(format!(
            "not a readable .npy file (truncated: shape {shape} needs {} bytes of data, the \
             file holds {})",
            h.data_bytes,
            len.saturating_sub(h.data_offset)
        )));
    }
    let raw =
        read_data(&mut f, &h).map_err(|m| file_err(format!("not a readable .npy file ({m})")))?;
    let array = Array {
        dtype: d,
        shape: h.shape,
        fortran: h.fortran,
        data: raw,
    };
    // The dtype is checked above and `read_data` read the whole data.
    let data = array
        .depth_values(scale, 0..height * width)
        .ok_or_else(|| {
            file_err(format!(
                "not a readable .npy file (truncated: shape {shape})"
            ))
        })?;
    let img = Image {
        data,
        height,
        width,
    };
    check_depth(path, &img)?;
    Ok(img)
}

/// A half-precision float's value (exact in single precision).
fn f16_to_f32(bits: u16) -> f32 {
    let exp = i32::from((bits >> 10) & 0x1f);
    let frac = f32::from(bits & 0x3ff);
    let magnitude = match exp {
        0 => frac * 2f32.powi(-24),
        31 if frac == 0.0 => f32::INFINITY,
        31 => f32::NAN,
        _ => (1.0 + frac / 1024.0) * 2f32.powi(exp - 15),
    };
    if bits >> 15 == 1 {
        -magnitude
    } else {
        magnitude
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{fuzz_cases, temp_dir};
    use super::*;
    use proptest::prelude::*;

    fn file(descr: &str, fortran: bool, shape: &[usize], data: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let a = Array {
            dtype: Dtype::parse(descr).unwrap(),
            shape: shape.to_vec(),
            fortran,
            data: data.to_vec(),
        };
        write_to(&mut out, &a).unwrap();
        out
    }

    #[test]
    fn values_come_in_c_order_whatever_the_data_order() {
        // C-order values 0..24 of a (2, 3, 4) array, stored in Fortran order: the
        // element at (i, j, k) sits at data index i + 2j + 6k.
        let shape = [2usize, 3, 4];
        let mut fortran = vec![0f32; 24];
        for c in 0..24 {
            let (i, j, k) = (c / 12, c / 4 % 3, c % 4);
            fortran[i + 2 * j + 6 * k] = c as f32;
        }
        let bytes = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let c_order: Vec<f32> = (0..24).map(|c| c as f32).collect();
        for (data, is_fortran) in [(&fortran, true), (&c_order, false)] {
            let a = Array {
                dtype: Dtype::parse("<f4").unwrap(),
                shape: shape.to_vec(),
                fortran: is_fortran,
                data: bytes(data),
            };
            let expected: Vec<f64> = (0..24).map(f64::from).collect();
            assert_eq!(a.to_f64().unwrap(), expected);
            assert_eq!(a.depth_values(1.0, 12..24).unwrap(), c_order[12..]);
        }
        // Big-endian uint16 units scaled to metres, in C order.
        let a = Array {
            dtype: Dtype::parse(">u2").unwrap(),
            shape: vec![2, 2],
            fortran: true,
            data: [2u16, 6, 4, 8]
                .iter()
                .flat_map(|v| v.to_be_bytes())
                .collect(),
        };
        assert_eq!(a.depth_values(0.5, 0..4).unwrap(), [1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn headers_are_numpys() {
        let bytes = file("<f4", false, &[2, 3], &[0; 24]);
        assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
        let text = String::from_utf8_lossy(&bytes[10..bytes.len() - 24]).into_owned();
        assert!(text.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }"));
        assert_eq!((bytes.len() - 24) % 64, 0);
        let h = parse_header(&bytes).unwrap();
        assert_eq!(
            (h.shape.clone(), h.data_bytes, h.data_offset),
            (vec![2, 3], 24, 128)
        );
        for (descr, name) in [
            ("<f4", "float32"),
            ("|u1", "uint8"),
            ("|b1", "bool"),
            ("<i8", "int64"),
            (">f8", ">f8"),
            ("<U16", "<U16"),
            ("|O", "object"),
        ] {
            let d = Dtype::parse(descr).unwrap();
            assert_eq!((d.descr().as_str(), d.name().as_str()), (descr, name));
        }
        assert_eq!(shape_text(&[3]), "(3,)");
        assert_eq!(shape_text(&[]), "()");
        // Headers as other writers space them; version 2.
        let mut v2 = b"\x93NUMPY\x02\x00".to_vec();
        let dict = b"{\"shape\":(4,),\"fortran_order\":True,\"descr\":\">u2\"}\n";
        v2.extend_from_slice(&(dict.len() as u32).to_le_bytes());
        v2.extend_from_slice(dict);
        let h = parse_header(&v2).unwrap();
        assert_eq!(
            (h.shape, h.fortran, h.dtype.big_endian),
            (vec![4], true, true)
        );
    }

    #[test]
    fn hostile_headers_are_clear_errors() {
        let good = file("<f4", false, &[2, 3], &[]);
        let with_dict = |dict: &str| {
            let mut b = b"\x93NUMPY\x01\x00".to_vec();
            b.extend_from_slice(&(dict.len() as u16).to_le_bytes());
            b.extend_from_slice(dict.as_bytes());
            b
        };
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..20].to_vec(), "truncated .npy header"),
            (good[..5].to_vec(), "truncated .npy header"),
            (b"\x93NUMPX\x01\x00\x00\x00".to_vec(), "magic"),
            (b"\x93NUMPY\x07\x00\x00\x00".to_vec(), "version 7.0"),
            (b"\x93NUMPY\x02\x00\xff\xff\xff\xff".to_vec(), "longer than"),
            (with_dict("{'descr': '<f4', 'fortran_order': False, 'shape': (99999999999, 99999999999, 99999999999), }"), "too large"),
            (with_dict("[1, 2]"), "not a dict"),
            (with_dict("{'descr': '<f4', 'shape': (2,), }"), "missing"),
            (with_dict("{'descr': '<f4', 'fortran_order': 0, 'shape': (2,)}"), "fortran_order"),
            (with_dict("{'descr': '<f4', 'fortran_order': False, 'shape': (-2,)}"), "shape"),
            (with_dict("{'descr': '<f4', 'fortran_order': False, 'shape': (2)}"), "shape"),
            (with_dict("{'descr': '<x9', 'fortran_order': False, 'shape': ()}"), "unsupported dtype"),
            (with_dict("{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': ()}"), "structured"),
            (with_dict("{'descr': '<f4', 'fortran_order': False, 'shape': (), 'x': 1}"), "unknown key"),
            (with_dict("{'descr': '<f4', 'fortran_order': False, 'shape': ()} junk"), "after the dict"),
        ];
        for (bytes, want) in cases {
            let e = parse_header(&bytes).unwrap_err();
            assert!(e.contains(want), "{want}: {e}");
        }
    }

    #[test]
    fn depth_reads_every_layout_and_refuses_the_rest() {
        let dir = temp_dir("npy");
        let p = dir.join("d.npy");
        // Fortran order (2, 3): columns stored one after the other.
        let cols: Vec<u8> = [1.0f64, 4.0, 2.0, 5.0, 3.0, 6.0]
            .iter()
            .flat_map(|v| v.to_be_bytes())
            .collect();
        std::fs::write(&p, file(">f8", true, &[2, 3], &cols)).unwrap();
        assert_eq!(
            read_depth(&p, 0.001).unwrap().data,
            [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
        );
        std::fs::write(&p, file("<u2", false, &[1, 2], &[0xe8, 0x03, 0, 0])).unwrap();
        assert_eq!(read_depth(&p, 0.001).unwrap().data, [1.0, 0.0]);
        std::fs::write(&p, file("<f2", false, &[1, 2], &[0x00, 0x3c, 0x00, 0x7e])).unwrap();
        let half = read_depth(&p, 0.001).unwrap().data;
        assert!(half[0] == 1.0 && half[1].is_nan());
        for (bytes, want) in [
            (file("<i4", false, &[1, 1], &[0; 4]), "got int32"),
            (file("|O", false, &[1, 1], &[0; 8]), "Python objects"),
            (file("<f4", false, &[3], &[0; 12]), "got shape (3,)"),
            (file("<f4", false, &[0, 8], &[]), "empty (shape (0, 8))"),
            (file("<f4", false, &[2, 2], &[0; 15]), "truncated"),
            (
                file("<f4", false, &[1 << 20, 1 << 20], &[]),
                "MAX_IMAGE_PIXELS",
            ),
            (
                file("<f4", false, &[1, 1], &(-1.0f32).to_le_bytes()),
                "-1 at row 0",
            ),
        ] {
            std::fs::write(&p, bytes).unwrap();
            let e = read_depth(&p, 0.001).unwrap_err().to_string();
            assert!(e.contains(want) && e.contains("d.npy"), "{want}: {e}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn half_floats_are_exact() {
        assert_eq!(f16_to_f32(0x3c00), 1.0);
        assert_eq!(f16_to_f32(0xc000), -2.0);
        assert_eq!(f16_to_f32(0x7bff), 65504.0);
        assert_eq!(f16_to_f32(0x0001), 2f32.powi(-24));
        assert_eq!(f16_to_f32(0xfc00), f32::NEG_INFINITY);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(fuzz_cases(256)))]

        /// Any bytes after the magic: a header whose sizes add up, or an error.
        #[test]
        fn header_parser_survives_any_bytes(
            version in 0u8..4,
            tail in proptest::collection::vec(any::<u8>(), 0..120),
        ) {
            let mut bytes = b"\x93NUMPY".to_vec();
            bytes.extend_from_slice(&[version, 0]);
            bytes.extend_from_slice(&tail);
            if let Ok(h) = parse_header(&bytes) {
                let n: u64 = h.shape.iter().map(|&d| d as u64).product();
                prop_assert_eq!(n * h.dtype.size as u64, h.data_bytes);
            }
        }

        /// Dicts of any text: no panic.
        #[test]
        fn header_parser_survives_any_dict(dict in "[{}():,'\" a-z_0-9<>|TrueFals]{0,80}") {
            let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
            bytes.extend_from_slice(&(dict.len() as u16).to_le_bytes());
            bytes.extend_from_slice(dict.as_bytes());
            let _ = parse_header(&bytes);
        }

        /// What is written reads back: shape, order and bytes.
        #[test]
        fn round_trips_are_exact(
            shape in proptest::collection::vec(0usize..4, 0..4),
            fortran in any::<bool>(),
            descr in prop_oneof![Just("<f4"), Just("<f8"), Just("<u2"), Just("|u1"), Just("|b1"),
                                 Just("<i4"), Just("<i8"), Just(">f4"), Just("<U3")],
            seed in any::<u8>(),
        ) {
            let dtype = Dtype::parse(descr).unwrap();
            let n: usize = shape.iter().product::<usize>() * dtype.size;
            let data: Vec<u8> = (0..n).map(|k| (k as u8).wrapping_mul(seed)).collect();
            let bytes = file(descr, fortran, &shape, &data);
            let mut r = &bytes[..];
            let h = read_header(&mut r).unwrap();
            prop_assert_eq!((&h.shape, h.fortran, h.dtype), (&shape, fortran, dtype));
            prop_assert_eq!(read_data(&mut r, &h).unwrap(), data);
        }
    }
}
