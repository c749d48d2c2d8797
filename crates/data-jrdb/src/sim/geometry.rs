//! Analytic ray intersection with the simulator's primitives (world frame, metres, z up).

/// 3-vector helpers.
pub type V3 = [f64; 3];

pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(crate) fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
fn norm(a: V3) -> V3 {
    let n = dot(a, a).sqrt().max(1e-12);
    scale(a, 1.0 / n)
}
/// Rotates the xy part by `yaw` (counter-clockwise).
pub fn rot(a: V3, yaw: f64) -> V3 {
    let (s, c) = yaw.sin_cos();
    [c * a[0] - s * a[1], s * a[0] + c * a[1], a[2]]
}

/// A surface a ray can hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// The horizontal plane at height z (floor or ceiling), seen from either side.
    PlaneZ(f64),
    /// A box of half sizes `half` about centre `c`, turned by `yaw` about z.
    Cuboid {
        /// Centre.
        c: V3,
        /// Half sizes along the box's own x, y, z.
        half: V3,
        /// Turn about z (radians).
        yaw: f64,
    },
    /// An upright capped cylinder.
    Cylinder {
        /// Axis position (x, y).
        c: [f64; 2],
        /// Radius.
        r: f64,
        /// Bottom cap height.
        z0: f64,
        /// Top cap height.
        z1: f64,
    },
    /// All points within `r` of the segment a–b.
    Capsule {
        /// One end of the segment.
        a: V3,
        /// The other end.
        b: V3,
        /// Radius.
        r: f64,
    },
    /// An ellipsoid with semi-axes `radii` along its own x, y, z, turned by `yaw` about z.
    Ellipsoid {
        /// Centre.
        c: V3,
        /// Semi-axes along its own x, y, z.
        radii: V3,
        /// Turn about z (radians).
        yaw: f64,
    },
    /// Foliage: an upright ellipsoid a beam enters and stops in after a random free path (mean
    /// `1 / density` metres), so a crown or a hedge returns a scattered volume, not a shell.
    Foliage {
        /// Centre.
        c: V3,
        /// Semi-axes along x, y, z.
        radii: V3,
        /// Leaves met per metre of beam.
        density: f64,
    },
}

/// A uniform number in (0, 1] from a ray's direction and a shape's centre: the same ray through
/// the same foliage always stops at the same depth.
fn ray_unit(d: V3, c: V3) -> f64 {
    let mut z = 0x9E37_79B9_7F4A_7C15u64;
    for v in [d[0], d[1], d[2], c[0], c[1], c[2]] {
        z = (z ^ v.to_bits()).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z ^= z >> 29;
    }
    z = (z ^ (z >> 32)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z >> 11) as f64 + 1.0) / (1u64 << 53) as f64
}

/// A ray hit: distance along the unit direction and the unit surface normal there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the ray's unit direction.
    pub t: f64,
    /// Unit surface normal at the hit.
    pub normal: V3,
}

const EPS: f64 = 1e-6;

impl Shape {
    /// Centre and radius of a vertical cylinder around the shape in the ground plane (culling).
    pub fn bounds_xy(&self) -> Option<([f64; 2], f64)> {
        match *self {
            Shape::PlaneZ(_) => None,
            Shape::Cuboid { c, half, .. } => Some(([c[0], c[1]], half[0].hypot(half[1]))),
            Shape::Cylinder { c, r, .. } => Some((c, r)),
            Shape::Capsule { a, b, r } => {
                let m = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
                Some((m, (a[0] - b[0]).hypot(a[1] - b[1]) / 2.0 + r))
            }
            Shape::Ellipsoid { c, radii, .. } | Shape::Foliage { c, radii, .. } => Some(([c[0], c[1]], radii[0].max(radii[1]))),
        }
    }

    /// The shape moved from its own frame (x forward, the ground at z = 0) to the ground point
    /// (x, y, z), turned by `yaw`: how people and objects are placed in the world.
    pub fn placed(self, x: f64, y: f64, z: f64, yaw: f64) -> Shape {
        let tr = |p: V3| {
            let q = rot(p, yaw);
            [q[0] + x, q[1] + y, q[2] + z]
        };
        match self {
            Shape::Capsule { a, b, r } => Shape::Capsule { a: tr(a), b: tr(b), r },
            Shape::Ellipsoid { c, radii, yaw: y0 } => Shape::Ellipsoid { c: tr(c), radii, yaw: y0 + yaw },
            Shape::Cuboid { c, half, yaw: y0 } => Shape::Cuboid { c: tr(c), half, yaw: y0 + yaw },
            Shape::Cylinder { c, r, z0, z1 } => {
                let q = tr([c[0], c[1], 0.0]);
                Shape::Cylinder { c: [q[0], q[1]], r, z0: z0 + z, z1: z1 + z }
            }
            Shape::PlaneZ(h) => Shape::PlaneZ(h + z),
            Shape::Foliage { c, radii, density } => Shape::Foliage { c: tr(c), radii, density },
        }
    }

    /// Height range of the shape (culling by elevation is not done; used for placement).
    pub fn top(&self) -> f64 {
        match *self {
            Shape::PlaneZ(z) => z,
            Shape::Cuboid { c, half, .. } => c[2] + half[2],
            Shape::Cylinder { z1, .. } => z1,
            Shape::Capsule { a, b, r } => a[2].max(b[2]) + r,
            Shape::Ellipsoid { c, radii, .. } | Shape::Foliage { c, radii, .. } => c[2] + radii[2],
        }
    }

    /// The nearest hit of the ray o + t·d (d of unit length) with t in (EPS, t_max).
    pub fn intersect(&self, o: V3, d: V3, t_max: f64) -> Option<Hit> {
        let h = match *self {
            Shape::PlaneZ(z) => {
                if d[2].abs() < 1e-12 {
                    return None;
                }
                let t = (z - o[2]) / d[2];
                Hit { t, normal: [0.0, 0.0, -d[2].signum()] }
            }
            Shape::Cuboid { c, half, yaw } => {
                let lo = rot(sub(o, c), -yaw);
                let ld = rot(d, -yaw);
                let (mut tn, mut tf, mut axis) = (f64::NEG_INFINITY, f64::INFINITY, 0);
                for k in 0..3 {
                    if ld[k].abs() < 1e-12 {
                        if lo[k].abs() > half[k] {
                            return None;
                        }
                        continue;
                    }
                    let inv = 1.0 / ld[k];
                    let (mut t1, mut t2) = ((-half[k] - lo[k]) * inv, (half[k] - lo[k]) * inv);
                    if t1 > t2 {
                        std::mem::swap(&mut t1, &mut t2);
                    }
                    if t1 > tn {
                        tn = t1;
                        axis = k;
                    }
                    tf = tf.min(t2);
                }
                if tn > tf || tn <= EPS {
                    return None;
                }
                let mut n = [0.0; 3];
                n[axis] = -ld[axis].signum();
                Hit { t: tn, normal: rot(n, yaw) }
            }
            Shape::Cylinder { c, r, z0, z1 } => {
                let (ox, oy) = (o[0] - c[0], o[1] - c[1]);
                let a = d[0] * d[0] + d[1] * d[1];
                let mut best: Option<Hit> = None;
                if a > 1e-12 {
                    let b = ox * d[0] + oy * d[1];
                    let cc = ox * ox + oy * oy - r * r;
                    let disc = b * b - a * cc;
                    if disc >= 0.0 {
                        let t = (-b - disc.sqrt()) / a;
                        let z = o[2] + t * d[2];
                        if t > EPS && z >= z0 && z <= z1 {
                            let n = [(ox + t * d[0]) / r, (oy + t * d[1]) / r, 0.0];
                            best = Some(Hit { t, normal: n });
                        }
                    }
                }
                if d[2].abs() > 1e-12 {
                    for (zc, nz) in [(z1, 1.0), (z0, -1.0)] {
                        let t = (zc - o[2]) / d[2];
                        let (px, py) = (ox + t * d[0], oy + t * d[1]);
                        if t > EPS && px * px + py * py <= r * r && best.is_none_or(|h| t < h.t) && d[2] * nz < 0.0 {
                            best = Some(Hit { t, normal: [0.0, 0.0, nz] });
                        }
                    }
                }
                best?
            }
            Shape::Capsule { a, b, r } => {
                // Inigo Quilez's capsule intersection.
                let ba = sub(b, a);
                let oa = sub(o, a);
                let baba = dot(ba, ba);
                let bard = dot(ba, d);
                let baoa = dot(ba, oa);
                let rdoa = dot(d, oa);
                let oaoa = dot(oa, oa);
                let qa = baba - bard * bard;
                let qb = baba * rdoa - baoa * bard;
                let qc = baba * oaoa - baoa * baoa - r * r * baba;
                let mut hit_t = None;
                if qa.abs() > 1e-12 {
                    let h = qb * qb - qa * qc;
                    if h >= 0.0 {
                        let t = (-qb - h.sqrt()) / qa;
                        let y = baoa + t * bard;
                        if y > 0.0 && y < baba && t > EPS {
                            hit_t = Some(t);
                        }
                    }
                }
                if hit_t.is_none() {
                    for cap in [a, b] {
                        let oc = sub(o, cap);
                        let bb = dot(d, oc);
                        let h = bb * bb - (dot(oc, oc) - r * r);
                        if h >= 0.0 {
                            let t = -bb - h.sqrt();
                            if t > EPS && hit_t.is_none_or(|u| t < u) {
                                hit_t = Some(t);
                            }
                        }
                    }
                }
                let t = hit_t?;
                let p = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
                let s = (dot(sub(p, a), ba) / baba).clamp(0.0, 1.0);
                let q = [a[0] + s * ba[0], a[1] + s * ba[1], a[2] + s * ba[2]];
                Hit { t, normal: norm(sub(p, q)) }
            }
            Shape::Ellipsoid { c, radii, yaw } => {
                let lo = rot(sub(o, c), -yaw);
                let ld = rot(d, -yaw);
                let so = [lo[0] / radii[0], lo[1] / radii[1], lo[2] / radii[2]];
                let sd = [ld[0] / radii[0], ld[1] / radii[1], ld[2] / radii[2]];
                let a = dot(sd, sd);
                let b = dot(so, sd);
                let cc = dot(so, so) - 1.0;
                let disc = b * b - a * cc;
                if disc < 0.0 {
                    return None;
                }
                let t = (-b - disc.sqrt()) / a;
                let p = [lo[0] + t * ld[0], lo[1] + t * ld[1], lo[2] + t * ld[2]];
                let n = [p[0] / (radii[0] * radii[0]), p[1] / (radii[1] * radii[1]), p[2] / (radii[2] * radii[2])];
                Hit { t, normal: rot(norm(n), yaw) }
            }
            Shape::Foliage { c, radii, density } => {
                let lo = sub(o, c);
                let so = [lo[0] / radii[0], lo[1] / radii[1], lo[2] / radii[2]];
                let sd = [d[0] / radii[0], d[1] / radii[1], d[2] / radii[2]];
                let a = dot(sd, sd);
                let b = dot(so, sd);
                let disc = b * b - a * (dot(so, so) - 1.0);
                if disc < 0.0 {
                    return None;
                }
                let (t0, t1) = ((-b - disc.sqrt()) / a, (-b + disc.sqrt()) / a);
                let t = t0.max(EPS) - ray_unit(d, c).ln() / density;
                if t >= t1 {
                    return None;
                }
                // Leaves face every way: the return is as bright as a square-on one.
                Hit { t, normal: [-d[0], -d[1], -d[2]] }
            }
        };
        (h.t > EPS && h.t < t_max).then_some(h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_shape_is_hit_at_the_expected_distance() {
        let o = [0.0, 0.0, 0.0];
        let d = [1.0, 0.0, 0.0];
        let cases = [
            (Shape::Cuboid { c: [5.0, 0.0, 0.0], half: [0.5, 1.0, 1.0], yaw: 0.0 }, 4.5),
            (Shape::Cuboid { c: [5.0, 0.0, 0.0], half: [0.5, 0.5, 1.0], yaw: std::f64::consts::FRAC_PI_4 }, 5.0 - 0.5f64.hypot(0.5)),
            (Shape::Cylinder { c: [3.0, 0.0], r: 0.5, z0: -1.0, z1: 1.0 }, 2.5),
            (Shape::Capsule { a: [4.0, 0.0, -1.0], b: [4.0, 0.0, 1.0], r: 0.25 }, 3.75),
            (Shape::Capsule { a: [4.0, 0.0, 0.0], b: [6.0, 0.0, 0.0], r: 0.25 }, 3.75),
            (Shape::Ellipsoid { c: [6.0, 0.0, 0.0], radii: [0.2, 1.0, 2.0], yaw: 0.0 }, 5.8),
            (Shape::Ellipsoid { c: [6.0, 0.0, 0.0], radii: [0.2, 1.0, 2.0], yaw: std::f64::consts::FRAC_PI_2 }, 5.0),
        ];
        for (s, t) in cases {
            let h = s.intersect(o, d, 100.0).unwrap_or_else(|| panic!("{s:?} missed"));
            assert!((h.t - t).abs() < 1e-9, "{s:?}: {} vs {t}", h.t);
            assert!(h.normal[0] < -0.7, "{s:?} normal {:?}", h.normal);
            assert!(s.intersect(o, [-1.0, 0.0, 0.0], 100.0).is_none());
        }
        let floor = Shape::PlaneZ(-0.7);
        let h = floor.intersect([0.0, 0.0, 0.3], norm([1.0, 0.0, -1.0]), 100.0).unwrap();
        assert!((h.t - 2f64.sqrt()).abs() < 1e-9 && h.normal[2] == 1.0);
    }
}
