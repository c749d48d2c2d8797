//! PCD files (PCL's point cloud format, VERSION 0.7): a header-driven reader for `DATA ascii`,
//! `binary` and `binary_compressed`, and a writer for the simulator and fixtures.
//!
//! Layouts: `binary` stores points one after another, each with every field in header order;
//! `binary_compressed` stores `u32 compressed size, u32 raw size`, then one LZF block whose raw
//! bytes hold the fields column by column (all x, then all y, ...). All numbers are little-endian.

use std::path::Path;

use crate::cloud::ReadLimits;
use crate::error::{DataError, ErrorKind, Result};
use crate::lzf;

/// How the data section of a PCD file is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Encoding {
    /// Text, one point per line.
    Ascii,
    /// Raw little-endian records, point by point.
    Binary,
    /// LZF-compressed columns.
    BinaryCompressed,
}

impl Encoding {
    /// The word of the `DATA` line.
    pub fn keyword(self) -> &'static str {
        match self {
            Encoding::Ascii => "ascii",
            Encoding::Binary => "binary",
            Encoding::BinaryCompressed => "binary_compressed",
        }
    }
}

/// A field's scalar type: the header's `TYPE` letter with its `SIZE`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)] // I/U/F with 1, 2, 4 or 8 bytes, as named.
pub enum FieldType {
    I8,
    I16,
    I32,
    I64,
    U8,
    U16,
    U32,
    U64,
    F32,
    F64,
}

impl FieldType {
    fn from_header(ty: &str, size: usize) -> Option<Self> {
        Some(match (ty, size) {
            ("I", 1) => Self::I8,
            ("I", 2) => Self::I16,
            ("I", 4) => Self::I32,
            ("I", 8) => Self::I64,
            ("U", 1) => Self::U8,
            ("U", 2) => Self::U16,
            ("U", 4) => Self::U32,
            ("U", 8) => Self::U64,
            ("F", 4) => Self::F32,
            ("F", 8) => Self::F64,
            _ => return None,
        })
    }

    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::I64 | Self::U64 | Self::F64 => 8,
        }
    }

    /// The header's `TYPE` letter.
    pub fn letter(self) -> char {
        match self {
            Self::I8 | Self::I16 | Self::I32 | Self::I64 => 'I',
            Self::U8 | Self::U16 | Self::U32 | Self::U64 => 'U',
            Self::F32 | Self::F64 => 'F',
        }
    }

    fn decode(self, b: &[u8]) -> f64 {
        match self {
            Self::I8 => b[0] as i8 as f64,
            Self::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Self::I32 => i32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
            Self::I64 => i64::from_le_bytes(b[..8].try_into().unwrap()) as f64,
            Self::U8 => b[0] as f64,
            Self::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Self::U32 => u32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
            Self::U64 => u64::from_le_bytes(b[..8].try_into().unwrap()) as f64,
            Self::F32 => f32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
            Self::F64 => f64::from_le_bytes(b[..8].try_into().unwrap()),
        }
    }

    fn encode(self, v: f64, out: &mut Vec<u8>) {
        match self {
            Self::I8 => out.push(v as i8 as u8),
            Self::I16 => out.extend((v as i16).to_le_bytes()),
            Self::I32 => out.extend((v as i32).to_le_bytes()),
            Self::I64 => out.extend((v as i64).to_le_bytes()),
            Self::U8 => out.push(v as u8),
            Self::U16 => out.extend((v as u16).to_le_bytes()),
            Self::U32 => out.extend((v as u32).to_le_bytes()),
            Self::U64 => out.extend((v as u64).to_le_bytes()),
            Self::F32 => out.extend((v as f32).to_le_bytes()),
            Self::F64 => out.extend(v.to_le_bytes()),
        }
    }

    fn format(self, v: f64) -> String {
        match self {
            Self::F32 => format!("{}", v as f32),
            Self::F64 => format!("{v}"),
            _ => format!("{}", v as i64),
        }
    }
}

/// One `FIELDS` entry with its type and element count.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    /// Field name (`x`, `intensity`, `ring`, ...).
    pub name: String,
    /// Scalar type.
    pub ty: FieldType,
    /// Elements per point (`COUNT`).
    pub count: usize,
}

/// What to do with points whose x, y or z is NaN or infinite.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NonFinite {
    /// Drop them and count them in [`PointCloud::dropped_non_finite`] (real scans mark misses so).
    #[default]
    Drop,
    /// Treat them as a malformed file.
    Error,
}

/// A parsed PCD file: finite xyz plus every other field, aligned point by point.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud {
    /// The header's fields, in file order.
    pub fields: Vec<Field>,
    /// The encoding the file used.
    pub encoding: Encoding,
    /// Coordinates of the kept (finite) points, in the file's frame.
    pub xyz: Vec<[f32; 3]>,
    /// Every field other than x, y, z (first element when `COUNT > 1`), one value per kept point.
    pub extra: Vec<(String, Vec<f32>)>,
    /// Points dropped for a non-finite coordinate.
    pub dropped_non_finite: usize,
}

impl PointCloud {
    /// Values of an extra field such as `intensity` or `ring`.
    pub fn field(&self, name: &str) -> Option<&[f32]> {
        self.extra.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_slice())
    }
}

/// Reads and parses a PCD file.
pub fn read_pcd(path: &Path, non_finite: NonFinite) -> Result<PointCloud> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    parse_pcd(&bytes, non_finite).map_err(|kind| DataError::new(path, kind))
}

struct Header {
    fields: Vec<Field>,
    points: usize,
    encoding: Encoding,
}

/// LZF's largest expansion: a 3-byte back-reference writes at most 264 bytes.
const LZF_MAX_EXPANSION: usize = 88;

fn parse_header(bytes: &[u8]) -> std::result::Result<(Header, usize), ErrorKind> {
    let bad = |s: String| ErrorKind::PcdHeader(s);
    let (mut names, mut sizes, mut types, mut counts) = (None, None, None, None);
    let (mut width, mut height, mut points) = (None, None, None);
    let mut pos = 0;
    loop {
        let Some(nl) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(bad("header ends without a DATA line".into()));
        };
        let line = std::str::from_utf8(&bytes[pos..pos + nl]).map_err(|_| bad("header is not text".into()))?;
        pos += nl + 1;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut it = line.split_whitespace();
        let key = it.next().unwrap_or_default().to_ascii_uppercase();
        let vals: Vec<&str> = it.collect();
        let num = |v: &[&str]| -> std::result::Result<usize, ErrorKind> {
            match v {
                [x] => x.parse().map_err(|_| bad(format!("{key} `{x}` is not a count"))),
                _ => Err(bad(format!("{key} needs one value, got {}", v.len()))),
            }
        };
        let list = |v: &[&str]| -> std::result::Result<Vec<usize>, ErrorKind> {
            v.iter().map(|x| x.parse().map_err(|_| bad(format!("{key} value `{x}` is not a number")))).collect()
        };
        match key.as_str() {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => names = Some(vals.iter().map(|s| s.to_string()).collect::<Vec<_>>()),
            "SIZE" => sizes = Some(list(&vals)?),
            "TYPE" => types = Some(vals.iter().map(|s| s.to_ascii_uppercase()).collect::<Vec<_>>()),
            "COUNT" => counts = Some(list(&vals)?),
            "WIDTH" => width = Some(num(&vals)?),
            "HEIGHT" => height = Some(num(&vals)?),
            "POINTS" => points = Some(num(&vals)?),
            "DATA" => {
                let word = vals.first().copied().unwrap_or("");
                let encoding = match word.to_ascii_lowercase().as_str() {
                    "ascii" => Encoding::Ascii,
                    "binary" => Encoding::Binary,
                    "binary_compressed" => Encoding::BinaryCompressed,
                    _ => return Err(ErrorKind::UnknownData(word.to_string())),
                };
                let names = names.ok_or_else(|| bad("no FIELDS line".into()))?;
                let sizes = sizes.ok_or_else(|| bad("no SIZE line".into()))?;
                let types = types.ok_or_else(|| bad("no TYPE line".into()))?;
                let counts = counts.unwrap_or_else(|| vec![1; names.len()]);
                if sizes.len() != names.len() || types.len() != names.len() || counts.len() != names.len() {
                    return Err(bad(format!(
                        "FIELDS has {} entries but SIZE {}, TYPE {}, COUNT {}",
                        names.len(),
                        sizes.len(),
                        types.len(),
                        counts.len()
                    )));
                }
                let mut fields = Vec::with_capacity(names.len());
                for (((name, &size), ty), &count) in names.iter().zip(&sizes).zip(&types).zip(&counts) {
                    let ty = FieldType::from_header(ty, size)
                        .ok_or_else(|| bad(format!("field `{name}`: TYPE {ty} with SIZE {size} is not supported")))?;
                    fields.push(Field { name: name.clone(), ty, count });
                }
                for axis in ["x", "y", "z"] {
                    match fields.iter().find(|f| f.name == axis) {
                        None => return Err(bad(format!("no `{axis}` field"))),
                        Some(f) if f.count == 0 => return Err(bad(format!("field `{axis}` has COUNT 0"))),
                        Some(_) => {}
                    }
                }
                let wh = match (width, height) {
                    (Some(w), Some(h)) => {
                        Some(w.checked_mul(h).ok_or_else(|| bad(format!("WIDTH {w} x HEIGHT {h} overflows")))?)
                    }
                    (Some(w), None) => Some(w),
                    _ => None,
                };
                let points = match (points, wh) {
                    (Some(p), Some(wh)) if p != wh => {
                        return Err(bad(format!("POINTS {p} but WIDTH x HEIGHT = {wh}")));
                    }
                    (Some(p), _) => p,
                    (None, Some(wh)) => wh,
                    (None, None) => return Err(bad("neither POINTS nor WIDTH given".into())),
                };
                return Ok((Header { fields, points, encoding }, pos));
            }
            other => return Err(bad(format!("unknown header line `{other}`"))),
        }
    }
}

/// Where each field lives: in a binary record (bytes) and in an ascii line (values).
struct RecordLayout {
    /// Byte offset of each field's first element in a `binary` record.
    byte: Vec<usize>,
    /// Bytes per point.
    record: usize,
    /// Values per point (the sum of the COUNTs).
    values: usize,
}

impl RecordLayout {
    fn of(fields: &[Field]) -> std::result::Result<Self, ErrorKind> {
        let too_big = || ErrorKind::PcdHeader("the fields' SIZE x COUNT overflows".into());
        let (mut byte, mut record, mut values) = (Vec::with_capacity(fields.len()), 0usize, 0usize);
        for f in fields {
            byte.push(record);
            record = f.count.checked_mul(f.ty.size()).and_then(|b| record.checked_add(b)).ok_or_else(too_big)?;
            values = values.checked_add(f.count).ok_or_else(too_big)?;
        }
        Ok(Self { byte, record, values })
    }
}

/// Collects the kept points as they are decoded: xyz and the first element of every other named
/// field (PCL's `_` padding and COUNT 0 fields carry nothing).
struct Points<'h> {
    fields: &'h [Field],
    axes: [usize; 3],
    extras: Vec<usize>,
    non_finite: NonFinite,
    xyz: Vec<[f32; 3]>,
    extra: Vec<(String, Vec<f32>)>,
    dropped: usize,
}

impl<'h> Points<'h> {
    /// `capacity` must be justified by bytes already present (see the callers).
    fn new(fields: &'h [Field], non_finite: NonFinite, capacity: usize, keep_extras: bool) -> Self {
        let find = |axis: &str| fields.iter().position(|f| f.name == axis).expect("parse_header checked x, y, z");
        let axes = [find("x"), find("y"), find("z")];
        let extras: Vec<usize> = (0..fields.len())
            .filter(|&i| keep_extras && !["x", "y", "z", "_"].contains(&fields[i].name.as_str()) && fields[i].count > 0)
            .collect();
        let extra = extras.iter().map(|&i| (fields[i].name.clone(), Vec::with_capacity(capacity))).collect();
        Self { fields, axes, extras, non_finite, xyz: Vec::with_capacity(capacity), extra, dropped: 0 }
    }

    /// Adds point `i`, whose field `f`'s first element is `first(f)`.
    fn push(&mut self, i: usize, first: impl Fn(usize) -> f64) -> std::result::Result<(), ErrorKind> {
        let p = self.axes.map(|a| first(a) as f32);
        if !p.iter().all(|v| v.is_finite()) {
            if self.non_finite == NonFinite::Error {
                return Err(ErrorKind::NonFinite(format!("point {i} is ({}, {}, {})", p[0], p[1], p[2])));
            }
            self.dropped += 1;
            return Ok(());
        }
        self.xyz.push(p);
        for (k, &f) in self.extras.iter().enumerate() {
            self.extra[k].1.push(first(f) as f32);
        }
        Ok(())
    }

    fn finish(self, encoding: Encoding) -> PointCloud {
        PointCloud { fields: self.fields.to_vec(), encoding, xyz: self.xyz, extra: self.extra, dropped_non_finite: self.dropped }
    }
}

/// Parses the bytes of a PCD file; errors carry no path (see [`read_pcd`]).
///
/// Every size the header states is checked against the bytes present, with overflow-checked
/// arithmetic, before memory is reserved for it: the points kept never take more than about four
/// times the data section, or its stated uncompressed size (itself at most LZF's 88-fold
/// expansion of the compressed block).
pub fn parse_pcd(bytes: &[u8], non_finite: NonFinite) -> std::result::Result<PointCloud, ErrorKind> {
    parse_pcd_within(bytes, non_finite, &ReadLimits::NONE, true)
}

/// As [`parse_pcd`] under `limits`, with the fields other than x, y, z kept or not.
pub(crate) fn parse_pcd_within(
    bytes: &[u8],
    non_finite: NonFinite,
    limits: &ReadLimits,
    keep_extras: bool,
) -> std::result::Result<PointCloud, ErrorKind> {
    let (h, start) = parse_header(bytes)?;
    let data = &bytes[start..];
    let n = h.points;
    limits.check_points(n)?;
    let layout = RecordLayout::of(&h.fields)?;
    let rec = layout.record;
    let record_bytes = || {
        rec.checked_mul(n).ok_or_else(|| ErrorKind::PcdHeader(format!("{n} points x {rec} bytes overflows")))
    };
    Ok(match h.encoding {
        Encoding::Ascii => {
            // Every value takes a character and a separator: n points need 2·n·values − 1 bytes.
            let need = n.checked_mul(layout.values).and_then(|v| v.checked_mul(2)).map(|v| v.saturating_sub(1));
            if need.is_none_or(|need| need > data.len()) {
                return Err(ErrorKind::Truncated(format!(
                    "ascii data of {} bytes cannot hold the {n} points of {} values the header declares",
                    data.len(),
                    layout.values
                )));
            }
            let text = std::str::from_utf8(data).map_err(|_| ErrorKind::Mismatch("ascii data is not text".into()))?;
            let mut points = Points::new(&h.fields, non_finite, n, keep_extras);
            let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
            let mut first = vec![0f64; h.fields.len()];
            for i in 0..n {
                let line = lines.next().ok_or_else(|| ErrorKind::Truncated(format!("{i} of {n} points present")))?;
                let mut toks = line.split_whitespace();
                for (fi, f) in h.fields.iter().enumerate() {
                    for c in 0..f.count {
                        let tok = toks.next().ok_or_else(|| {
                            ErrorKind::Mismatch(format!("point {i} has fewer than the {} values the header declares", layout.values))
                        })?;
                        let v = parse_ascii(tok, f.ty).ok_or_else(|| {
                            ErrorKind::Mismatch(format!("point {i}: `{tok}` is not a valid {}{} value", f.ty.letter(), f.ty.size()))
                        })?;
                        if c == 0 {
                            first[fi] = v;
                        }
                    }
                }
                if toks.next().is_some() {
                    return Err(ErrorKind::Mismatch(format!("point {i} has more than the {} values the header declares", layout.values)));
                }
                points.push(i, |f| first[f])?;
            }
            if lines.next().is_some() {
                return Err(ErrorKind::Mismatch(format!("more lines than the {n} points the header declares")));
            }
            points.finish(h.encoding)
        }
        Encoding::Binary => {
            let need = record_bytes()?;
            if data.len() < need {
                return Err(ErrorKind::Truncated(format!(
                    "{} data bytes, the header needs {need} ({n} points x {rec} bytes)",
                    data.len()
                )));
            }
            // Zeros after the last point are padding some PCL-era writers leave (a page's rest);
            // anything else there means the header describes another file.
            if data.len() > need && data[need..].iter().any(|&b| b != 0) {
                return Err(ErrorKind::Mismatch(format!(
                    "{} data bytes, the header declares {need} ({n} points x {rec} bytes)",
                    data.len()
                )));
            }
            let mut points = Points::new(&h.fields, non_finite, n, keep_extras);
            for i in 0..n {
                let at = i * rec;
                points.push(i, |f| h.fields[f].ty.decode(&data[at + layout.byte[f]..]))?;
            }
            points.finish(h.encoding)
        }
        Encoding::BinaryCompressed => {
            if data.len() < 8 {
                return Err(ErrorKind::Truncated("binary_compressed data shorter than its 8-byte size prefix".into()));
            }
            let csize = u32::from_le_bytes(data[0..4].try_into().unwrap()) as usize;
            let usize_ = u32::from_le_bytes(data[4..8].try_into().unwrap()) as usize;
            let need = record_bytes()?;
            limits.check_data_bytes(need)?;
            if usize_ != need {
                return Err(ErrorKind::Mismatch(format!(
                    "uncompressed size {usize_} but the header declares {need} ({n} points x {rec} bytes)"
                )));
            }
            let body = &data[8..];
            if body.len() < csize {
                return Err(ErrorKind::Truncated(format!("compressed block of {csize} bytes but only {} present", body.len())));
            }
            if body.len() > csize {
                return Err(ErrorKind::Mismatch(format!(
                    "{} bytes after the {csize}-byte compressed block",
                    body.len() - csize
                )));
            }
            if usize_ > csize.saturating_mul(LZF_MAX_EXPANSION) {
                return Err(ErrorKind::Mismatch(format!(
                    "uncompressed size {usize_} cannot come from a {csize}-byte LZF block (at most {LZF_MAX_EXPANSION} times larger)"
                )));
            }
            let raw = if usize_ == 0 { Vec::new() } else { lzf::decompress(&body[..csize], usize_).map_err(ErrorKind::Mismatch)? };
            // Field f's column holds every point's elements: point i's first one is at
            // n·byte[f] + i·count·size.
            let mut points = Points::new(&h.fields, non_finite, n, keep_extras);
            for i in 0..n {
                points.push(i, |f| {
                    let fd = &h.fields[f];
                    fd.ty.decode(&raw[n * layout.byte[f] + i * fd.count * fd.ty.size()..])
                })?;
            }
            points.finish(h.encoding)
        }
    })
}

fn parse_ascii(tok: &str, ty: FieldType) -> Option<f64> {
    match ty {
        FieldType::F32 | FieldType::F64 => tok.parse::<f64>().ok(),
        FieldType::U8 | FieldType::U16 | FieldType::U32 | FieldType::U64 => tok.parse::<u64>().ok().map(|v| v as f64),
        _ => tok.parse::<i64>().ok().map(|v| v as f64),
    }
}

/// One column to write: a scalar field and its values.
#[derive(Debug, Clone)]
pub struct Column {
    /// Field name.
    pub name: String,
    /// Stored type.
    pub ty: FieldType,
    /// One value per point.
    pub values: Vec<f64>,
}

/// Serializes columns (all the same length) as a PCD file, the way PCL writes VERSION 0.7.
pub fn encode_pcd(columns: &[Column], encoding: Encoding) -> Vec<u8> {
    let n = columns.first().map_or(0, |c| c.values.len());
    assert!(columns.iter().all(|c| c.values.len() == n), "PCD columns must have equal lengths");
    let join = |f: &dyn Fn(&Column) -> String| columns.iter().map(f).collect::<Vec<_>>().join(" ");
    let mut out = format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {}\nSIZE {}\nTYPE {}\nCOUNT {}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {}\n",
        join(&|c| c.name.clone()),
        join(&|c| c.ty.size().to_string()),
        join(&|c| c.ty.letter().to_string()),
        join(&|_| "1".to_string()),
        encoding.keyword()
    )
    .into_bytes();
    match encoding {
        Encoding::Ascii => {
            for i in 0..n {
                let line = columns.iter().map(|c| c.ty.format(c.values[i])).collect::<Vec<_>>().join(" ");
                out.extend_from_slice(line.as_bytes());
                out.push(b'\n');
            }
        }
        Encoding::Binary => {
            for i in 0..n {
                for c in columns {
                    c.ty.encode(c.values[i], &mut out);
                }
            }
        }
        Encoding::BinaryCompressed => {
            let mut raw = Vec::new();
            for c in columns {
                for &v in &c.values {
                    c.ty.encode(v, &mut raw);
                }
            }
            let comp = lzf::compress(&raw);
            out.extend((comp.len() as u32).to_le_bytes());
            out.extend((raw.len() as u32).to_le_bytes());
            out.extend(comp);
        }
    }
    out
}

/// Writes columns as a PCD file (see [`encode_pcd`]).
pub fn write_pcd(path: &Path, columns: &[Column], encoding: Encoding) -> Result<()> {
    std::fs::write(path, encode_pcd(columns, encoding)).map_err(|e| DataError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cols() -> Vec<Column> {
        vec![
            Column { name: "x".into(), ty: FieldType::F32, values: vec![1.5, -2.25, 3.0] },
            Column { name: "intensity".into(), ty: FieldType::F32, values: vec![10.0, 20.0, 30.0] },
            Column { name: "y".into(), ty: FieldType::F32, values: vec![0.5, 0.25, f64::NAN] },
            Column { name: "z".into(), ty: FieldType::F32, values: vec![-0.5, 1.0, 2.0] },
            Column { name: "ring".into(), ty: FieldType::U16, values: vec![0.0, 7.0, 15.0] },
        ]
    }

    #[test]
    fn all_encodings_round_trip_in_any_field_order() {
        for enc in [Encoding::Ascii, Encoding::Binary, Encoding::BinaryCompressed] {
            let pc = parse_pcd(&encode_pcd(&cols(), enc), NonFinite::Drop).unwrap();
            assert_eq!(pc.xyz, vec![[1.5, 0.5, -0.5], [-2.25, 0.25, 1.0]], "{enc:?}");
            assert_eq!(pc.dropped_non_finite, 1);
            assert_eq!(pc.field("ring").unwrap(), &[0.0, 7.0]);
            assert_eq!(pc.field("intensity").unwrap(), &[10.0, 20.0]);
            assert!(matches!(parse_pcd(&encode_pcd(&cols(), enc), NonFinite::Error), Err(ErrorKind::NonFinite(_))));
        }
    }
}
