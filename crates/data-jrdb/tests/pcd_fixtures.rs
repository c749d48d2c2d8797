//! Hand-written PCD files in every encoding, and every kind of malformed PCD.

use std::path::PathBuf;

use data_jrdb::pcd::{NonFinite, read_pcd};
use data_jrdb::{ErrorKind, lzf};

const POINTS: [[f32; 3]; 3] = [[1.0, 2.0, 3.0], [-0.5, 0.25, -1.5], [10.125, -20.0, 0.0]];

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("pcd-fixtures-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write(name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir().join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// Header with fields `intensity x y z ring` (intensity F4, xyz F4, ring U2), as PCL writes it.
fn header(n: usize, data: &str) -> String {
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS intensity x y z ring\nSIZE 4 4 4 4 2\nTYPE F F F F U\nCOUNT 1 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    )
}

fn binary_body() -> Vec<u8> {
    let mut b = Vec::new();
    for (i, p) in POINTS.iter().enumerate() {
        b.extend((i as f32 * 10.0).to_le_bytes());
        for v in p {
            b.extend(v.to_le_bytes());
        }
        b.extend((i as u16).to_le_bytes());
    }
    b
}

fn columns_raw() -> Vec<u8> {
    let mut raw = Vec::new();
    raw.extend(POINTS.iter().enumerate().flat_map(|(i, _)| (i as f32 * 10.0).to_le_bytes()));
    for k in 0..3 {
        raw.extend(POINTS.iter().flat_map(|p| p[k].to_le_bytes()));
    }
    raw.extend((0..3u16).flat_map(|i| i.to_le_bytes()));
    raw
}

/// An LZF block made only of literal runs (valid liblzf input, independent of our compressor).
fn literal_lzf(raw: &[u8]) -> Vec<u8> {
    raw.chunks(32).flat_map(|c| std::iter::once((c.len() - 1) as u8).chain(c.iter().copied())).collect()
}

fn compressed(raw: &[u8], block: &[u8]) -> Vec<u8> {
    let mut b = header(3, "binary_compressed").into_bytes();
    b.extend((block.len() as u32).to_le_bytes());
    b.extend((raw.len() as u32).to_le_bytes());
    b.extend(block);
    b
}

#[test]
fn three_encodings_parse_to_the_same_points() {
    let ascii = header(3, "ascii") + "0 1 2 3 0\n10 -0.5 0.25 -1.5 1\n20 10.125 -20 0 2\n";
    let mut binary = header(3, "binary").into_bytes();
    binary.extend(binary_body());
    let raw = columns_raw();
    let files = [
        write("a.pcd", ascii.as_bytes()),
        write("b.pcd", &binary),
        write("c_literal.pcd", &compressed(&raw, &literal_lzf(&raw))),
        write("c_lzf.pcd", &compressed(&raw, &lzf::compress(&raw))),
    ];
    for f in &files {
        let pc = read_pcd(f, NonFinite::Drop).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(pc.xyz, POINTS, "{}", f.display());
        assert_eq!(pc.field("intensity").unwrap(), &[0.0, 10.0, 20.0]);
        assert_eq!(pc.field("ring").unwrap(), &[0.0, 1.0, 2.0]);
        assert_eq!(pc.dropped_non_finite, 0);
    }
}

#[test]
fn count_double_and_nan_fields() {
    // xyz as doubles, a 2-element field in front, NaN rows dropped and counted.
    let text = "VERSION .7\nFIELDS rgb_pair z y x\nSIZE 1 8 8 8\nTYPE U F F F\nCOUNT 2 1 1 1\nWIDTH 2\nHEIGHT 2\nPOINTS 4\nDATA ascii\n\
                1 2 3 2 1\n3 4 nan 0 0\n5 6 -1.5 0.25 -0.5\n7 8 0 0 inf\n";
    let f = write("count.pcd", text.as_bytes());
    let pc = read_pcd(&f, NonFinite::Drop).unwrap();
    assert_eq!(pc.xyz, vec![[1.0, 2.0, 3.0], [-0.5, 0.25, -1.5]]);
    assert_eq!(pc.dropped_non_finite, 2);
    assert_eq!(pc.field("rgb_pair").unwrap(), &[1.0, 5.0]);
    let e = read_pcd(&f, NonFinite::Error).unwrap_err();
    assert!(matches!(e.kind, ErrorKind::NonFinite(_)), "{e}");
    assert!(e.to_string().contains("count.pcd"));
}

fn expect(name: &str, bytes: &[u8], check: fn(&ErrorKind) -> bool) {
    let f = write(name, bytes);
    let e = read_pcd(&f, NonFinite::Drop).expect_err(name);
    assert!(check(&e.kind), "{name}: unexpected {e}");
    assert!(e.to_string().contains(name), "{e} should name the file");
}

#[test]
fn malformed_files_are_errors_naming_the_file() {
    let mut binary = header(3, "binary").into_bytes();
    binary.extend(binary_body());
    expect("trunc_bin.pcd", &binary[..binary.len() - 5], |k| matches!(k, ErrorKind::Truncated(_)));
    let mut extra = binary.clone();
    extra.extend([0u8, 0, 3, 0, 0, 0, 0]);
    expect("extra_bin.pcd", &extra, |k| matches!(k, ErrorKind::Mismatch(_)));
    // Zero padding after the last point (as SUSTechPOINTS' example scans have) is read past.
    let mut padded = binary.clone();
    padded.extend([0u8; 3848]);
    assert_eq!(read_pcd(&write("padded_bin.pcd", &padded), NonFinite::Drop).unwrap().xyz, POINTS);
    let raw = columns_raw();
    let c = compressed(&raw, &lzf::compress(&raw));
    expect("trunc_comp.pcd", &c[..c.len() - 3], |k| matches!(k, ErrorKind::Truncated(_)));
    let mut bad_size = compressed(&raw, &literal_lzf(&raw));
    let at = header(3, "binary_compressed").len() + 4;
    bad_size[at..at + 4].copy_from_slice(&((raw.len() + 4) as u32).to_le_bytes());
    expect("size_comp.pcd", &bad_size, |k| matches!(k, ErrorKind::Mismatch(_)));
    let mut corrupt = compressed(&raw, &literal_lzf(&raw));
    corrupt[at + 4] = 0x20; // the first control byte becomes a back-reference before the start
    expect("corrupt_comp.pcd", &corrupt, |k| matches!(k, ErrorKind::Mismatch(_) | ErrorKind::Truncated(_)));
    expect("unknown_data.pcd", (header(3, "binary_lzma") + "xx").as_bytes(), |k| matches!(k, ErrorKind::UnknownData(_)));
    expect("trunc_ascii.pcd", (header(3, "ascii") + "0 1 2 3 0\n").as_bytes(), |k| matches!(k, ErrorKind::Truncated(_)));
    // Too short to hold the declared values at all: refused before any line is read.
    expect("short_file.pcd", (header(1, "ascii") + "0 1 2 3\n").as_bytes(), |k| matches!(k, ErrorKind::Truncated(_)));
    expect("short_row.pcd", (header(2, "ascii") + "0 1 2 3\n0 1 2 3 4 5 6\n").as_bytes(), |k| matches!(k, ErrorKind::Mismatch(_)));
    expect("long_row.pcd", (header(1, "ascii") + "0 1 2 3 4 5\n").as_bytes(), |k| matches!(k, ErrorKind::Mismatch(_)));
    expect("bad_value.pcd", (header(1, "ascii") + "0 1 two 3 4\n").as_bytes(), |k| matches!(k, ErrorKind::Mismatch(_)));
    expect("extra_rows.pcd", (header(1, "ascii") + "0 1 2 3 4\n0 1 2 3 4\n").as_bytes(), |k| matches!(k, ErrorKind::Mismatch(_)));
    let wh = header(3, "ascii").replace("WIDTH 3", "WIDTH 4");
    expect("points_vs_width.pcd", wh.as_bytes(), |k| matches!(k, ErrorKind::PcdHeader(_)));
    let sizes = header(3, "ascii").replace("SIZE 4 4 4 4 2", "SIZE 4 4 4 4");
    expect("size_count.pcd", sizes.as_bytes(), |k| matches!(k, ErrorKind::PcdHeader(_)));
    let nox = header(3, "ascii").replace("FIELDS intensity x y z ring", "FIELDS intensity u y z ring");
    expect("no_x.pcd", nox.as_bytes(), |k| matches!(k, ErrorKind::PcdHeader(_)));
    expect("no_data.pcd", header(3, "ascii").replace("DATA ascii\n", "").as_bytes(), |k| matches!(k, ErrorKind::PcdHeader(_)));
    expect("f2.pcd", header(3, "ascii").replace("SIZE 4 4", "SIZE 2 4").as_bytes(), |k| matches!(k, ErrorKind::PcdHeader(_)));
    let missing = dir().join("nope.pcd");
    let e = read_pcd(&missing, NonFinite::Drop).unwrap_err();
    assert!(matches!(e.kind, ErrorKind::Io(_)) && e.to_string().contains("nope.pcd"));
}
