//! CenterPoint's targets (its `AssignLabel`): a Gaussian heatmap per sample with CenterNet's radius
//! rule, and regression targets at each object's centre cell.

use data_jrdb::Batch;

use super::grid::BevGrid;

/// Regression values per object: dx, dy, z, log l, log w, log h, sin θ, cos θ.
pub const REG_VALUES: usize = 8;

/// Targets of one batch, on the CPU.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct HeatmapTargets {
    /// `[B, X, Y]` heatmap in [0, 1], 1 exactly at each object's centre cell.
    pub heatmap: Vec<f32>,
    /// Flat index `b·X·Y + x·Y + y` of each object's centre cell.
    pub index: Vec<i64>,
    /// `objects × 8` regression targets.
    pub reg: Vec<f32>,
}

impl HeatmapTargets {
    /// Number of objects (inside the grid).
    pub fn num_objects(&self) -> usize {
        self.index.len()
    }
}

/// CenterNet's `gaussian_radius((height, width), min_overlap)`, copied with its `(b + sq) / 2`
/// quirk, as CenterPoint's `center_utils.py` has it: the smallest of three corner-shift radii.
pub fn gaussian_radius(height: f64, width: f64, min_overlap: f64) -> f64 {
    let (a1, b1, c1) = (1.0, height + width, width * height * (1.0 - min_overlap) / (1.0 + min_overlap));
    let r1 = (b1 + (b1 * b1 - 4.0 * a1 * c1).sqrt()) / 2.0;
    let (a2, b2, c2) = (4.0, 2.0 * (height + width), (1.0 - min_overlap) * width * height);
    let r2 = (b2 + (b2 * b2 - 4.0 * a2 * c2).sqrt()) / 2.0;
    let (a3, b3, c3) = (4.0 * min_overlap, -2.0 * min_overlap * (height + width), (min_overlap - 1.0) * width * height);
    let r3 = (b3 + (b3 * b3 - 4.0 * a3 * c3).sqrt()) / 2.0;
    r1.min(r2).min(r3)
}

/// CenterNet's `draw_umich_gaussian`: a `(2r + 1)²` Gaussian with σ = (2r + 1)/6, values below
/// `f32::EPSILON × max` zeroed, merged by element-wise max into `hm` (`[X, Y]`) around `(cx, cy)`.
pub fn draw_gaussian(hm: &mut [f32], size: [usize; 2], cx: usize, cy: usize, radius: usize) {
    let r = radius as i64;
    let sigma = (2 * radius + 1) as f64 / 6.0;
    for dx in -r..=r {
        for dy in -r..=r {
            let (x, y) = (cx as i64 + dx, cy as i64 + dy);
            if x < 0 || y < 0 || x >= size[0] as i64 || y >= size[1] as i64 {
                continue;
            }
            let mut g = (-((dx * dx + dy * dy) as f64) / (2.0 * sigma * sigma)).exp();
            if g < f64::EPSILON {
                g = 0.0; // numpy's `h[h < eps * h.max()] = 0` with max = 1
            }
            let cell = &mut hm[x as usize * size[1] + y as usize];
            *cell = cell.max(g as f32);
        }
    }
}

/// Heatmap and regression targets of every sample; boxes whose centre is off the grid are skipped.
pub fn assign(batch: &Batch, grid: &BevGrid, min_overlap: f64, min_radius: usize) -> HeatmapTargets {
    let [sx, sy] = grid.out_size();
    let cell = grid.out_cell();
    let mut t = HeatmapTargets { heatmap: vec![0.0; batch.len() * sx * sy], ..Default::default() };
    for (s, boxes) in batch.boxes.iter().enumerate() {
        let hm = &mut t.heatmap[s * sx * sy..(s + 1) * sx * sy];
        for b in boxes {
            let [u, v] = grid.to_cells(b.cx, b.cy);
            if !(u >= 0.0 && v >= 0.0 && u < sx as f64 && v < sy as f64) {
                continue;
            }
            let (ix, iy) = (u.floor() as usize, v.floor() as usize);
            let radius = (gaussian_radius(b.l / cell[0], b.w / cell[1], min_overlap) as usize).max(min_radius);
            draw_gaussian(hm, [sx, sy], ix, iy, radius);
            t.index.push((s * sx * sy + ix * sy + iy) as i64);
            let (sin, cos) = b.rot_z.sin_cos();
            let reg = [u - ix as f64, v - iy as f64, b.cz, b.l.ln(), b.w.ln(), b.h.ln(), sin, cos];
            t.reg.extend(reg.map(|x| x as f32));
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::centerpoint::CenterPointConfig;
    use data_jrdb::Box3d;

    #[test]
    fn radius_rule_matches_centernet_values() {
        // CenterNet on a 10×20 box at overlap 0.7: r1 = 13.898, r2 = 17.162, r3 = 2.7734 → 2.773...
        let r = gaussian_radius(10.0, 20.0, 0.7);
        let r3 = {
            let (a, b, c): (f64, f64, f64) = (2.8, -2.0 * 0.7 * 30.0, -0.3 * 200.0);
            (b + ((b * b) - 4.0 * a * c).sqrt()) / 2.0
        };
        assert!((r - r3).abs() < 1e-12, "{r} vs {r3}");
        // A person (0.9 × 0.5 m) on 0.2 m cells at overlap 0.1 is below the 2-cell minimum.
        let r = gaussian_radius(4.5, 2.5, 0.1);
        assert!((r - (-1.4 + (1.96f64 + 16.2).sqrt()) / 2.0).abs() < 1e-12 && r < 2.0, "{r}");
    }

    #[test]
    fn gaussian_peak_is_one_at_the_centre_and_targets_hold_the_box() {
        let cfg = CenterPointConfig { x_range: [-3.2, 3.2], y_range: [-3.2, 3.2], ..Default::default() };
        let grid = BevGrid::new(&cfg);
        assert_eq!(grid.out_size(), [32, 32]);
        let b = Box3d { cx: 0.55, cy: -1.01, cz: 0.1, l: 0.9, w: 0.5, h: 1.7, rot_z: 0.4 };
        let far = Box3d { cx: 30.0, ..b };
        let mut batch = Batch { boxes: vec![vec![b, far]], offsets: vec![0, 0], ..Default::default() };
        batch.frames.push(("s".into(), "0".into()));
        let t = assign(&batch, &grid, 0.1, 2);
        assert_eq!(t.num_objects(), 1);
        // (0.55 + 3.2) / 0.2 = 18.75, (−1.01 + 3.2) / 0.2 = 10.95.
        assert_eq!(t.index, vec![18 * 32 + 10]);
        assert_eq!(t.heatmap[18 * 32 + 10], 1.0);
        // Radius 2: σ = 5/6; the neighbour one cell away is exp(−1/(2σ²)) = exp(−0.72).
        assert!((t.heatmap[19 * 32 + 10] - (-0.72f32).exp()).abs() < 1e-6);
        assert!(t.heatmap[18 * 32 + 12] > 0.0 && t.heatmap[18 * 32 + 13] == 0.0, "radius 2 cells");
        let want = [0.75, 0.95, 0.1, 0.9f64.ln(), 0.5f64.ln(), 1.7f64.ln(), 0.4f64.sin(), 0.4f64.cos()];
        for (g, w) in t.reg.iter().zip(want) {
            assert!((*g as f64 - w).abs() < 1e-5, "{:?}", t.reg);
        }
    }
}
