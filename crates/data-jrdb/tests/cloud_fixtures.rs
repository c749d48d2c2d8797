//! Cloud files written by NumPy (`np.save`, float32 N×4 and float64 N×3) and a KITTI `.bin`
//! written with `ndarray.tofile`, all holding the same three points (the last with a NaN), read
//! through `read_cloud`. Made with:
//!
//! ```python
//! a = np.array([[1.5, -2.25, 0.5, 7.0], [3.0, 4.0, -0.75, 1.0], [np.nan, 1, 1, 1]], dtype=np.float32)
//! np.save("cloud_f4x4.npy", a); np.save("cloud_f8x3.npy", a[:, :3].astype(np.float64)); a.tofile("cloud_kitti.bin")
//! ```

use std::path::Path;

use data_jrdb::{CloudFormat, read_cloud};

#[test]
fn numpy_and_kitti_files_read_the_same_points() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    for (name, format) in [("cloud_f4x4.npy", CloudFormat::Npy), ("cloud_f8x3.npy", CloudFormat::Npy), ("cloud_kitti.bin", CloudFormat::KittiBin)] {
        let c = read_cloud(&dir.join(name)).unwrap();
        assert_eq!(c.format, format, "{name}");
        assert_eq!(c.points, vec![[1.5, -2.25, 0.5], [3.0, 4.0, -0.75]], "{name}");
        assert_eq!(c.dropped_non_finite, 1, "{name}");
    }
}

#[test]
fn an_unknown_file_is_an_error_naming_it() {
    let p = std::env::temp_dir().join(format!("cloud-{}.ply", std::process::id()));
    std::fs::write(&p, b"ply\nformat ascii 1.0\n").unwrap();
    let e = read_cloud(&p).unwrap_err().to_string();
    assert!(e.contains(&p.display().to_string()) && e.contains(".npy"), "{e}");
}
