//! The real scans of `real-scans/` (docs/real-scans.md), as other tools wrote them: a Hesai-class
//! 40-beam scan saved by SUSTechPOINTS (binary PCD with PCL padding fields, a COUNT 0 field and
//! zeros after the last point), nuScenes' HDL-32E and Argoverse 2's two VLP-32C (as `.npy`). Each
//! reads with every point its source states and almost all of it inside the default working volume.

use std::path::Path;

use data_jrdb::{Volume, read_cloud};

#[test]
fn every_real_scan_reads_with_the_points_its_source_states() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../real-scans");
    for (file, points) in [
        ("sustechpoints/000950.pcd", 68_242),
        ("sustechpoints/000975.pcd", 67_153),
        ("nuscenes/1532402927647951.npy", 34_688),
        ("argoverse2/7fab2350-315966265259836000.npy", 99_229),
        ("argoverse2/7fab2350-315966265360032000.npy", 99_466),
        ("argoverse2/adcf7d18-315973157959879000.npy", 100_660),
    ] {
        let c = read_cloud(&root.join(file)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.points.len() + c.dropped_non_finite, points, "{file}");
        let mut kept = c.points.clone();
        let outside = Volume::default().crop(&mut kept);
        // Argoverse 2's sensors reach 200 m: about 1 % of their returns lie beyond the volume's 100 m.
        assert!(outside * 50 < points, "{file}: {outside} points outside the default volume");
    }
}
