//! Voxel scenes for benchmarks: `.npy` coordinate files and a built-in LiDAR-like scene.

use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use sparse_conv::Coord;

/// Reads int32 or int64 voxel coordinates, `N×4` (batch, x, y, z) or `N×3` (batch 0), from a
/// NumPy `.npy` file (C order, little-endian).
pub fn read_npy_coords(path: &Path) -> anyhow::Result<Vec<Coord>> {
    let bytes = std::fs::read(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    parse_npy_coords(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

fn parse_npy_coords(bytes: &[u8]) -> anyhow::Result<Vec<Coord>> {
    anyhow::ensure!(bytes.len() >= 10 && &bytes[..6] == b"\x93NUMPY", "not a .npy file (bad magic)");
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            anyhow::ensure!(bytes.len() >= 12, "truncated .npy header");
            (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12)
        }
        v => anyhow::bail!("unsupported .npy version {v}"),
    };
    anyhow::ensure!(bytes.len() >= start + header_len, "truncated .npy header");
    let header = std::str::from_utf8(&bytes[start..start + header_len])?;
    let field = |name: &str| -> anyhow::Result<&str> {
        let at = header.find(&format!("'{name}'")).ok_or_else(|| anyhow::anyhow!("header has no '{name}'"))?;
        let rest = header[at..].split_once(':').map(|(_, r)| r.trim_start()).unwrap_or("");
        Ok(rest)
    };
    let descr = field("descr")?;
    let width = if descr.starts_with("'<i4'") {
        4
    } else if descr.starts_with("'<i8'") {
        8
    } else {
        anyhow::bail!("coordinates must be little-endian int32 or int64, header says {}", descr.split(',').next().unwrap_or(""))
    };
    anyhow::ensure!(field("fortran_order")?.starts_with("False"), "Fortran-order arrays are not supported");
    let shape = field("shape")?;
    let inner = shape.strip_prefix('(').and_then(|s| s.split(')').next()).ok_or_else(|| anyhow::anyhow!("malformed shape"))?;
    let dims: Vec<usize> = inner.split(',').map(str::trim).filter(|s| !s.is_empty()).map(str::parse).collect::<Result<_, _>>()?;
    anyhow::ensure!(dims.len() == 2 && (dims[1] == 3 || dims[1] == 4), "coordinates must be N×3 or N×4, got shape {dims:?}");
    let (n, cols) = (dims[0], dims[1]);
    let data = &bytes[start + header_len..];
    anyhow::ensure!(data.len() >= n * cols * width, "truncated .npy data: {} bytes for {n}×{cols} values", data.len());
    let value = |i: usize| -> i64 {
        let b = &data[i * width..(i + 1) * width];
        if width == 4 { i32::from_le_bytes(b.try_into().unwrap()) as i64 } else { i64::from_le_bytes(b.try_into().unwrap()) }
    };
    (0..n)
        .map(|r| {
            let row: Vec<i64> = (0..cols).map(|c| value(r * cols + c)).collect();
            let full = if cols == 4 { [row[0], row[1], row[2], row[3]] } else { [0, row[0], row[1], row[2]] };
            let mut c = [0i32; 4];
            for (d, v) in c.iter_mut().zip(full) {
                *d = i32::try_from(v).map_err(|_| anyhow::anyhow!("row {r}: coordinate {v} does not fit in i32"))?;
            }
            Ok(c)
        })
        .collect()
}

/// Writes `N×4` int32 coordinates as `.npy`.
pub fn write_npy_coords(path: &Path, coords: &[Coord]) -> std::io::Result<()> {
    let mut header = format!("{{'descr': '<i4', 'fortran_order': False, 'shape': ({}, 4), }}", coords.len());
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + coords.len() * 16);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for c in coords {
        for v in c {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::write(path, out)
}

/// Voxel size of the paper (x, y, z metres).
pub const VOXEL_SIZE: [f64; 3] = [0.05, 0.05, 0.1];

/// A seeded JRDB-like frame: two 16-beam LiDARs (z = +0.34 / −0.14 m, ±15°, 0.2° azimuth steps)
/// in a walled plaza with pillars and people, floor 0.72 m below the base frame, voxelized at
/// the paper's size. Stands in for `scene_jrdb_like.npy` where that file is not at hand.
pub fn synthetic_lidar_scene(seed: u64) -> Vec<Coord> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let floor = -0.72;
    let (half_x, half_y, wall_h) = (25.0, 17.5, 8.0);
    // Vertical cylinders (x, y, radius, z_top): pillars, then people.
    let mut cylinders: Vec<[f64; 4]> = Vec::new();
    for _ in 0..11 {
        cylinders.push([rng.random_range(-20.0..20.0), rng.random_range(-14.0..14.0), rng.random_range(0.3..0.8), floor + 4.0]);
    }
    for _ in 0..25 {
        let (r, a) = (rng.random_range(1.0..20.0), rng.random_range(0.0..std::f64::consts::TAU));
        cylinders.push([r * a.cos(), r * a.sin(), rng.random_range(0.2..0.3), floor + rng.random_range(1.5..1.9)]);
    }
    let mut points = Vec::new();
    for sensor_z in [0.34, -0.14] {
        for beam in 0..16 {
            let elev = (-15.0 + 2.0 * beam as f64).to_radians();
            for step in 0..1800 {
                if rng.random::<f64>() < 0.05 {
                    continue; // dropped return
                }
                let az = (step as f64 * 0.2).to_radians();
                let d = [elev.cos() * az.cos(), elev.cos() * az.sin(), elev.sin()];
                let mut t = 60.0f64;
                if d[2] < 0.0 {
                    t = t.min((floor - sensor_z) / d[2]);
                }
                for (bound, dir) in [(half_x, d[0]), (half_y, d[1])] {
                    if dir.abs() > 1e-9 {
                        t = t.min(bound / dir.abs());
                    }
                }
                for &[cx, cy, r, top] in &cylinders {
                    let (a, b) = (d[0] * d[0] + d[1] * d[1], -2.0 * (d[0] * cx + d[1] * cy));
                    let c = cx * cx + cy * cy - r * r;
                    let disc = b * b - 4.0 * a * c;
                    if disc >= 0.0 && a > 0.0 {
                        let hit = (-b - disc.sqrt()) / (2.0 * a);
                        let z = sensor_z + hit * d[2];
                        if hit > 0.0 && hit < t && z >= floor && z <= top {
                            t = hit;
                        }
                    }
                }
                let z = sensor_z + t * d[2];
                if t >= 60.0 || z > floor + wall_h {
                    continue;
                }
                let t = t + rng.random_range(-0.01..0.01);
                points.push([t * d[0], t * d[1], sensor_z + t * d[2]]);
            }
        }
    }
    voxelize(&points)
}

/// Unique voxels of `points` at [`VOXEL_SIZE`], first point first, batch 0.
fn voxelize(points: &[[f64; 3]]) -> Vec<Coord> {
    let mut seen = std::collections::HashSet::new();
    points
        .iter()
        .map(|p| [0, (p[0] / VOXEL_SIZE[0]).floor() as i32, (p[1] / VOXEL_SIZE[1]).floor() as i32, (p[2] / VOXEL_SIZE[2]).floor() as i32])
        .filter(|c| seen.insert(*c))
        .collect()
}

/// The scene tiled `times` times as extra batch samples: same geometry, `times`× the voxels.
pub fn tile_as_batch(coords: &[Coord], times: usize) -> Vec<Coord> {
    let samples = coords.iter().map(|c| c[0]).max().map_or(1, |b| b + 1);
    (0..times as i32).flat_map(|t| coords.iter().map(move |c| [c[0] + t * samples, c[1], c[2], c[3]])).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npy_round_trip_and_errors() {
        let coords = vec![[0, -1, 2, 3], [1, 4, -5, 6]];
        let dir = std::env::temp_dir().join(format!("pmunet-npy-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("c.npy");
        write_npy_coords(&path, &coords).unwrap();
        assert_eq!(read_npy_coords(&path).unwrap(), coords);
        let bytes = std::fs::read(&path).unwrap();
        assert!(parse_npy_coords(&bytes[..bytes.len() - 3]).unwrap_err().to_string().contains("truncated"));
        assert!(parse_npy_coords(b"not numpy at all").is_err());
        assert!(read_npy_coords(&dir.join("missing.npy")).unwrap_err().to_string().contains("missing.npy"));
    }

    #[test]
    fn synthetic_scene_is_lidar_sized_and_deterministic() {
        let a = synthetic_lidar_scene(7);
        assert!((20_000..60_000).contains(&a.len()), "{} voxels", a.len());
        assert_eq!(a, synthetic_lidar_scene(7));
    }
}
