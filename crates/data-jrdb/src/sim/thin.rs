//! A dense real scan seen as a sparse sensor would see it: some of its rings and columns kept, so
//! that simulated people ray-cast with the kept beams are as sparse as a 32-beam sensor's people
//! and stand in a place sampled as sparsely (`sim::backdrop`).
//!
//! A real scan's rings are not its datasheet's: lasers sit a few tenths of a degree off their
//! nominal elevations and, on an HDL-64E, off the sensor's axis, so two nominal beams' returns
//! overlap in elevation. The rings are found from the returns instead: as gaps in the elevations
//! of far returns where the lasers are told apart that way (Pandar64, Ouster), else from the
//! order the driver wrote them in, ring after ring, each ring one turn of azimuth (KITTI's
//! HDL-64E files).

/// A scan's rings, found from its returns.
#[derive(Debug, Clone, PartialEq)]
pub struct Rings {
    /// Each return's ring (0 = lowest).
    pub of_point: Vec<u16>,
    /// Each ring's elevation (radians, ascending): the median over its returns beyond
    /// [`FAR`] (over all of them where it has too few there).
    pub elevation: Vec<f64>,
}

/// Returns nearer than this (horizontal metres) are left out of finding elevations: there a
/// laser's offset from the sensor's axis moves its elevation by more than the rings' spacing.
pub const FAR: f64 = 6.0;

/// Far returns whose elevations lie closer than this (radians, 0.03°) are one ring's.
const GAP: f64 = 0.03 * std::f64::consts::PI / 180.0;

/// A ring has at least this many far returns (fewer: stray returns between rings).
const MIN_RING: usize = 20;

/// Rings found in written order whose elevations lie within this (radians, 0.08°) are one ring,
/// split where the file starts and ends mid-turn.
const SAME_RING: f64 = 0.08 * std::f64::consts::PI / 180.0;

/// Azimuth turning back by more than this (radians) between two returns written one after the
/// other starts a new ring: within a ring it only advances (by a column, or across a gap).
const TURN_BACK: f64 = 0.5;

fn elevation(p: [f32; 3]) -> f64 {
    let [x, y, z] = p.map(f64::from);
    z.atan2(x.hypot(y))
}

/// The index of the value of `sorted` (ascending, not empty) nearest `x`, the lower on a tie.
pub(super) fn nearest(sorted: &[f64], x: f64) -> usize {
    let k = sorted.partition_point(|&c| c < x);
    if k == sorted.len() || (k > 0 && x - sorted[k - 1] < sorted[k] - x) { k - 1 } else { k }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The rings of a scan of a sensor with `beams` lasers (sensor frame), or `None` where neither
/// the elevations nor the written order tell `beams` rings apart (within 20 %).
pub fn find_rings(points: &[[f32; 3]], beams: usize) -> Option<Rings> {
    let plausible = |n: usize| n * 5 >= beams * 4 && n <= beams + beams / 5;
    by_elevation(points).filter(|r| plausible(r.elevation.len())).or_else(|| by_order(points).filter(|r| plausible(r.elevation.len())))
}

/// Rings as clusters of far returns' elevations; every return joins the nearest.
fn by_elevation(points: &[[f32; 3]]) -> Option<Rings> {
    let mut far: Vec<f64> = points.iter().filter(|p| f64::from(p[0]).hypot(f64::from(p[1])) > FAR).map(|&p| elevation(p)).collect();
    far.sort_by(f64::total_cmp);
    let mut centres = Vec::new();
    let mut start = 0;
    for i in 1..=far.len() {
        if i == far.len() || far[i] - far[i - 1] > GAP {
            if i - start >= MIN_RING {
                centres.push(far[start + (i - start) / 2]);
            }
            start = i;
        }
    }
    if centres.len() < 2 {
        return None;
    }
    let of_point = points
        .iter()
        .map(|&p| nearest(&centres, elevation(p)) as u16)
        .collect();
    Some(Rings { of_point, elevation: centres })
}

/// Rings as runs of returns in written order, a run ending where azimuth turns back against the
/// scan's direction by more than [`TURN_BACK`] (a ring's last return, wherever it lies, and the
/// next ring's first); runs of one elevation are one ring (a file starting mid-turn splits its
/// rings where azimuth wraps).
fn by_order(points: &[[f32; 3]]) -> Option<Rings> {
    if points.len() < 2 {
        return None;
    }
    let az: Vec<f64> = points.iter().map(|p| f64::from(p[1]).atan2(f64::from(p[0]))).collect();
    // The scan's direction: the sign of most small steps between neighbours.
    let small: Vec<f64> = az.windows(2).map(|w| w[1] - w[0]).filter(|d| d.abs() < 0.1).collect();
    let forward = small.iter().filter(|&&d| d > 0.0).count();
    let dir = if forward * 2 >= small.len() { 1.0 } else { -1.0 };
    let mut run_of = Vec::with_capacity(points.len());
    let mut run = 0usize;
    for i in 0..points.len() {
        if i > 0 && (az[i] - az[i - 1]) * dir < -TURN_BACK {
            run += 1;
        }
        run_of.push(run);
    }
    let runs = run + 1;
    let (mut far, mut all) = (vec![Vec::new(); runs], vec![Vec::new(); runs]);
    for (&p, &r) in points.iter().zip(&run_of) {
        let e = elevation(p);
        all[r].push(e);
        if f64::from(p[0]).hypot(f64::from(p[1])) > FAR {
            far[r].push(e);
        }
    }
    let level: Vec<f64> = far.iter_mut().zip(&mut all).map(|(f, a)| if f.len() >= MIN_RING { median(f) } else { median(a) }).collect();
    let mut order: Vec<usize> = (0..runs).collect();
    order.sort_by(|&a, &b| level[a].total_cmp(&level[b]));
    let mut ring_of_run = vec![0u16; runs];
    let mut members: Vec<Vec<usize>> = Vec::new();
    for &r in &order {
        let joins = members.last().is_some_and(|m| level[r] - level[*m.last().unwrap()] < SAME_RING);
        if !joins {
            members.push(Vec::new());
        }
        members.last_mut().unwrap().push(r);
        ring_of_run[r] = (members.len() - 1) as u16;
    }
    if members.len() < 2 {
        return None;
    }
    let elevation = members
        .iter()
        .map(|m| {
            let mut f: Vec<f64> = m.iter().flat_map(|&r| far[r].iter().copied()).collect();
            if f.len() >= MIN_RING { median(&mut f) } else { median(&mut m.iter().flat_map(|&r| all[r].iter().copied()).collect::<Vec<_>>()) }
        })
        .collect();
    Some(Rings { of_point: run_of.iter().map(|&r| ring_of_run[r]).collect(), elevation })
}

/// A scan thinned to a sparser sensor: the returns kept and the beams and columns that sensor has.
#[derive(Debug, Clone, PartialEq)]
pub struct Thinned {
    /// The returns of the kept rings and columns.
    pub points: Vec<[f32; 3]>,
    /// The kept rings' elevations (radians, ascending): the beams people are ray-cast with.
    pub elevations: Vec<f64>,
    /// Columns per revolution of the thinned sensor.
    pub columns: usize,
}

/// Keeps the rings at least `beam_spacing` apart (radians; lowest ring first) and one column in
/// `k`, the whole `k` nearest `column_spacing` over a column of a sensor of `columns` columns
/// (radians; at least 1). A column is an azimuth band of one source column's width every `k`:
/// each ring fires once in it whatever its azimuth offset, so no phase has to be known.
pub fn thin(points: &[[f32; 3]], rings: &Rings, columns: usize, beam_spacing: f64, column_spacing: f64) -> Thinned {
    let mut keep = vec![false; rings.elevation.len()];
    let mut last = f64::NEG_INFINITY;
    for (k, &e) in rings.elevation.iter().enumerate() {
        if e - last >= beam_spacing {
            keep[k] = true;
            last = e;
        }
    }
    let step = std::f64::consts::TAU / columns as f64;
    let k = ((column_spacing / step).round() as usize).max(1);
    let kept_columns = columns / k;
    let band = step * k as f64;
    let points = points
        .iter()
        .zip(&rings.of_point)
        .filter(|&(p, &r)| {
            let az = f64::from(p[1]).atan2(f64::from(p[0]));
            keep[r as usize] && (az / band).rem_euclid(1.0) < 1.0 / k as f64
        })
        .map(|(&p, _)| p)
        .collect();
    let elevations = rings.elevation.iter().zip(&keep).filter(|&(_, &k)| k).map(|(&e, _)| e).collect();
    Thinned { points, elevations, columns: kept_columns }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::geometry::Shape;
    use crate::sim::scene::Prim;
    use crate::sim::sensors::SensorModel;

    /// An HDL-64E's scan of a square room's walls 8–12 m away, tall and deep enough for every
    /// beam to reach them, as `scan_beams` writes it (column by column).
    fn scan() -> Vec<super::super::lidar::Return> {
        let wall = |c: [f64; 2], yaw: f64| Prim { shape: Shape::Cuboid { c: [c[0], c[1], -3.0], half: [0.5, 14.0, 9.0], yaw }, reflectivity: 0.5 };
        let walls = [wall([8.5, 0.0], 0.0), wall([-12.5, 0.0], 0.0), wall([0.0, 10.5], std::f64::consts::FRAC_PI_2), wall([0.0, -9.5], std::f64::consts::FRAC_PI_2)];
        let m = SensorModel::Hdl64e;
        m.scanner().scan_beams(&m.elevations(), &walls, [0.0; 3], 0.0, None, 3)
    }

    #[test]
    fn rings_told_apart_by_elevation_are_the_beams() {
        let rets = scan();
        let points: Vec<[f32; 3]> = rets.iter().map(|r| r.xyz.map(|v| v as f32)).collect();
        let rings = find_rings(&points, 64).expect("rings");
        // Every beam is found, and each return is given its own beam.
        assert_eq!(rings.elevation.len(), 64);
        let wrong = rets.iter().zip(&rings.of_point).filter(|(r, k)| r.ring != **k).count();
        assert_eq!(wrong, 0);
        let e = SensorModel::Hdl64e.elevations();
        for (k, c) in rings.elevation.iter().enumerate() {
            assert!((c - e[k]).abs() < 2e-3, "ring {k}: {c} against {}", e[k]);
        }
    }

    #[test]
    fn rings_overlapping_in_elevation_are_read_from_the_written_order() {
        // Ring after ring, each one turn from −π; every return's elevation jittered by ±0.3°,
        // more than the beams' spacing, so elevations alone cannot tell the rings apart.
        let e = SensorModel::Hdl64e.elevations();
        let mut points = Vec::new();
        let mut truth = Vec::new();
        for (k, &el) in e.iter().enumerate() {
            for c in 0..2000 {
                let az = -std::f64::consts::PI + (c as f64 + 0.5) * std::f64::consts::TAU / 2000.0;
                let jitter = ((c * 7919 + k * 104_729) % 601) as f64 / 600.0 - 0.5;
                let el = el + (0.6 * jitter).to_radians();
                let r = 20.0;
                points.push([(r * el.cos() * az.cos()) as f32, (r * el.cos() * az.sin()) as f32, (r * el.sin()) as f32]);
                truth.push(k as u16);
            }
        }
        assert!(by_elevation(&points).is_none_or(|r| r.elevation.len() < 51), "elevations alone would tell them apart");
        let rings = find_rings(&points, 64).expect("rings");
        assert_eq!(rings.of_point, truth);
        for (c, &want) in rings.elevation.iter().zip(&e) {
            assert!((c - want).abs() < 0.2f64.to_radians());
        }
        // A file that starts mid-turn: its first ring's returns are split in two runs, one ring.
        let mut turned = points.clone();
        turned.rotate_left(700);
        let mut want = truth.clone();
        want.rotate_left(700);
        assert_eq!(find_rings(&turned, 64).expect("rings").of_point, want);
    }

    #[test]
    fn thinning_keeps_rings_a_spacing_apart_and_one_column_in_k() {
        let rets = scan();
        let points: Vec<[f32; 3]> = rets.iter().map(|r| r.xyz.map(|v| v as f32)).collect();
        let rings = find_rings(&points, 64).unwrap();
        let t = thin(&points, &rings, 2000, 1.2f64.to_radians(), 0.33f64.to_radians());
        assert_eq!(t.columns, 1000);
        assert!(t.elevations.windows(2).all(|w| w[1] - w[0] >= 1.2f64.to_radians() - 1e-12));
        // HDL-64E: 0.33° apart above −8.33°, 0.5° below: every fourth ring, then every third.
        assert!((12..=24).contains(&t.elevations.len()), "{} rings", t.elevations.len());
        // Each kept ring keeps every other column: half its returns, within a few.
        let kept_rings: Vec<usize> = rings.elevation.iter().enumerate().filter(|(_, e)| t.elevations.contains(e)).map(|(k, _)| k).collect();
        let ring_of: std::collections::HashMap<[u32; 3], u16> = points.iter().zip(&rings.of_point).map(|(p, &r)| (p.map(f32::to_bits), r)).collect();
        for &k in &kept_rings {
            let before = rings.of_point.iter().filter(|&&r| r as usize == k).count();
            let after = t.points.iter().filter(|p| ring_of[&p.map(f32::to_bits)] as usize == k).count();
            assert!((after as f64 - before as f64 / 2.0).abs() <= 0.02 * before as f64 + 2.0, "ring {k}: {after} of {before}");
        }
        let dropped = points.len() - t.points.len();
        assert!(dropped > points.len() * 3 / 4, "kept {} of {}", t.points.len(), points.len());
    }
}
