//! Inputs written to hurt: every size a file states is checked against the bytes present before
//! memory is taken for it. Hand-written hostile files (sizes claiming billions of points,
//! overflowing products, an LZF bomb) get named errors; seeded mutations of valid files in every
//! format (the short, CI-sized property check beside `fuzz/`) never panic and never hold more
//! than a bounded multiple of their input. This binary counts the bytes each test
//! thread holds with its own allocator.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;

use data_jrdb::pcd::{Column, Encoding, FieldType, encode_pcd, parse_pcd};
use data_jrdb::{Calibration, CloudFormat, ErrorKind, NonFinite, ReadLimits, encode_npy, parse_cloud, parse_cloud_within, read_cloud};
use rand::{Rng, SeedableRng};

/// Counts the bytes live on each thread and the peak since the last reset.
struct PerThread;

thread_local! {
    static LIVE: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

fn add(n: isize) {
    let _ = LIVE.try_with(|l| {
        l.set(l.get() + n);
        let _ = PEAK.try_with(|p| p.set(p.get().max(l.get())));
    });
}

unsafe impl GlobalAlloc for PerThread {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        add(layout.size() as isize);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        add(-(layout.size() as isize));
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        add(new_size as isize - layout.size() as isize);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOC: PerThread = PerThread;

/// The most bytes `f` held at once beyond what was live when it started.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(base));
    let out = f();
    (out, (PEAK.with(Cell::get) - base).max(0) as usize)
}

fn pcd_header(fields: &str, sizes: &str, types: &str, counts: &str, width: &str, height: &str, points: &str, data: &str) -> Vec<u8> {
    format!("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {sizes}\nTYPE {types}\nCOUNT {counts}\nWIDTH {width}\nHEIGHT {height}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA {data}\n").into_bytes()
}

fn npy_file(shape: &str, data: &[u8]) -> Vec<u8> {
    encode_npy("<f4", shape, data)
}

/// Parses `bytes` as `format`, expecting an error that `check` accepts, within a few kilobytes.
fn refused(name: &str, bytes: &[u8], format: CloudFormat, check: fn(&ErrorKind) -> bool, says: &str) {
    let (res, peak) = peak_of(|| parse_cloud(bytes, format));
    let e = res.expect_err(name);
    assert!(check(&e), "{name}: unexpected {e}");
    assert!(e.to_string().contains(says), "{name}: `{e}` should say `{says}`");
    assert!(peak < 64 << 10, "{name}: held {peak} bytes to refuse a {}-byte input", bytes.len());
}

#[test]
fn sizes_are_checked_against_the_bytes_present_before_memory_is_taken() {
    let claim = |data: &str| {
        let mut b = pcd_header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", "4000000000", "1", "4000000000", data);
        b.resize(271, b'1');
        b
    };
    let truncated = |k: &ErrorKind| matches!(k, ErrorKind::Truncated(_));
    let mismatch = |k: &ErrorKind| matches!(k, ErrorKind::Mismatch(_));
    let header = |k: &ErrorKind| matches!(k, ErrorKind::PcdHeader(_));
    refused("4e9 points, binary", &claim("binary"), CloudFormat::Pcd, truncated, "4000000000 points");
    refused("4e9 points, ascii", &claim("ascii"), CloudFormat::Pcd, truncated, "4000000000 points");
    let mut lzf = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", "100000000", "1", "100000000", "binary_compressed");
    lzf.extend(16u32.to_le_bytes());
    lzf.extend(1_200_000_000u32.to_le_bytes());
    lzf.extend([0u8; 16]);
    refused("an LZF block claiming 75 million times its size", &lzf, CloudFormat::Pcd, mismatch, "cannot come from a 16-byte LZF block");
    let wh = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", "4294967296", "4294967296", "1", "binary");
    refused("WIDTH x HEIGHT overflowing", &wh, CloudFormat::Pcd, header, "overflows");
    let count = pcd_header("x y z pad", "4 4 4 8", "F F F F", "1 1 1 2000000000", "1", "1", "1", "binary");
    refused("COUNT 2e9, binary", &count, CloudFormat::Pcd, truncated, "16000000012");
    let count = pcd_header("x y z pad", "4 4 4 8", "F F F F", "1 1 1 2000000000", "1", "1", "1", "ascii");
    refused("COUNT 2e9, ascii", &count, CloudFormat::Pcd, truncated, "2000000003 values");
    let count = pcd_header("x y z pad", "8 8 8 8", "F F F F", "1 1 1 18446744073709551615", "1", "1", "1", "binary");
    refused("SIZE x COUNT overflowing", &count, CloudFormat::Pcd, header, "overflows");
    refused("an NPY of 10^12 x 3", &npy_file("(1000000000000, 3)", &[]), CloudFormat::Npy, truncated, "NPY data has 0 bytes");
    refused("an NPY whose shape overflows", &npy_file("(9223372036854775807, 3)", &[]), CloudFormat::Npy, mismatch, "overflows");
    assert!(parse_cloud(&npy_file("(1000000000000, 3)", &[]), CloudFormat::Npy).unwrap_err().to_string().starts_with("truncated data: NPY"));
}

#[test]
fn limits_refuse_large_clouds_from_their_stated_size() {
    let limits = ReadLimits { max_points: 10, max_data_bytes: 1 << 10 };
    let over = |k: &ErrorKind| matches!(k, ErrorKind::OverLimit(_));
    let points: Vec<[f32; 3]> = (0..11).map(|i| [i as f32, 0.0, 0.0]).collect();
    let cols = |pts: &[[f32; 3]]| -> Vec<Column> {
        (0..3).map(|k| Column { name: ["x", "y", "z"][k].into(), ty: FieldType::F32, values: pts.iter().map(|p| p[k] as f64).collect() }).collect()
    };
    for enc in [Encoding::Ascii, Encoding::Binary, Encoding::BinaryCompressed] {
        let e = parse_cloud_within(&encode_pcd(&cols(&points), enc), CloudFormat::Pcd, &limits).unwrap_err();
        assert!(over(&e), "{enc:?}: {e}");
        assert!(parse_cloud_within(&encode_pcd(&cols(&points[..10]), enc), CloudFormat::Pcd, &limits).is_ok());
    }
    let bin: Vec<u8> = points.iter().flat_map(|p| [p[0], p[1], p[2], 0.0]).flat_map(f32::to_le_bytes).collect();
    assert!(over(&parse_cloud_within(&bin, CloudFormat::KittiBin, &limits).unwrap_err()));
    let f4: Vec<u8> = points.iter().flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes())).collect();
    assert!(over(&parse_cloud_within(&npy_file("(11, 3)", &f4), CloudFormat::Npy, &limits).unwrap_err()));
    // A compressed cloud within the point limit whose fields decode to more than the byte limit.
    let wide = pcd_header("x y z pad", "4 4 4 1", "F F F U", "1 1 1 4096", "1", "1", "1", "binary_compressed");
    let e = parse_cloud_within(&[wide, vec![0u8; 8]].concat(), CloudFormat::Pcd, &limits).unwrap_err();
    assert!(matches!(e, ErrorKind::OverLimit(_) | ErrorKind::Mismatch(_)), "{e}");
}

#[test]
fn real_pcd_layouts_load_padding_fields_count_zero_and_organised_clouds() {
    // PCL's padding (`_`), a field of COUNT 0 and one of COUNT 4, 2 rows of 2 with a NaN point.
    let mut b = pcd_header("x y z _ _ intensity normal", "4 4 4 1 4 4 4", "F F F U F F F", "1 1 1 4 0 1 3", "2", "2", "4", "binary");
    let rows = [[1.0f32, 2.0, 3.0, 9.0], [f32::NAN, f32::NAN, f32::NAN, 0.0], [4.0, 5.0, 6.0, 7.0], [-1.0, -2.0, -3.0, 8.0]];
    for r in rows {
        b.extend(r[..3].iter().flat_map(|v| v.to_le_bytes()));
        b.extend([0u8; 4]);
        b.extend(r[3].to_le_bytes());
        b.extend([0u8; 12]);
    }
    let pc = parse_pcd(&b, NonFinite::Drop).unwrap();
    assert_eq!(pc.xyz, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [-1.0, -2.0, -3.0]]);
    assert_eq!((pc.dropped_non_finite, pc.field("intensity").unwrap()), (1, &[9.0, 7.0, 8.0][..]));
    assert!(pc.field("_").is_none());
    let zero_x = pcd_header("x y z", "4 4 4", "F F F", "0 1 1", "1", "1", "1", "binary");
    assert!(parse_pcd(&zero_x, NonFinite::Drop).unwrap_err().to_string().contains("field `x` has COUNT 0"));
}

/// Valid files of every cloud format, to mutate.
fn seeds() -> Vec<(CloudFormat, Vec<u8>)> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(44);
    let pts: Vec<[f32; 3]> = (0..40).map(|_| [rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(-1.0..1.0)]).collect();
    let col = |name: &str, ty, k: usize| Column { name: name.into(), ty, values: pts.iter().map(|p| if k < 3 { p[k] as f64 } else { 7.0 }).collect() };
    let cols = vec![col("x", FieldType::F32, 0), col("intensity", FieldType::U8, 3), col("y", FieldType::F64, 1), col("z", FieldType::F32, 2)];
    let mut out: Vec<(CloudFormat, Vec<u8>)> =
        [Encoding::Ascii, Encoding::Binary, Encoding::BinaryCompressed].map(|e| (CloudFormat::Pcd, encode_pcd(&cols, e))).into();
    out.push((CloudFormat::KittiBin, pts.iter().flat_map(|p| [p[0], p[1], p[2], 1.0]).flat_map(f32::to_le_bytes).collect()));
    out.push((CloudFormat::Npy, npy_file("(40, 3)", &pts.iter().flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes())).collect::<Vec<u8>>())));
    out
}

/// One random edit: a flipped byte, a run overwritten, inserted or cut, the file truncated, or a
/// number in a header replaced by a large one.
fn mutate(bytes: &mut Vec<u8>, rng: &mut impl Rng) {
    let n = bytes.len().max(1);
    match rng.random_range(0..6) {
        0 => {
            let i = rng.random_range(0..n).min(bytes.len().saturating_sub(1));
            if let Some(b) = bytes.get_mut(i) {
                *b ^= 1 << rng.random_range(0..8);
            }
        }
        1 => {
            let i = rng.random_range(0..n);
            let len = rng.random_range(1..16);
            let fill: u8 = rng.random();
            for b in bytes.iter_mut().skip(i).take(len) {
                *b = fill;
            }
        }
        2 => {
            let i = rng.random_range(0..=bytes.len());
            let run: Vec<u8> = (0..rng.random_range(1..32)).map(|_| rng.random()).collect();
            bytes.splice(i..i, run);
        }
        3 => {
            let i = rng.random_range(0..n).min(bytes.len());
            let j = (i + rng.random_range(1..64)).min(bytes.len());
            bytes.drain(i..j);
        }
        4 => bytes.truncate(rng.random_range(0..n)),
        _ => {
            // Replace a decimal number (a header's count or size) with a large or extreme one.
            let digits: Vec<usize> = (0..bytes.len()).filter(|&i| bytes[i].is_ascii_digit()).collect();
            if let Some(&i) = digits.get(rng.random_range(0..digits.len().max(1))) {
                let j = (i..bytes.len()).find(|&j| !bytes[j].is_ascii_digit()).unwrap_or(bytes.len());
                let big = ["0", "4000000000", "18446744073709551615", "99999999999999999999999", "2147483648", "65536"][rng.random_range(0..6)];
                bytes.splice(i..j, big.bytes());
            }
        }
    }
}

#[test]
fn mutated_clouds_never_panic_and_never_hold_more_than_a_bounded_multiple_of_their_bytes() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2026);
    let (mut ok, mut refused) = (0, 0);
    for (format, seed) in seeds() {
        for _ in 0..1500 {
            let mut bytes = seed.clone();
            for _ in 0..rng.random_range(1..4) {
                mutate(&mut bytes, &mut rng);
            }
            // The cloud's points take at most 4x its bytes; a compressed PCD's block may first
            // expand 88-fold (LZF's largest), and its points again 4x that.
            let factor = if bytes.windows(17).any(|w| w == b"binary_compressed") { 5 * 88 + 4 } else { 5 };
            let as_sniffed = CloudFormat::sniff(&bytes).unwrap_or(format);
            let (res, peak) = peak_of(|| parse_cloud(&bytes, as_sniffed));
            assert!(peak <= factor * bytes.len() + (64 << 10), "{format:?}: {peak} bytes held for a {}-byte input {:?}", bytes.len(), String::from_utf8_lossy(&bytes[..bytes.len().min(300)]));
            match res {
                Ok(_) => ok += 1,
                Err(e) => {
                    assert!(!e.to_string().is_empty());
                    refused += 1;
                }
            }
        }
    }
    assert!(ok > 500 && refused > 2000, "the mutations should reach both outcomes: {ok} parsed, {refused} refused");
}

#[test]
fn mutated_calibration_and_labels_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let cal = dir.path().join("defaults.yaml");
    Calibration::default().write(&cal).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let yaml = std::fs::read(&cal).unwrap();
    let labels = br#"{"labels": {"000000.pcd": [{"label_id": "pedestrian:1", "box": {"cx": 1.0, "cy": 2.0, "cz": 0.1, "l": 0.5, "w": 0.6, "h": 1.7, "rot_z": 0.3}, "attributes": {"num_points": 42}, "observation_angle": 0.1}]}}"#.to_vec();
    for _ in 0..2000 {
        let (mut y, mut l) = (yaml.clone(), labels.clone());
        mutate(&mut y, &mut rng);
        mutate(&mut l, &mut rng);
        let _ = Calibration::parse(&String::from_utf8_lossy(&y), Path::new("defaults.yaml"));
        let _ = data_jrdb::labels::parse_labels_json(&String::from_utf8_lossy(&l), Path::new("labels.json"));
    }
    // A missing file is named.
    let e = read_cloud(&dir.path().join("absent.pcd")).unwrap_err();
    assert!(e.to_string().contains("absent.pcd"));
}

#[test]
fn every_recorded_hostile_input_is_refused_or_read_within_bounds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz_regressions/clouds");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let bytes = std::fs::read(&path).unwrap();
        let factor = if bytes.windows(17).any(|w| w == b"binary_compressed") { 5 * 88 + 4 } else { 5 };
        let (res, peak) = peak_of(|| read_cloud(&path));
        assert!(peak <= factor * bytes.len() + (64 << 10) + bytes.len(), "{}: held {peak} bytes", path.display());
        if let Err(e) = res {
            assert!(e.to_string().contains(path.file_name().unwrap().to_str().unwrap()), "{e} should name the file");
        }
        n += 1;
    }
    assert!(n >= 10, "{n} recorded inputs");
}
