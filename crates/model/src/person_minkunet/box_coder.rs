//! Person-MinkUNet's box encoding (docs/model.md): centre offsets from the voxel centre,
//! log-dimensions against a mean size, and bin-based rotation with residuals for every bin; the
//! offsets and the heading in the base frame (the authors') or in each voxel's ray frame
//! ([`BoxFrame`]).
//!
//! Head channel layout (`2·bins + 7` channels): `[0]` cls logit, `[1..4]` centre offset (m),
//! `[4..7]` `log(l/l̄), log(w/w̄), log(h/h̄)`, `[7..7+bins]` bin logits, `[7+bins..7+2·bins]` bin
//! residuals (radians, not normalised). With [`HeadingEncoding::SinCos`] (9 channels), `[7]` and
//! `[8]` are the heading's sine and cosine instead. With [`HeadingEncoding::AxisFacing`]
//! (`2·bins + 8` channels) the bins and residuals cover the heading's axis (0 to π) and `[7+2·bins]`
//! is the facing logit: whether the person faces the sensor's side of that axis.

use std::f64::consts::{PI, TAU};

use data_jrdb::Box3d;
use serde::{Deserialize, Serialize};

/// Channel of the classification logit.
pub const CLS: usize = 0;
/// First channel of the centre offset (3 channels).
pub const OFFSET: usize = 1;
/// First channel of the log-dimensions (3 channels).
pub const LOG_DIMS: usize = 4;
/// First channel of the bin logits (`bins` channels; the residuals follow them).
pub const BINS: usize = 7;

/// Wraps an angle defined modulo `period` into (−period/2, period/2].
fn wrap(a: f64, period: f64) -> f64 {
    let half = period / 2.0;
    let r = (a + half).rem_euclid(period) - half;
    if r <= -half { r + period } else { r }
}

/// Wraps an angle into (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    wrap(a, TAU)
}

/// Wraps an axis angle (defined modulo π) into (−π/2, π/2].
pub fn wrap_axis(a: f64) -> f64 {
    wrap(a, PI)
}

/// Head channels for `num_bins` bins and `heading`: cls + offset + log-dims + bin logits +
/// residuals = `2·bins + 7`, the same and the facing logit = `2·bins + 8`, or cls + offset +
/// log-dims + sin + cos = 9.
pub fn head_channels(num_bins: usize, heading: HeadingEncoding) -> usize {
    match heading {
        HeadingEncoding::Bins => 2 * num_bins + 7,
        HeadingEncoding::AxisFacing => 2 * num_bins + 8,
        HeadingEncoding::SinCos => 9,
    }
}

/// Channel of the facing logit ([`HeadingEncoding::AxisFacing`]), after the bins' residuals.
pub fn facing_channel(num_bins: usize) -> usize {
    BINS + 2 * num_bins
}

/// Whether heading `rot_z` at (cx, cy) points within 90° of the sensor (the base frame's origin).
pub fn faces_sensor(cx: f64, cy: f64, rot_z: f64) -> bool {
    let (s, c) = rot_z.sin_cos();
    -(c * cx + s * cy) > 0.0
}

/// The frame a voxel's centre offset and heading are expressed in.
///
/// A LiDAR sees a person's near side: every voxel's offset to the centre points away from the
/// sensor by about the body's half-depth, and the shape a voxel's neighbourhood shows for a given
/// heading depends on the heading relative to the line of sight (the observation angle, KITTI's
/// α), not on the heading itself. In the base frame both are functions of the voxel's azimuth
/// that a translation-equivariant network must build from its raw-xyz input; in the ray frame
/// they are the same wherever the person stands.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum BoxFrame {
    /// The base frame's x, y, z and the heading θ (the authors').
    #[default]
    Base,
    /// Turned about z by the azimuth φ = atan2(y, x) of the voxel centre as seen from the base
    /// frame's origin (the sensor): x along the ray, y across it, z up; the heading as α = θ − φ.
    Ray,
}

/// How the head encodes the heading.
///
/// The authors classify 12 bins and regress a residual in each: a person seen from the front and
/// from the back look alike, so a voxel that cannot tell splits its bins between the two, and the
/// arg-max picks one at random. A sine and cosine regressed directly (CenterPoint's encoding)
/// average the two guesses instead: the vector shrinks, and whatever cue of the front there is
/// sets its direction.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum HeadingEncoding {
    /// `num_bins` bin logits and a residual per bin (the authors').
    #[default]
    Bins,
    /// sin θ and cos θ, regressed with an MSE; decoded as `atan2(sin, cos)`.
    SinCos,
    /// The axis (θ mod π) as `num_bins` bins with residuals, and a logit for whether the person
    /// faces the sensor (the heading within 90° of the direction from the box to the sensor, the
    /// base frame's origin) or away. The axis is a shape the grid shows at any azimuth; facing or
    /// not is whether the front or the back is the side in view, the same question wherever the
    /// person stands, where "which of two opposite bins" is a different one at every azimuth.
    AxisFacing,
}

/// A box encoded against one voxel centre: the regression targets of a foreground voxel.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodedBox {
    /// Box centre − voxel centre, metres, in the coder's [`BoxFrame`].
    pub offset: [f64; 3],
    /// `log(dim / mean)` for l, w, h.
    pub log_dims: [f64; 3],
    /// The heading's bin, `floor((θ mod 2π) / bin)` (θ in the coder's frame; θ mod π with
    /// [`HeadingEncoding::AxisFacing`]).
    pub bin: usize,
    /// `wrap(θ − (j + ½)·bin)` for every bin j (θ in the coder's frame; with
    /// [`HeadingEncoding::AxisFacing`] the axis θ mod π, wrapped into (−π/2, π/2]).
    pub residuals: Vec<f64>,
    /// Whether the heading points within 90° of the direction from the box's centre to the sensor.
    pub faces_sensor: bool,
    /// The heading θ in the coder's frame (what [`HeadingEncoding::SinCos`] regresses).
    pub theta: f64,
}

/// Encodes and decodes boxes; `decode(encode(b)) = b` with the heading wrapped into (−π, π].
#[derive(Debug, Clone, PartialEq)]
pub struct BoxCoder {
    /// Mean (l, w, h), metres.
    pub mean_size: [f64; 3],
    /// Number of rotation bins.
    pub num_bins: usize,
    /// The frame of the offsets and the heading.
    pub frame: BoxFrame,
    /// Bins and residuals, or sine and cosine.
    pub heading: HeadingEncoding,
}

/// The cosine and sine of the azimuth of `v` in the ray frame; `None` in the base frame (and at
/// the origin, where the azimuth is undefined and the ray frame is the base frame).
fn turn(frame: BoxFrame, v: [f64; 3]) -> Option<(f64, f64)> {
    let r = v[0].hypot(v[1]);
    (frame == BoxFrame::Ray && r > 0.0).then(|| (v[0] / r, v[1] / r))
}

impl BoxCoder {
    /// A coder for `num_bins` bins and the given mean size, in the base frame.
    pub fn new(mean_size: [f64; 3], num_bins: usize) -> Self {
        assert!(num_bins > 0, "at least one rotation bin");
        assert!(mean_size.iter().all(|&m| m > 0.0), "mean size must be positive, got {mean_size:?}");
        Self { mean_size, num_bins, frame: BoxFrame::Base, heading: HeadingEncoding::Bins }
    }

    /// The same coder in `frame`.
    pub fn in_frame(self, frame: BoxFrame) -> Self {
        Self { frame, ..self }
    }

    /// The same coder with the heading encoded as `heading`.
    pub fn with_heading(self, heading: HeadingEncoding) -> Self {
        Self { heading, ..self }
    }

    /// Head channels ([`head_channels`]).
    pub fn channels(&self) -> usize {
        head_channels(self.num_bins, self.heading)
    }

    /// The turn the bins cover: 2π for the heading, π for its axis.
    fn period(&self) -> f64 {
        if self.heading == HeadingEncoding::AxisFacing { PI } else { TAU }
    }

    /// Width of one rotation bin, radians.
    pub fn bin_width(&self) -> f64 {
        self.period() / self.num_bins as f64
    }

    /// Centre of bin `j`, radians in [0, 2π) (in [0, π) for the axis).
    pub fn bin_centre(&self, j: usize) -> f64 {
        (j as f64 + 0.5) * self.bin_width()
    }

    /// The bin of a heading (of its axis with [`HeadingEncoding::AxisFacing`]).
    pub fn bin_of(&self, theta: f64) -> usize {
        ((theta.rem_euclid(self.period()) / self.bin_width()).floor() as usize).min(self.num_bins - 1)
    }

    /// Encodes `b` against the voxel centre `v`.
    pub fn encode(&self, b: &Box3d, v: [f64; 3]) -> EncodedBox {
        let dims = [b.l, b.w, b.h];
        let (dx, dy, dz) = (b.cx - v[0], b.cy - v[1], b.cz - v[2]);
        let (offset, theta) = match turn(self.frame, v) {
            Some((c, s)) => ([c * dx + s * dy, c * dy - s * dx, dz], wrap_angle(b.rot_z - s.atan2(c))),
            None => ([dx, dy, dz], b.rot_z),
        };
        EncodedBox {
            offset,
            log_dims: [0, 1, 2].map(|k| (dims[k] / self.mean_size[k]).ln()),
            bin: self.bin_of(theta),
            residuals: (0..self.num_bins).map(|j| wrap(theta - self.bin_centre(j), self.period())).collect(),
            faces_sensor: faces_sensor(b.cx, b.cy, b.rot_z),
            theta,
        }
    }

    /// Heading from a bin and its residual: `(k + ½)·bin + r`, minus 2π when above π.
    pub fn decode_heading(&self, bin: usize, residual: f64) -> f64 {
        let theta = self.bin_centre(bin) + residual;
        if theta > PI { theta - TAU } else { theta }
    }

    /// Decodes an encoding back into a box.
    pub fn decode(&self, e: &EncodedBox, v: [f64; 3]) -> Box3d {
        let theta = match self.heading {
            HeadingEncoding::Bins | HeadingEncoding::AxisFacing => self.decode_heading(e.bin, e.residuals[e.bin]),
            HeadingEncoding::SinCos => wrap_angle(e.theta),
        };
        let b = self.decode_parts(v, e.offset, e.log_dims, theta);
        self.orient(b, e.faces_sensor)
    }

    /// With [`HeadingEncoding::AxisFacing`], turns `b` (whose heading is only right as an axis) to
    /// face the sensor or away; other encodings decode the heading itself and keep it.
    fn orient(&self, b: Box3d, faces: bool) -> Box3d {
        if self.heading != HeadingEncoding::AxisFacing {
            return b;
        }
        let flip = faces_sensor(b.cx, b.cy, b.rot_z) != faces;
        Box3d { rot_z: if flip { wrap_angle(b.rot_z + PI) } else { b.rot_z }, ..b }
    }

    /// Decodes one voxel's head output (`channels()` values): the arg-max bin and its residual,
    /// or `atan2(sin, cos)`.
    pub fn decode_row(&self, row: &[f32], v: [f64; 3]) -> Box3d {
        let f = |i: usize| row[i] as f64;
        let theta = match self.heading {
            HeadingEncoding::Bins | HeadingEncoding::AxisFacing => {
                let bins = &row[BINS..BINS + self.num_bins];
                let k = (0..self.num_bins).fold(0, |best, j| if bins[j] > bins[best] { j } else { best });
                self.decode_heading(k, f(BINS + self.num_bins + k))
            }
            HeadingEncoding::SinCos => f(BINS).atan2(f(BINS + 1)),
        };
        let offset = [f(OFFSET), f(OFFSET + 1), f(OFFSET + 2)];
        let log_dims = [f(LOG_DIMS), f(LOG_DIMS + 1), f(LOG_DIMS + 2)];
        let b = self.decode_parts(v, offset, log_dims, theta);
        let faces = self.heading == HeadingEncoding::AxisFacing && row[facing_channel(self.num_bins)] > 0.0;
        self.orient(b, faces)
    }

    fn decode_parts(&self, v: [f64; 3], offset: [f64; 3], log_dims: [f64; 3], theta: f64) -> Box3d {
        let [l, w, h] = [0, 1, 2].map(|k| self.mean_size[k] * log_dims[k].exp());
        let ([dx, dy, dz], rot_z) = match turn(self.frame, v) {
            Some((c, s)) => ([c * offset[0] - s * offset[1], s * offset[0] + c * offset[1], offset[2]], wrap_angle(theta + s.atan2(c))),
            None => (offset, theta),
        };
        Box3d { cx: v[0] + dx, cy: v[1] + dy, cz: v[2] + dz, l, w, h, rot_z }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn encode_decode_round_trip_is_exact() {
        for frame in [BoxFrame::Base, BoxFrame::Ray] {
            round_trip(BoxCoder::new([0.9, 0.5, 1.7], 12).in_frame(frame));
            round_trip(BoxCoder::new([0.9, 0.5, 1.7], 12).in_frame(frame).with_heading(HeadingEncoding::SinCos));
            round_trip(BoxCoder::new([0.9, 0.5, 1.7], 12).in_frame(frame).with_heading(HeadingEncoding::AxisFacing));
        }
    }

    /// Hand-derived: a person 5 m ahead of the sensor (+x) facing it (θ = π) has the axis 0, bin 0
    /// of 12 bins of 15°, residual −7.5°, and faces the sensor; facing +y (θ = π/2, across the line
    /// of sight, nudged towards the sensor) has the axis in bin 6 and faces it; away (θ = 0) not.
    /// A row with the facing logit's sign turned decodes the opposite heading.
    #[test]
    fn axis_and_facing_by_hand() {
        let coder = BoxCoder::new([0.9, 0.5, 1.7], 12).with_heading(HeadingEncoding::AxisFacing);
        assert_eq!(coder.channels(), 32);
        assert!((coder.bin_width() - PI / 12.0).abs() < 1e-15);
        let v = [4.9, 0.1, 0.0];
        let b = Box3d { cx: 5.0, cy: 0.0, cz: 0.0, l: 0.4, w: 0.6, h: 1.7, rot_z: PI };
        let e = coder.encode(&b, v);
        assert_eq!(e.bin, 0);
        assert!((e.residuals[0] + PI / 24.0).abs() < 1e-12, "{:?}", e.residuals);
        assert!((e.residuals[11] - PI / 24.0).abs() < 1e-12, "the axis 0 is π, half a bin above bin 11's centre");
        assert!(e.faces_sensor);
        let across = coder.encode(&Box3d { rot_z: PI / 2.0 + 0.01, ..b }, v);
        assert_eq!((across.bin, across.faces_sensor), (6, true));
        assert!(!coder.encode(&Box3d { rot_z: 0.0, ..b }, v).faces_sensor);
        let mut row = vec![0f32; 32];
        row[BINS] = 5.0;
        row[BINS + 12] = e.residuals[0] as f32;
        row[facing_channel(12)] = 2.0;
        assert!((coder.decode_row(&row, v).rot_z.abs() - PI).abs() < 1e-6, "faces the sensor: θ = ±π");
        row[facing_channel(12)] = -2.0;
        assert!(coder.decode_row(&row, v).rot_z.abs() < 1e-6, "faces away: θ = 0");
        assert!((wrap_axis(PI) - 0.0).abs() < 1e-15 && (wrap_axis(-FRAC_PI_2) - FRAC_PI_2).abs() < 1e-15);
        // In the ray frame the axis is the observation angle's (α = θ − φ = π at v: axis 0), and
        // the scene turned by 30° about the sensor encodes the same bin, residuals and facing.
        let ray = coder.in_frame(BoxFrame::Ray);
        let r = ray.encode(&b, v);
        let phi = v[1].atan2(v[0]);
        assert_eq!(r.bin, ray.bin_of(PI - phi));
        assert!(r.faces_sensor);
        let (c, s) = ((PI / 6.0).cos(), (PI / 6.0).sin());
        let turned = Box3d { cx: c * b.cx - s * b.cy, cy: s * b.cx + c * b.cy, rot_z: b.rot_z + PI / 6.0, ..b };
        let r30 = ray.encode(&turned, [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]]);
        assert_eq!((r30.bin, r30.faces_sensor), (r.bin, r.faces_sensor));
        for (x, y) in r30.residuals.iter().zip(&r.residuals) {
            assert!((x - y).abs() < 1e-12, "{r30:?} vs {r:?}");
        }
    }

    /// Hand-derived: a voxel at (0, 5) looks along +y (φ = 90°); a centre 0.2 m farther out and
    /// 0.1 m to the sensor's right (+x, seen from the origin looking along +y) is offset (0.2, −0.1)
    /// in the ray frame; a person facing the sensor (θ = −90°) has α = −180°, facing away α = 0.
    #[test]
    fn ray_frame_by_hand() {
        let coder = BoxCoder::new([0.9, 0.5, 1.7], 12).in_frame(BoxFrame::Ray);
        let v = [0.0, 5.0, 0.3];
        let b = Box3d { cx: 0.1, cy: 5.2, cz: 0.9, l: 0.4, w: 0.6, h: 1.7, rot_z: -PI / 2.0 };
        let e = coder.encode(&b, v);
        for (got, want) in e.offset.iter().zip([0.2, -0.1, 0.6]) {
            assert!((got - want).abs() < 1e-12, "{:?}", e.offset);
        }
        assert_eq!(e.bin, coder.bin_of(PI), "α = ±180° is bin {}", coder.bin_of(PI));
        let away = coder.encode(&Box3d { rot_z: PI / 2.0, ..b }, v);
        assert_eq!(away.bin, 0);
        assert!((away.residuals[0] + coder.bin_width() / 2.0).abs() < 1e-12);
        // The same person seen at another azimuth (the scene turned by 30° about the sensor) has
        // the same encoding.
        let (c, s) = ((PI / 6.0).cos(), (PI / 6.0).sin());
        let turned = |x: f64, y: f64| (c * x - s * y, s * x + c * y);
        let (vx, vy) = turned(v[0], v[1]);
        let (bx, by) = turned(b.cx, b.cy);
        let e30 = coder.encode(&Box3d { cx: bx, cy: by, rot_z: b.rot_z + PI / 6.0, ..b }, [vx, vy, v[2]]);
        assert_eq!(e30.bin, e.bin);
        for (x, y) in e30.offset.iter().zip(&e.offset).chain(e30.residuals.iter().zip(&e.residuals)) {
            assert!((x - y).abs() < 1e-12, "{e30:?} vs {e:?}");
        }
    }

    fn round_trip(coder: BoxCoder) {
        let want = match coder.heading {
            HeadingEncoding::Bins => 31,
            HeadingEncoding::AxisFacing => 32,
            HeadingEncoding::SinCos => 9,
        };
        assert_eq!(coder.channels(), want);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut headings: Vec<f64> = (0..500).map(|_| rng.random_range(-10.0..10.0)).collect();
        // Bin edges, ±π and 0 are where an off-by-one would show.
        headings.extend((0..=24).map(|j| j as f64 * PI / 12.0 - PI));
        for theta in headings {
            let b = Box3d { cx: rng.random_range(-20.0..20.0), cy: rng.random_range(-20.0..20.0), cz: rng.random_range(-1.0..1.0),
                l: rng.random_range(0.3..1.5), w: rng.random_range(0.2..1.0), h: rng.random_range(1.0..2.0), rot_z: theta };
            let v = [b.cx + rng.random_range(-0.5..0.5), b.cy - 0.2, b.cz + 0.1];
            let e = coder.encode(&b, v);
            assert!(e.residuals[e.bin].abs() <= coder.bin_width() / 2.0 + 1e-12, "{e:?}");
            // Facing the sensor: the heading within 90° of the bearing from the box to the origin.
            let bearing = (-b.cy).atan2(-b.cx);
            assert_eq!(e.faces_sensor, wrap_angle(b.rot_z - bearing).abs() < PI / 2.0, "{b:?}");
            let bound = if coder.heading == HeadingEncoding::AxisFacing { PI / 2.0 } else { PI };
            assert!(e.residuals.iter().all(|r| r.abs() <= bound + 1e-12), "{e:?}");
            let d = coder.decode(&e, v);
            for (a, b) in [(d.cx, b.cx), (d.cy, b.cy), (d.cz, b.cz), (d.l, b.l), (d.w, b.w), (d.h, b.h)] {
                assert!((a - b).abs() < 1e-12, "{d:?} vs {b:?}");
            }
            assert!(d.rot_z > -PI && d.rot_z <= PI);
            // (±π are one heading: compare the difference wrapped.)
            assert!(wrap_angle(d.rot_z - theta).abs() < 1e-9, "θ {theta}: {} vs {}", d.rot_z, wrap_angle(theta));
            // Through the head layout: a row whose arg-max bin is the encoded one decodes the same box.
            let mut row = vec![0f32; coder.channels()];
            row[OFFSET..OFFSET + 3].copy_from_slice(&e.offset.map(|x| x as f32));
            row[LOG_DIMS..LOG_DIMS + 3].copy_from_slice(&e.log_dims.map(|x| x as f32));
            match coder.heading {
                HeadingEncoding::Bins | HeadingEncoding::AxisFacing => {
                    row[BINS + e.bin] = 5.0;
                    for (j, r) in e.residuals.iter().enumerate() {
                        row[BINS + 12 + j] = *r as f32;
                    }
                    if coder.heading == HeadingEncoding::AxisFacing {
                        row[facing_channel(12)] = if e.faces_sensor { 3.0 } else { -3.0 };
                    }
                }
                // Any positive multiple of (sin, cos) is the same heading.
                HeadingEncoding::SinCos => {
                    row[BINS] = (0.4 * e.theta.sin()) as f32;
                    row[BINS + 1] = (0.4 * e.theta.cos()) as f32;
                }
            }
            let r = coder.decode_row(&row, v);
            assert!((r.cx - b.cx).abs() < 1e-5 && (r.l - b.l).abs() < 1e-5);
            assert!(wrap_angle(r.rot_z - theta).abs() < 1e-5);
        }
    }

    #[test]
    fn residuals_follow_spec_example() {
        let coder = BoxCoder::new([0.9, 0.5, 1.7], 12);
        let bin = PI / 6.0;
        let e = coder.encode(&Box3d { cx: 0.0, cy: 0.0, cz: 0.0, l: 0.9, w: 0.5, h: 1.7, rot_z: -0.1 }, [0.0; 3]);
        assert_eq!(e.bin, 11); // −0.1 mod 2π lies in the last bin
        assert!((e.residuals[11] - (TAU - 0.1 - 11.5 * bin)).abs() < 1e-12);
        assert!((e.residuals[0] - (-0.1 - 0.5 * bin)).abs() < 1e-12);
        assert_eq!(e.log_dims, [0.0, 0.0, 0.0]);
    }
}
