//! Point clouds as other tools write them, read into `[x, y, z]` points: PCD (any of its three
//! encodings, extra fields skipped), KITTI's velodyne `.bin` (float32 x, y, z, intensity),
//! nuScenes' LIDAR_TOP `.pcd.bin` (float32 x, y, z, intensity, ring) and NumPy `.npy` (N×3 or
//! N×4, float32 or float64, little-endian). Points with a non-finite coordinate are dropped
//! and counted. The format comes from the bytes where they carry a signature (PCD's header,
//! NPY's magic), else from the file's extension.

use std::path::Path;

use crate::error::{DataError, ErrorKind, Result};
use crate::pcd::{NonFinite, parse_pcd_within};

/// A point-cloud file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CloudFormat {
    /// PCD: ascii, binary or binary_compressed.
    Pcd,
    /// KITTI velodyne: little-endian float32 records of x, y, z, intensity.
    KittiBin,
    /// nuScenes LIDAR_TOP (and Lyft level 5): little-endian float32 records of x, y, z,
    /// intensity, ring index, in files named `*.pcd.bin`.
    NuScenesBin,
    /// NumPy `.npy`: a 2-D float32 or float64 array of 3 or 4 columns.
    Npy,
}

/// What the readers, `detect`, `serve` and their messages know of one format: adding a format is
/// a variant, a row of [`FORMATS`] and its parser in [`parse_cloud_within`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FormatInfo {
    /// The format.
    pub format: CloudFormat,
    /// Its short name in reports and `?format=` (`pcd`).
    pub name: &'static str,
    /// Other names `?format=` accepts.
    pub aliases: &'static [&'static str],
    /// How messages call it (`KITTI .bin`).
    pub title: &'static str,
    /// File extensions, lower case, without the dot.
    pub extensions: &'static [&'static str],
    /// Media types a request may name it by, the preferred one first.
    pub media_types: &'static [&'static str],
    /// What in the bytes says it is this format, if anything.
    pub signature: Option<&'static str>,
}

/// Every format read, in the order messages list them.
pub const FORMATS: [FormatInfo; 4] = [
    FormatInfo {
        format: CloudFormat::Pcd,
        name: "pcd",
        aliases: &[],
        title: "PCD",
        extensions: &["pcd"],
        media_types: &["application/x-pcd", "application/pcd", "text/x-pcd"],
        signature: Some("a PCD header"),
    },
    FormatInfo {
        format: CloudFormat::KittiBin,
        name: "bin",
        aliases: &["kitti"],
        title: "KITTI .bin",
        extensions: &["bin"],
        media_types: &["application/x-kitti-bin"],
        signature: None,
    },
    FormatInfo {
        format: CloudFormat::NuScenesBin,
        name: "nuscenes",
        aliases: &["pcd.bin"],
        title: "nuScenes .pcd.bin",
        extensions: &["pcd.bin"],
        media_types: &["application/x-nuscenes-bin"],
        signature: None,
    },
    FormatInfo {
        format: CloudFormat::Npy,
        name: "npy",
        aliases: &[],
        title: ".npy",
        extensions: &["npy"],
        media_types: &["application/x-npy", "application/npy"],
        signature: Some("NPY magic"),
    },
];

/// `a, b or c`.
fn or_list(items: impl IntoIterator<Item = String>) -> String {
    let items: Vec<String> = items.into_iter().collect();
    match items.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        Some((last, _)) => last.clone(),
        None => String::new(),
    }
}

impl FormatInfo {
    /// The formats' titles for a message: `PCD, KITTI .bin or .npy`.
    pub fn titles() -> String {
        or_list(FORMATS.iter().map(|f| f.title.to_string()))
    }

    /// The extensions for a message: `.pcd, .bin or .npy`.
    pub fn extensions() -> String {
        or_list(FORMATS.iter().flat_map(|f| f.extensions.iter().map(|e| format!(".{e}"))))
    }

    /// The names `?format=` takes: `pcd|bin|nuscenes|npy`.
    pub fn names() -> String {
        FORMATS.iter().map(|f| f.name).collect::<Vec<_>>().join("|")
    }

    /// The preferred media types for a message.
    pub fn media_types() -> String {
        or_list(FORMATS.iter().map(|f| f.media_types[0].to_string()))
    }

    /// What the signed formats carry, for a message: `a PCD header or NPY magic`.
    pub fn signatures() -> String {
        or_list(FORMATS.iter().filter_map(|f| f.signature.map(str::to_string)))
    }
}

impl CloudFormat {
    /// Its row of [`FORMATS`].
    pub fn info(self) -> &'static FormatInfo {
        FORMATS.iter().find(|f| f.format == self).expect("every format has a row")
    }

    /// The format a file's name says (`.pcd`, `.bin`, `.pcd.bin`, `.npy`, any case; the longest
    /// matching ending wins, so `x.pcd.bin` is nuScenes', `x.bin` KITTI's).
    pub fn from_extension(path: &Path) -> Option<Self> {
        let name = path.file_name()?.to_str()?.to_ascii_lowercase();
        FORMATS
            .iter()
            .flat_map(|f| f.extensions.iter().map(move |e| (f.format, *e)))
            .filter(|(_, e)| name.len() > e.len() + 1 && name.ends_with(e) && name.as_bytes()[name.len() - e.len() - 1] == b'.')
            .max_by_key(|(_, e)| e.len())
            .map(|(f, _)| f)
    }

    /// The format a short name or alias says (`pcd`, `bin`, `kitti`, `npy`, any case).
    pub fn from_name(name: &str) -> Option<Self> {
        let name = name.trim().to_ascii_lowercase();
        FORMATS.iter().find(|f| f.name == name || f.aliases.contains(&name.as_str())).map(|f| f.format)
    }

    /// The format a media type names (parameters and case ignored).
    pub fn from_media_type(content_type: &str) -> Option<Self> {
        let essence = content_type.split(';').next().unwrap_or("").trim().to_ascii_lowercase();
        FORMATS.iter().find(|f| f.media_types.contains(&essence.as_str())).map(|f| f.format)
    }

    /// The format the bytes announce: NPY's magic, or a PCD header's first keyword. A `.bin`
    /// has no signature.
    pub fn sniff(bytes: &[u8]) -> Option<Self> {
        if bytes.starts_with(b"\x93NUMPY") {
            return Some(Self::Npy);
        }
        let head = &bytes[..bytes.len().min(64)];
        let text = String::from_utf8_lossy(head);
        let first = text.lines().map(str::trim).find(|l| !l.is_empty() && !l.starts_with('#'));
        let commented_pcd = text.trim_start().starts_with("# .PCD");
        (commented_pcd || first.is_some_and(|l| l.starts_with("VERSION") || l.starts_with("FIELDS"))).then_some(Self::Pcd)
    }
}

/// A cloud read from a file or a buffer.
#[derive(Debug, Clone, PartialEq)]
pub struct Cloud {
    /// The finite points, in the file's frame and order.
    pub points: Vec<[f32; 3]>,
    /// Points dropped for a non-finite coordinate.
    pub dropped_non_finite: usize,
    /// The format it was read as.
    pub format: CloudFormat,
}

/// Reads a cloud file: the format from its bytes where they say, else from its extension.
pub fn read_cloud(path: &Path) -> Result<Cloud> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    let format = CloudFormat::sniff(&bytes).or_else(|| CloudFormat::from_extension(path)).ok_or_else(|| {
        DataError::new(
            path,
            ErrorKind::Layout(format!("not a point cloud this reads: no {}, and not named {}", FormatInfo::signatures(), FormatInfo::extensions())),
        )
    })?;
    parse_cloud(&bytes, format).map_err(|kind| DataError::new(path, kind))
}

/// Bounds on what one input may make a reader decode, checked before it is decoded: what a
/// service bounds one request's memory with. Whatever the bounds, every size an input states
/// (PCD's points, fields and compressed sizes, NPY's shape) is checked against the bytes present
/// before memory is reserved for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadLimits {
    /// Most points (finite or not) a cloud may hold.
    pub max_points: usize,
    /// Most bytes its data may decode to (a compressed PCD's uncompressed size).
    pub max_data_bytes: usize,
}

impl ReadLimits {
    /// No bounds beyond the bytes present.
    pub const NONE: Self = Self { max_points: usize::MAX, max_data_bytes: usize::MAX };

    pub(crate) fn check_points(&self, n: usize) -> std::result::Result<(), ErrorKind> {
        if n > self.max_points {
            return Err(ErrorKind::OverLimit(format!("{n} points, more than the {} accepted", self.max_points)));
        }
        Ok(())
    }

    pub(crate) fn check_data_bytes(&self, n: usize) -> std::result::Result<(), ErrorKind> {
        if n > self.max_data_bytes {
            return Err(ErrorKind::OverLimit(format!("data of {n} bytes uncompressed, more than the {} accepted", self.max_data_bytes)));
        }
        Ok(())
    }
}

/// Parses a cloud from bytes in `format`.
pub fn parse_cloud(bytes: &[u8], format: CloudFormat) -> std::result::Result<Cloud, ErrorKind> {
    parse_cloud_within(bytes, format, &ReadLimits::NONE)
}

/// As [`parse_cloud`], refusing a cloud beyond `limits` before it is decoded.
pub fn parse_cloud_within(bytes: &[u8], format: CloudFormat, limits: &ReadLimits) -> std::result::Result<Cloud, ErrorKind> {
    let finite = |raw: Vec<[f32; 3]>| {
        let before = raw.len();
        let points: Vec<[f32; 3]> = raw.into_iter().filter(|p| p.iter().all(|v| v.is_finite())).collect();
        (before - points.len(), points)
    };
    let (dropped_non_finite, points) = match format {
        // The PCD reader drops them itself.
        CloudFormat::Pcd => {
            let pcd = parse_pcd_within(bytes, NonFinite::Drop, limits, false)?;
            (pcd.dropped_non_finite, pcd.xyz)
        }
        CloudFormat::KittiBin => finite(float_records(bytes, 4, "a KITTI .bin", limits)?),
        CloudFormat::NuScenesBin => finite(float_records(bytes, 5, "a nuScenes .pcd.bin", limits)?),
        CloudFormat::Npy => finite(npy(bytes, limits)?),
    };
    Ok(Cloud { points, dropped_non_finite, format })
}

/// Little-endian float32 records of `fields` values, x, y, z first (KITTI's 4, nuScenes' 5).
fn float_records(bytes: &[u8], fields: usize, what: &str, limits: &ReadLimits) -> std::result::Result<Vec<[f32; 3]>, ErrorKind> {
    let record = 4 * fields;
    if bytes.len() % record != 0 {
        return Err(ErrorKind::Mismatch(format!(
            "{what} holds records of {fields} float32 ({record} bytes); {} bytes is {} records and {} bytes over",
            bytes.len(),
            bytes.len() / record,
            bytes.len() % record
        )));
    }
    limits.check_points(bytes.len() / record)?;
    let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    Ok(bytes.chunks_exact(record).map(|r| [f(&r[0..4]), f(&r[4..8]), f(&r[8..12])]).collect())
}

/// NumPy's `.npy` (format versions 1–3): the magic, a header length, a Python-literal header
/// `{'descr': '<f4', 'fortran_order': False, 'shape': (N, 3), }`, then the data.
fn npy(bytes: &[u8], limits: &ReadLimits) -> std::result::Result<Vec<[f32; 3]>, ErrorKind> {
    let bad = |what: String| ErrorKind::Mismatch(format!("NPY: {what}"));
    let header_error = |what: &str| ErrorKind::Parse(format!("NPY header: {what}"));
    if !bytes.starts_with(b"\x93NUMPY") || bytes.len() < 10 {
        return Err(header_error("no NPY magic"));
    }
    let (len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        v => return Err(header_error(&format!("format version {v} is not one of 1, 2, 3"))),
    };
    let header = bytes.get(start..start + len).ok_or_else(|| header_error("shorter than its stated length"))?;
    let header = std::str::from_utf8(header).map_err(|_| header_error("not text"))?;
    let value = |key: &str| -> std::result::Result<&str, ErrorKind> {
        let at = header.find(&format!("'{key}'")).ok_or_else(|| header_error(&format!("no '{key}'")))?;
        let rest = header[at + key.len() + 2..].trim_start().strip_prefix(':').ok_or_else(|| header_error(&format!("'{key}' has no value")))?;
        Ok(rest.trim_start())
    };
    let descr = value("descr")?;
    let descr = descr.strip_prefix('\'').and_then(|d| d.split('\'').next()).ok_or_else(|| header_error("'descr' is not a string"))?;
    if value("fortran_order")?.starts_with("True") {
        return Err(bad("column-major (Fortran-order) arrays are not read; save with np.ascontiguousarray".into()));
    }
    let shape = value("shape")?;
    let shape = shape.strip_prefix('(').and_then(|s| s.split(')').next()).ok_or_else(|| header_error("'shape' is not a tuple"))?;
    let dims: Vec<usize> = shape.split(',').map(str::trim).filter(|d| !d.is_empty()).map(|d| d.parse().map_err(|_| header_error(&format!("shape entry `{d}`")))).collect::<std::result::Result<_, _>>()?;
    let [n, c] = dims[..] else { return Err(bad(format!("expected a 2-D array (N×3 or N×4), got shape {dims:?}"))) };
    if c != 3 && c != 4 {
        return Err(bad(format!("expected 3 (x, y, z) or 4 (x, y, z, intensity) columns, got {c}")));
    }
    let size = match descr {
        "<f4" | "=f4" => 4,
        "<f8" | "=f8" => 8,
        other => return Err(bad(format!("dtype `{other}`; expected little-endian float32 (<f4) or float64 (<f8)"))),
    };
    let data = &bytes[start + len..];
    let need = n.checked_mul(c * size).ok_or_else(|| bad(format!("shape {n}×{c} of {size}-byte floats overflows")))?;
    if data.len() < need {
        return Err(ErrorKind::Truncated(format!("NPY data has {} bytes, its shape {n}×{c} of {size}-byte floats needs {need}", data.len())));
    }
    if data.len() > need {
        return Err(bad(format!("{} data bytes, its shape {n}×{c} of {size}-byte floats declares {need}", data.len())));
    }
    limits.check_points(n)?;
    let at = |i: usize| -> f32 {
        let b = &data[i * size..(i + 1) * size];
        if size == 4 { f32::from_le_bytes([b[0], b[1], b[2], b[3]]) } else { f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) as f32 }
    };
    Ok((0..n).map(|r| [at(r * c), at(r * c + 1), at(r * c + 2)]).collect())
}

/// An NPY file as NumPy's `np.save` writes format 1.0 (C order, the header padded to 64 bytes):
/// `descr` is the dtype (`<f4`), `shape` the Python tuple (`(N, 3)`), `data` the raw array. For
/// fixtures and tests, odd shapes included.
pub fn encode_npy(descr: &str, shape: &str, data: &[u8]) -> Vec<u8> {
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.as_bytes());
    out.extend(data);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_format_reads_the_same_points() {
        let pts = [[1.0f32, 2.0, 3.0], [-4.5, 0.25, -0.7], [f32::NAN, 1.0, 1.0]];
        let bin: Vec<u8> = pts.iter().flat_map(|p| p.iter().chain(&[0.5f32]).flat_map(|v| v.to_le_bytes())).collect();
        let f4: Vec<u8> = pts.iter().flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes())).collect();
        let f8x4: Vec<u8> = pts.iter().flat_map(|p| p.iter().chain(&[9.0]).flat_map(|&v| (v as f64).to_le_bytes())).collect();
        let nus: Vec<u8> = pts.iter().flat_map(|p| p.iter().chain(&[0.5f32, 17.0]).flat_map(|v| v.to_le_bytes())).collect();
        let want = vec![pts[0], pts[1]];
        for (bytes, format) in [
            (bin, CloudFormat::KittiBin),
            (nus, CloudFormat::NuScenesBin),
            (encode_npy("<f4", "(3, 3)", &f4), CloudFormat::Npy),
            (encode_npy("<f8", "(3, 4)", &f8x4), CloudFormat::Npy),
        ] {
            let c = parse_cloud(&bytes, format).unwrap();
            assert_eq!((c.points, c.dropped_non_finite), (want.clone(), 1), "{format:?}");
        }
    }

    #[test]
    fn formats_are_recognised_from_bytes_then_names() {
        assert_eq!(CloudFormat::sniff(&encode_npy("<f4", "(0, 3)", &[])), Some(CloudFormat::Npy));
        assert_eq!(CloudFormat::sniff(b"# .PCD v0.7 - Point Cloud Data\nVERSION 0.7\n"), Some(CloudFormat::Pcd));
        assert_eq!(CloudFormat::sniff(b"VERSION 0.7\nFIELDS x y z\n"), Some(CloudFormat::Pcd));
        assert_eq!(CloudFormat::sniff(&[0u8; 32]), None);
        assert_eq!(CloudFormat::from_extension(Path::new("a/000001.BIN")), Some(CloudFormat::KittiBin));
        let nus = "n008-2018-08-01-15-16-36-0400__LIDAR_TOP__1533151603547590.pcd.bin";
        assert_eq!(CloudFormat::from_extension(Path::new(nus)), Some(CloudFormat::NuScenesBin));
        assert_eq!(CloudFormat::from_extension(Path::new("x.PCD.BIN")), Some(CloudFormat::NuScenesBin));
        assert_eq!(CloudFormat::from_extension(Path::new("pcd.bin")), Some(CloudFormat::KittiBin), "a bare name has no .pcd ending");
        assert_eq!(CloudFormat::from_extension(Path::new("a.xpcd.bin")), Some(CloudFormat::KittiBin));
        assert_eq!(CloudFormat::from_extension(Path::new("scan.ply")), None);
        assert_eq!((CloudFormat::from_name("KITTI"), CloudFormat::from_name("ply")), (Some(CloudFormat::KittiBin), None));
        assert_eq!(CloudFormat::from_media_type("Application/X-NPY; q=1"), Some(CloudFormat::Npy));
        assert_eq!((FormatInfo::titles().as_str(), FormatInfo::extensions().as_str()), ("PCD, KITTI .bin, nuScenes .pcd.bin or .npy", ".pcd, .bin, .pcd.bin or .npy"));
        assert_eq!(FormatInfo::signatures(), "a PCD header or NPY magic");
        assert!(FORMATS.iter().all(|f| f.format.info() == f));
    }

    #[test]
    fn malformed_clouds_say_what_is_wrong() {
        let e = parse_cloud(&[0u8; 20], CloudFormat::KittiBin).unwrap_err().to_string();
        assert!(e.contains("16 bytes") && e.contains("4 bytes over"), "{e}");
        // A KITTI file named as nuScenes' (or the reverse) is refused, not misread, unless its
        // size happens to fit both (a multiple of 80 bytes).
        let e = parse_cloud(&[0u8; 32], CloudFormat::NuScenesBin).unwrap_err().to_string();
        assert!(e.contains("nuScenes .pcd.bin") && e.contains("20 bytes") && e.contains("12 bytes over"), "{e}");
        let e = parse_cloud(&encode_npy("<f4", "(2, 5)", &[0u8; 40]), CloudFormat::Npy).unwrap_err().to_string();
        assert!(e.contains("got 5"), "{e}");
        let e = parse_cloud(&encode_npy("<i4", "(1, 3)", &[0u8; 12]), CloudFormat::Npy).unwrap_err().to_string();
        assert!(e.contains("float32"), "{e}");
        let e = parse_cloud(&encode_npy("<f4", "(3,)", &[0u8; 12]), CloudFormat::Npy).unwrap_err().to_string();
        assert!(e.contains("2-D"), "{e}");
        let e = parse_cloud(&encode_npy("<f4", "(4, 3)", &[0u8; 12]), CloudFormat::Npy).unwrap_err().to_string();
        assert!(e.contains("NPY"), "{e}");
        let e = parse_cloud(b"\x93NUMPY\x01", CloudFormat::Npy).unwrap_err().to_string();
        assert!(e.contains("NPY header"), "{e}");
    }
}
