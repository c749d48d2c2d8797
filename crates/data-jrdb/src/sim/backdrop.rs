//! Real backdrops: real scans with their people taken out, and simulated people ray-cast into
//! them with the scan's own sensor model. The world around people as a real sensor saw it (walls,
//! kerbs, vegetation, vehicles, barriers), the people with exact labels: the lever of
//! Paved2Paradise and LiDAR-Aug against a simulator's too-clean surroundings.
//!
//! A person stands only where the scan saw nothing within 0.8 m of their feet between 0.25 m and
//! 2.3 m above the ground there. Rays are compared by the cell (azimuth column, beam) they fall
//! in: a person's return hides the backdrop's returns behind it in its cell (its shadow), and a
//! backdrop return in front of a person's hides the person's.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::geometry::V3;
use super::lidar::{Return, tip};
use super::people::{Activity, Body, place, tight_box};
use super::scene::Prim;
use super::sensors::SensorModel;
use super::thin::{find_rings, nearest, thin};
use super::writer::{SynthConfig, label, mix, mkdir, write_cloud};
use crate::calibration::{Calibration, Lidar};
use crate::cloud::read_cloud;
use crate::error::{DataError, ErrorKind, Result};
use crate::ground::{GroundPlane, GroundSearch, fit_ground};
use crate::labels::write_labels;
use crate::split::Layout;
use crate::timestamps::{FrameTime, write_timestamps};

/// The floor's height in JRDB's base frame (as `bench-v2` writes it).
const FLOOR: f64 = -0.7;
/// Bird's-eye cells of the free-ground search (m).
const CELL: f64 = 0.4;
/// People stand within this range of the sensor (m).
const REACH: f64 = 30.0;

/// One real scan with its people removed, in its sensor's frame.
#[derive(Debug, Clone)]
pub struct Backdrop {
    /// The file it came from (names it in errors and sequences).
    pub file: PathBuf,
    /// The sensor that scanned it: the beams people are ray-cast with.
    pub sensor: SensorModel,
    /// Its returns (sensor frame).
    pub points: Vec<[f32; 3]>,
    /// Its ground, fitted as `detect` fits a user's scan.
    pub ground: GroundPlane,
}

/// Reads `DIR/backdrops.csv` (`file,sensor` with a header; more columns are kept for people,
/// e.g. the source): each file a cloud `read_cloud` reads, in its sensor's frame, its people
/// already removed; `sensor` a model name (`hdl64e`, `pandar64`, …).
pub fn read_backdrops(dir: &Path) -> Result<Vec<Backdrop>> {
    let index = dir.join("backdrops.csv");
    let text = std::fs::read_to_string(&index).map_err(|e| DataError::io(&index, e))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let cols: Vec<&str> = line.split(',').map(str::trim).collect();
        let bad = |what: String| DataError::new(&index, ErrorKind::Layout(format!("line {}: {what}", i + 1)));
        let [file, sensor, ..] = cols[..] else { return Err(bad("want `file,sensor`".into())) };
        let sensor = SensorModel::from_name(sensor)
            .ok_or_else(|| bad(format!("unknown sensor `{sensor}` (one of {})", SensorModel::ALL.map(SensorModel::name).join(", "))))?;
        let file = dir.join(file);
        let points = read_cloud(&file)?.points;
        let ground = fit_ground(&points, &GroundSearch::default())
            .map_err(|e| DataError::new(&file, ErrorKind::Layout(format!("no ground to stand people on: {e}"))))?;
        out.push(Backdrop { file, sensor, points, ground });
    }
    if out.is_empty() {
        return Err(DataError::new(&index, ErrorKind::Layout("lists no backdrops".into())));
    }
    Ok(out)
}

/// A sequence's name: its split, `thin-` where its scan is thinned, its backdrop's file stem and
/// its index.
pub fn sequence_name(b: &Backdrop, index: usize, thinned: bool) -> String {
    let stem = b.file.file_stem().and_then(|s| s.to_str()).unwrap_or("scan");
    let stem: String = stem.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '-' }).collect();
    let thin = if thinned { "thin-" } else { "" };
    format!("bd-train-{thin}{stem}-{index:03}")
}

/// A thinned scan's least spacing of rings (degrees): a little under an HDL-32E's 1.33°, so that a
/// table 0.33° apart keeps every fourth ring rather than every fifth.
const THIN_BEAMS: f64 = 1.2;
/// A thinned scan's least spacing of columns (degrees): an HDL-32E's at 20 Hz.
const THIN_COLUMNS: f64 = 0.33;

/// What people are cast with and merged into: the backdrop's returns, beams and mechanics, or
/// those of the backdrop thinned to a 32-beam sensor.
struct View<'a> {
    points: std::borrow::Cow<'a, [[f32; 3]]>,
    elevations: Vec<f64>,
    scanner: super::lidar::Scanner,
}

impl<'a> View<'a> {
    fn of(b: &'a Backdrop, thinned: bool) -> Result<Self> {
        let scanner = b.sensor.scanner();
        if !thinned {
            return Ok(View { points: (&b.points[..]).into(), elevations: b.sensor.elevations(), scanner });
        }
        let beams = b.sensor.elevations().len();
        let rings = find_rings(&b.points, beams).ok_or_else(|| {
            DataError::new(&b.file, ErrorKind::Layout(format!("cannot thin it: neither its elevations nor its written order tell its {beams} rings apart")))
        })?;
        let t = thin(&b.points, &rings, scanner.columns, THIN_BEAMS.to_radians(), THIN_COLUMNS.to_radians());
        Ok(View { points: t.points.into(), elevations: t.elevations, scanner: super::lidar::Scanner { columns: t.columns, ..scanner } })
    }
}

/// Whether sequence `si` of a tree seeded `seed` is thinned: an independent draw per sequence
/// (not its index's parity, which `si % backdrops` would tie to the backdrop).
fn is_thinned(seed: u64, si: usize, share: f64) -> bool {
    share > 0.0 && ((mix(mix(seed, si as u64), 0x7468_696E) >> 11) as f64 / (1u64 << 53) as f64) < share
}

/// The levelled frame of a backdrop: its sensor at the origin, the ground at `-height`.
struct Level {
    tilt: [f64; 2],
    height: f64,
}

impl Level {
    fn of(g: &GroundPlane) -> Self {
        let (roll, pitch) = g.levelling();
        Level { tilt: [roll, pitch], height: g.height }
    }

    fn point(&self, p: [f32; 3]) -> V3 {
        tip(p.map(f64::from), self.tilt)
    }
}

/// The ground people may stand on: per bird's-eye cell, the lowest return and every return's
/// height.
struct FreeGround {
    cells: HashMap<(i32, i32), Vec<f64>>,
    floor: f64,
}

impl FreeGround {
    fn new(levelled: &[V3], floor: f64) -> Self {
        let mut cells: HashMap<(i32, i32), Vec<f64>> = HashMap::new();
        for p in levelled {
            if p[0].hypot(p[1]) <= REACH + 2.0 {
                cells.entry(Self::cell(p[0], p[1])).or_default().push(p[2]);
            }
        }
        FreeGround { cells, floor }
    }

    fn cell(x: f64, y: f64) -> (i32, i32) {
        ((x / CELL).floor() as i32, (y / CELL).floor() as i32)
    }

    /// The ground of a cell: the median of its returns within 0.15 m of its lowest (the lowest
    /// alone sits a few noise deviations low).
    fn ground(&self, c: &(i32, i32)) -> Option<f64> {
        let zs = self.cells.get(c)?;
        let low = zs.iter().copied().reduce(f64::min)?;
        let mut near: Vec<f64> = zs.iter().copied().filter(|&z| z < low + 0.15).collect();
        near.sort_by(f64::total_cmp);
        Some(near[near.len() / 2])
    }

    /// The ground height at `(x, y)` if a person may stand there: the ground of its cell (the
    /// fitted plane where the scan saw none, as in a shadow), near the plane, nothing between
    /// 0.25 m and 2.3 m above it within 0.8 m, and no step of more than 0.12 m under their feet.
    fn stand(&self, x: f64, y: f64) -> Option<f64> {
        let (cx, cy) = Self::cell(x, y);
        let g = self.ground(&(cx, cy)).unwrap_or(self.floor);
        if (g - self.floor).abs() > 0.5 {
            return None;
        }
        for dx in -2..=2 {
            for dy in -2..=2 {
                let Some(zs) = self.cells.get(&(cx + dx, cy + dy)) else { continue };
                if zs.iter().any(|&z| z > g + 0.25 && z < g + 2.3) {
                    return None;
                }
                if dx.abs() <= 1 && dy.abs() <= 1 && self.ground(&(cx + dx, cy + dy)).is_some_and(|l| (l - g).abs() > 0.12) {
                    return None;
                }
            }
        }
        Some(g)
    }
}

/// A person put into a backdrop: their surfaces and their box (levelled frame).
struct Placed {
    prims: Vec<Prim>,
    bbox: crate::box3d::Box3d,
}

/// Up to `max_people` people where the backdrop has free ground, some in pairs and groups.
fn populate<R: Rng + ?Sized>(ground: &FreeGround, max_people: usize, rng: &mut R) -> Vec<Placed> {
    let want = rng.random_range(1..=max_people.max(1));
    let mut spots: Vec<[f64; 2]> = Vec::new();
    let mut out = Vec::new();
    let mut tries = 0;
    while out.len() < want && tries < want * 60 {
        tries += 1;
        // Half near a previous person (a pair or a group), else anywhere within reach, with
        // range drawn uniformly (as many near people as far ones).
        let [x, y] = match spots.last() {
            Some(&[px, py]) if rng.random_bool(0.35) => {
                let (a, d) = (rng.random_range(0.0..std::f64::consts::TAU), rng.random_range(0.5..1.2));
                [px + d * a.cos(), py + d * a.sin()]
            }
            _ => {
                let (a, d) = (rng.random_range(0.0..std::f64::consts::TAU), rng.random_range(2.0..REACH));
                [d * a.cos(), d * a.sin()]
            }
        };
        if x.hypot(y) < 2.0 || spots.iter().any(|s| (s[0] - x).hypot(s[1] - y) < 0.5) {
            continue;
        }
        let Some(floor) = ground.stand(x, y) else { continue };
        let body = Body::sample_crowd(rng);
        let activity = if rng.random_bool(0.55) { Activity::Walking { speed: rng.random_range(0.8..1.7) } } else { Activity::Standing };
        let (yaw, phase) = (rng.random_range(0.0..std::f64::consts::TAU), rng.random_range(0.0..std::f64::consts::TAU));
        let parts = body.parts(activity, phase);
        let reflectivity = rng.random_range(0.15..0.65);
        let prims = place(&parts, x, y, floor, yaw).into_iter().map(|shape| Prim { shape, reflectivity }).collect();
        out.push(Placed { prims, bbox: tight_box(&parts, x, y, floor, yaw) });
        spots.push([x, y]);
    }
    out
}

/// The (azimuth column, beam) cell a sensor-frame direction falls in, for a sensor of `columns`
/// columns starting at azimuth `start` and beams at `elevations` (radians, sorted).
fn ray_cell(p: V3, start: f64, columns: usize, elevations: &[f64]) -> (u32, u16) {
    let az = p[1].atan2(p[0]) - start;
    let col = (az / std::f64::consts::TAU * columns as f64).round().rem_euclid(columns as f64) as u32;
    let el = (p[2] / (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()).asin();
    (col, nearest(elevations, el) as u16)
}

fn range(p: V3) -> f64 {
    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
}

/// Returns nearer than this behind an occluder still count as hidden (metres): the scans' noise.
const OCCLUSION_MARGIN: f64 = 0.1;

/// Merges a person scan into a backdrop, both in the sensor frame: each hides what lies behind
/// it in its ray cell. Returns the backdrop's surviving points and the people's surviving returns.
fn merge(backdrop: &[[f32; 3]], people: Vec<Return>, start: f64, columns: usize, elevations: &[f64]) -> (Vec<V3>, Vec<Return>) {
    let cell = |p: V3| ray_cell(p, start, columns, elevations);
    let nearest = |points: &mut dyn Iterator<Item = V3>| {
        let mut map: HashMap<(u32, u16), f64> = HashMap::new();
        for p in points {
            let e = map.entry(cell(p)).or_insert(f64::INFINITY);
            *e = e.min(range(p));
        }
        map
    };
    // Hidden by a return of the other in its cell, or by two on either side of it: a ray the
    // scan dropped still hit what it hit.
    let hidden = |map: &HashMap<(u32, u16), f64>, p: V3| {
        let ((col, beam), r) = (cell(p), range(p));
        let nearer = |col: i64, beam: i32| {
            let col = col.rem_euclid(columns as i64) as u32;
            u16::try_from(beam).ok().and_then(|b| map.get(&(col, b))).is_some_and(|&q| q < r - OCCLUSION_MARGIN)
        };
        let (col, beam) = (col as i64, beam as i32);
        nearer(col, beam) || (nearer(col - 1, beam) && nearer(col + 1, beam)) || (nearer(col, beam - 1) && nearer(col, beam + 1))
    };
    let by_people = nearest(&mut people.iter().map(|r| r.xyz));
    let by_backdrop = nearest(&mut backdrop.iter().map(|p| p.map(f64::from)));
    let kept = backdrop.iter().map(|p| p.map(f64::from)).filter(|&p| !hidden(&by_people, p)).collect();
    let people = people.into_iter().filter(|r| !hidden(&by_backdrop, r.xyz)).collect();
    (kept, people)
}

/// The fewest returns a person keeps to be there: fewer, seen through gaps a real scan would not
/// leave, are taken out with their label.
const MIN_RETURNS: usize = 3;

/// Writes `cfg.sequences` sequences of `cfg.frames` frames, sequence `i` on backdrop
/// `i % backdrops.len()`, people drawn anew in every frame; returns the summary's counts.
pub(super) fn synth_backdrops(layout: &Layout, backdrops: &[Backdrop], cfg: &SynthConfig, calib: &Calibration) -> Result<(Vec<String>, usize, usize, usize)> {
    let upper = calib.lidar(Lidar::Upper);
    let (mut names, mut n_frames, mut n_points, mut n_boxes) = (Vec::new(), 0, 0, 0);
    for si in 0..cfg.sequences {
        let b = &backdrops[si % backdrops.len()];
        let thinned = is_thinned(cfg.seed, si, cfg.thinned_share);
        let view = View::of(b, thinned)?;
        let seq = sequence_name(b, si, thinned);
        for l in Lidar::BOTH {
            mkdir(&layout.cloud_dir(l, &seq))?;
        }
        mkdir(layout.timestamps_file(&seq).parent().unwrap())?;
        let seq_seed = mix(cfg.seed, si as u64);
        let mut rng = ChaCha8Rng::seed_from_u64(seq_seed);
        let level = Level::of(&b.ground);
        let levelled: Vec<V3> = b.points.iter().map(|&p| level.point(p)).collect();
        let ground = FreeGround::new(&levelled, -level.height);
        let (elevations, scanner) = (&view.elevations, view.scanner);
        let mut labels = BTreeMap::new();
        let mut times = Vec::new();
        for fi in 0..cfg.frames {
            let people = populate(&ground, cfg.max_people, &mut rng);
            let prims: Vec<Prim> = people.iter().flat_map(|p| p.prims.iter().copied()).collect();
            let scan_seed = mix(seq_seed, fi as u64 + 1);
            let rets = scanner.scan_beams(elevations, &prims, [0.0; 3], 0.0, Some(level.tilt), scan_seed);
            // The scan's first column: the same draw `scan_beams` makes from its seed.
            let start = super::lidar::column_start(scan_seed, scanner.columns);
            let (kept, mut rets) = merge(&view.points, rets, start, scanner.columns, elevations);
            let in_level = |r: &Return| {
                let q = level.point(r.xyz.map(|v| v as f32));
                [q[0] as f32, q[1] as f32, q[2] as f32]
            };
            let people: Vec<Placed> = people
                .into_iter()
                .filter(|p| {
                    let seen = rets.iter().filter(|r| p.bbox.contains(in_level(r).map(f64::from))).count();
                    seen >= MIN_RETURNS || {
                        rets.retain(|r| !p.bbox.contains(in_level(r).map(f64::from)));
                        false
                    }
                })
                .collect();
            // Levelled, the ground under the sensor at the base frame's floor, written as the
            // upper sensor's cloud (the lower one empty), as `bench-v2` writes one sensor.
            let lift = level.height + FLOOR;
            let to_written = |p: V3| {
                let q = level.point(p.map(|v| v as f32));
                let s = upper.to_sensor([q[0], q[1], q[2] + lift]);
                [s[0] as f32, s[1] as f32, s[2] as f32]
            };
            let mut xyz: Vec<[f32; 3]> = kept.iter().map(|&p| to_written(p)).collect();
            let mut all: Vec<Return> = kept.iter().map(|&p| Return { xyz: p, intensity: 0.0, ring: ray_cell(p, start, scanner.columns, elevations).1 }).collect();
            xyz.extend(rets.iter().map(|r| to_written(r.xyz)));
            all.extend(rets);
            let name = format!("{fi:06}");
            write_cloud(&layout.cloud_dir(Lidar::Upper, &seq).join(format!("{name}.pcd")), &xyz, &all, cfg.encoding)?;
            write_cloud(&layout.cloud_dir(Lidar::Lower, &seq).join(format!("{name}.pcd")), &[], &[], cfg.encoding)?;
            let base_points: Vec<[f32; 3]> = xyz.iter().map(|&p| upper.to_base(p)).collect();
            n_points += base_points.len();
            let mut frame_labels = Vec::new();
            for (id, p) in people.iter().enumerate() {
                let mut bx = p.bbox;
                bx.cz += lift;
                if bx.bev_range() > cfg.label_range {
                    continue;
                }
                frame_labels.push(label(id, bx, &base_points));
            }
            n_boxes += frame_labels.len();
            labels.insert(format!("{name}.pcd"), frame_labels);
            times.push(FrameTime { frame_id: fi as u64, timestamp: 1_700_000_000.0 + si as f64 * 10_000.0 + fi as f64 });
        }
        write_labels(&layout.labels_file(&seq), &labels)?;
        write_timestamps(&layout.timestamps_file(&seq), &seq, &times)?;
        n_frames += cfg.frames;
        names.push(seq);
    }
    Ok((names, n_frames, n_points, n_boxes))
}
