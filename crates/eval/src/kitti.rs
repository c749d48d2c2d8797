//! The official KITTI-style txt format of the JRDB tool: `DIR/<sequence>/<frame>.txt`, one object
//! per line, 17 whitespace-separated columns, KITTI's camera frame:
//!
//! ```text
//! type trunc occ num_points alpha x1 y1 x2 y2 h w l x y z ry score
//! ```
//!
//! Camera frame: x right, y down, z forward; (x, y, z) is the *bottom* centre, the box spans
//! y ∈ [y − h, y]; the footprint in the (x, z) plane has corners `(x, z) + M(ry)·(±l/2, ±w/2)`
//! with `M(ry) = [[cos ry, sin ry], [−sin ry, cos ry]]`. In ground-truth files the 17th column is
//! an integer (the converter writes `1`); in detection files it is the score.
//!
//! The JRDB → KITTI mapping is the official converter's (`convert_labels_to_KITTI.py`):
//! `h_k = h, w_k = l, l_k = w, x = −cy, y = −cz + h/2, z = cx`,
//! `ry = −rot_z` if `rot_z < π` else `2π − rot_z`.

use std::fmt::Write as _;
use std::path::Path;

use data_jrdb::Box3d;

use crate::error::{EvalError, Result};

/// One line of a KITTI-style file: a ground-truth object or a detection.
#[derive(Debug, Clone, PartialEq)]
pub struct KittiObject {
    /// Object type; only `Pedestrian` (any case) is evaluated.
    pub kind: String,
    /// Truncation flag (unused by the 3D evaluation).
    pub truncated: i32,
    /// Occlusion level (unused by the 3D evaluation).
    pub occluded: i32,
    /// LiDAR points inside the box; `< 0` drops a GT, `< 10` ignores it.
    pub num_points: i32,
    /// Observation angle (unused by the 3D evaluation).
    pub alpha: f64,
    /// 2D box `x1 y1 x2 y2` (unused by the 3D evaluation).
    pub bbox: [f64; 4],
    /// Height (camera y extent).
    pub h: f64,
    /// KITTI width (= JRDB `l`).
    pub w: f64,
    /// KITTI length (= JRDB `w`).
    pub l: f64,
    /// Bottom-centre x (= −cy).
    pub x: f64,
    /// Bottom-centre y (= −cz + h/2).
    pub y: f64,
    /// Bottom-centre z (= cx).
    pub z: f64,
    /// Rotation about the camera y axis.
    pub ry: f64,
    /// Detection score; for ground truth the integer of the 17th column.
    pub score: f64,
}

/// Whether a file holds ground truth (integer 17th column) or detections (score).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    /// Ground truth: the 17th column is an integer.
    GroundTruth,
    /// Detections: the 17th column is the score.
    Detections,
}

const COLUMN_NAMES: [&str; 17] = [
    "type",
    "truncated",
    "occluded",
    "num_points",
    "alpha",
    "x1",
    "y1",
    "x2",
    "y2",
    "h",
    "w",
    "l",
    "x",
    "y",
    "z",
    "ry",
    "score",
];

/// The official converter's angle: `−rot_z` for `rot_z < π`, else `2π − rot_z`.
pub fn rot_z_to_ry(rot_z: f64) -> f64 {
    if rot_z < std::f64::consts::PI {
        -rot_z
    } else {
        2.0 * std::f64::consts::PI - rot_z
    }
}

impl KittiObject {
    /// A pedestrian line for a JRDB box, converted exactly as the official converter does.
    pub fn from_box3d(b: &Box3d, num_points: i32, score: f64) -> Self {
        KittiObject {
            kind: "Pedestrian".to_string(),
            truncated: 0,
            occluded: 0,
            num_points,
            alpha: -1.0,
            bbox: [-1.0; 4],
            h: b.h,
            w: b.l,
            l: b.w,
            x: -b.cy,
            y: -b.cz + b.h / 2.0,
            z: b.cx,
            ry: rot_z_to_ry(b.rot_z),
            score,
        }
    }

    /// A ground-truth line for a JRDB label, as the official converter writes it without the 2D
    /// labels: truncation and occlusion −1, `num_points` (clamped to `i32`) and the observation
    /// angle carried over, score 1.
    pub fn ground_truth(b: &Box3d, num_points: i64, observation_angle: f64) -> Self {
        KittiObject {
            truncated: -1,
            occluded: -1,
            alpha: observation_angle,
            ..Self::from_box3d(b, num_points.clamp(i32::MIN as i64, i32::MAX as i64) as i32, 1.0)
        }
    }

    /// The JRDB box of this line (inverse of [`KittiObject::from_box3d`], up to rounding of `cz`).
    pub fn to_box3d(&self) -> Box3d {
        Box3d {
            cx: self.z,
            cy: -self.x,
            cz: self.h / 2.0 - self.y,
            l: self.w,
            w: self.l,
            h: self.h,
            rot_z: -self.ry,
        }
    }

    /// Whether this object is of the evaluated class (the tool compares case-insensitively).
    pub fn is_pedestrian(&self) -> bool {
        self.kind.eq_ignore_ascii_case("pedestrian")
    }

    /// Squared distance of the bottom centre from the sensor in the ground plane (`x² + z²`),
    /// computed as the tool does so that the 25 m boundary falls on the same side.
    pub fn range_sq(&self) -> f64 {
        self.x * self.x + self.z * self.z
    }

    /// Parses one non-empty line. `path` and `line` only label errors.
    pub fn parse(text: &str, kind: FileKind, path: &Path, line: usize) -> Result<Self> {
        let fields: Vec<&str> = text.split_whitespace().collect();
        let err = |column: usize, message: String| EvalError::Parse {
            path: path.to_path_buf(),
            line,
            column,
            message,
        };
        if fields.len() != 17 {
            let column = fields.len().min(17) + 1;
            return Err(err(
                column,
                format!(
                    "expected 17 whitespace-separated columns ({}), found {}",
                    COLUMN_NAMES.join(" "),
                    fields.len()
                ),
            ));
        }
        let int = |i: usize| -> Result<i32> {
            fields[i].parse::<i32>().map_err(|_| {
                err(
                    i + 1,
                    format!(
                        "{}: expected an integer, found `{}`",
                        COLUMN_NAMES[i], fields[i]
                    ),
                )
            })
        };
        let float = |i: usize| -> Result<f64> {
            fields[i].parse::<f64>().map_err(|_| {
                err(
                    i + 1,
                    format!(
                        "{}: expected a number, found `{}`",
                        COLUMN_NAMES[i], fields[i]
                    ),
                )
            })
        };
        let score = match kind {
            FileKind::GroundTruth => int(16)? as f64,
            FileKind::Detections => float(16)?,
        };
        let obj = KittiObject {
            kind: fields[0].to_string(),
            truncated: int(1)?,
            occluded: int(2)?,
            num_points: int(3)?,
            alpha: float(4)?,
            bbox: [float(5)?, float(6)?, float(7)?, float(8)?],
            h: float(9)?,
            w: float(10)?,
            l: float(11)?,
            x: float(12)?,
            y: float(13)?,
            z: float(14)?,
            ry: float(15)?,
            score,
        };
        // Negative sizes make the tool's polygon turn the other way (undefined in Boost);
        // a GT line the tool drops (num_points < 0, e.g. a 2D-only label with sizes −1) is exempt.
        let dropped_gt = kind == FileKind::GroundTruth && obj.num_points < 0;
        if !dropped_gt {
            for (i, v) in [(9, obj.h), (10, obj.w), (11, obj.l)] {
                if v < 0.0 {
                    return Err(err(
                        i + 1,
                        format!(
                            "{}: a box size must not be negative, found {v}",
                            COLUMN_NAMES[i]
                        ),
                    ));
                }
            }
        }
        Ok(obj)
    }

    /// The line as written to a file (without newline). Numbers use Rust's shortest round-trip
    /// form, so reading the line back gives bit-identical values.
    pub fn to_line(&self, kind: FileKind) -> String {
        let mut s = String::new();
        let b = self.bbox;
        write!(
            s,
            "{} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} ",
            self.kind,
            self.truncated,
            self.occluded,
            self.num_points,
            self.alpha,
            b[0],
            b[1],
            b[2],
            b[3],
            self.h,
            self.w,
            self.l,
            self.x,
            self.y,
            self.z,
            self.ry
        )
        .expect("writing to a String cannot fail");
        match kind {
            FileKind::GroundTruth => write!(s, "{}", self.score as i64),
            FileKind::Detections => write!(s, "{}", self.score),
        }
        .expect("writing to a String cannot fail");
        s
    }
}

/// Parses a whole file's text; blank lines are skipped.
pub fn parse_str(text: &str, kind: FileKind, path: &Path) -> Result<Vec<KittiObject>> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| KittiObject::parse(l, kind, path, i + 1))
        .collect()
}

/// Reads one KITTI-style file.
pub fn read_file(path: &Path, kind: FileKind) -> Result<Vec<KittiObject>> {
    let text = std::fs::read_to_string(path).map_err(|e| EvalError::io(path, e))?;
    parse_str(&text, kind, path)
}

/// Writes one KITTI-style file (creating its folder).
pub fn write_file(path: &Path, objects: &[KittiObject], kind: FileKind) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| EvalError::io(dir, e))?;
    }
    let mut text = String::new();
    for o in objects {
        text.push_str(&o.to_line(kind));
        text.push('\n');
    }
    std::fs::write(path, text).map_err(|e| EvalError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_a_detection_line() {
        let o = KittiObject::parse(
            "Pedestrian 0 0 -1 0 -1 -1 -1 -1 1.7 0.9 0.5 -2 0.85 3 -0.5 0.75",
            FileKind::Detections,
            Path::new("d.txt"),
            1,
        )
        .unwrap();
        assert_eq!(
            (o.h, o.w, o.l, o.x, o.y, o.z, o.ry, o.score),
            (1.7, 0.9, 0.5, -2.0, 0.85, 3.0, -0.5, 0.75)
        );
        assert!(o.is_pedestrian());
    }

    #[test]
    fn malformed_lines_name_line_and_column() {
        let p = Path::new("seq/000001.txt");
        let e = parse_str(
            "\nPedestrian 0 0 12 0 0 0 0 0 1 1 1 0 0 x 0 1\n",
            FileKind::GroundTruth,
            p,
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "seq/000001.txt:2: column 15: z: expected a number, found `x`"
        );
        let e = parse_str(
            "Pedestrian 0 0 12.5 0 0 0 0 0 1 1 1 0 0 0 0 1",
            FileKind::GroundTruth,
            p,
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("seq/000001.txt:1: column 4: num_points: expected an integer"),
            "{e}"
        );
        let e = parse_str(
            "Pedestrian 0 0 12 0 0 0 0 0 1 1 1 0 0 0 0",
            FileKind::GroundTruth,
            p,
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("seq/000001.txt:1: column 17: expected 17"),
            "{e}"
        );
        let e = parse_str(
            "Pedestrian 0 0 12 0 0 0 0 0 1 1 1 0 0 0 0 0.5",
            FileKind::GroundTruth,
            p,
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("seq/000001.txt:1: column 17: score: expected an integer"),
            "{e}"
        );
        let e = parse_str(
            "Pedestrian 0 0 12 0 0 0 0 0 1 -1 1 0 0 0 0 1",
            FileKind::GroundTruth,
            p,
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("seq/000001.txt:1: column 11: w: a box size must not be negative"),
            "{e}"
        );
        // A dropped GT (num_points < 0, sizes −1 as the converter writes 2D-only labels) is fine.
        assert!(
            parse_str(
                "Pedestrian 0 0 -1 0 0 0 0 0 -1 -1 -1 -1 -1 -1 -1 1",
                FileKind::GroundTruth,
                p
            )
            .is_ok()
        );
    }

    #[test]
    fn box_round_trip_and_converter_angle() {
        let b = Box3d {
            cx: 3.25,
            cy: -1.5,
            cz: 0.125,
            l: 0.9,
            w: 0.5,
            h: 1.75,
            rot_z: 0.4,
        };
        let k = KittiObject::from_box3d(&b, 20, 0.5);
        assert_eq!(
            (k.h, k.w, k.l, k.x, k.y, k.z, k.ry),
            (1.75, 0.9, 0.5, 1.5, -0.125 + 0.875, 3.25, -0.4)
        );
        assert_eq!(k.to_box3d(), b);
        let line = k.to_line(FileKind::Detections);
        assert_eq!(
            KittiObject::parse(&line, FileKind::Detections, Path::new("x"), 1).unwrap(),
            k
        );
        // rot_z ≥ π goes to 2π − rot_z, as the converter writes it.
        assert_eq!(rot_z_to_ry(4.0), 2.0 * std::f64::consts::PI - 4.0);
        assert_eq!(rot_z_to_ry(-1.0), 1.0);
    }
}
