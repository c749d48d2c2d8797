//! The things around people that a LiDAR confuses with them: vehicles, bicycles, posts, trees,
//! fences, furniture. Each builder returns world-frame shapes with their reflectivities, standing
//! on the ground at height `z` and turned by `yaw`.

use rand::Rng;

use super::geometry::{Shape, V3, rot};

/// Shapes with their reflectivities.
pub type Parts = Vec<(Shape, f32)>;

/// A box of sizes (sx, sy, sz) whose centre's footprint is (x, y), from height z0 up.
pub fn cuboid(x: f64, y: f64, z0: f64, sx: f64, sy: f64, sz: f64, yaw: f64) -> Shape {
    Shape::Cuboid { c: [x, y, z0 + sz / 2.0], half: [sx / 2.0, sy / 2.0, sz / 2.0], yaw }
}

/// Moves object-frame shapes (x forward along `yaw`, z up from the ground) to (x, y, z).
pub fn placed(parts: Parts, x: f64, y: f64, z: f64, yaw: f64) -> Parts {
    parts.into_iter().map(|(s, r)| (s.placed(x, y, z, yaw), r)).collect()
}

fn local(x: f64, y: f64, z0: f64, sx: f64, sy: f64, sz: f64) -> Shape {
    cuboid(x, y, z0, sx, sy, sz, 0.0)
}

/// A wheel of radius `r` at (x, y) in the object's frame: a thin disc facing sideways.
fn wheel(x: f64, y: f64, r: f64, width: f64) -> Shape {
    Shape::Ellipsoid { c: [x, y, r], radii: [r, width / 2.0, r], yaw: 0.0 }
}

/// The kinds of road vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Vehicle {
    /// A car (hatchback to saloon).
    Car,
    /// A van or SUV.
    Van,
    /// A bus or lorry.
    Bus,
}

impl Vehicle {
    /// A random kind: mostly cars.
    pub fn sample<R: Rng + ?Sized>(rng: &mut R) -> Self {
        match rng.random_range(0..10) {
            0..=6 => Vehicle::Car,
            7..=8 => Vehicle::Van,
            _ => Vehicle::Bus,
        }
    }

    /// Length and width (m), for placing it.
    pub fn footprint(self) -> [f64; 2] {
        match self {
            Vehicle::Car => [4.4, 1.8],
            Vehicle::Van => [5.2, 2.0],
            Vehicle::Bus => [11.0, 2.55],
        }
    }

    /// Its body in its own frame (x forward, the ground at z = 0), sizes jittered by `rng`.
    pub fn parts<R: Rng + ?Sized>(self, rng: &mut R) -> Parts {
        let paint = rng.random_range(0.1..0.8);
        let glass = 0.05;
        let [l, w] = self.footprint();
        let (l, w) = (l * rng.random_range(0.92..1.08), w * rng.random_range(0.95..1.05));
        let mut out = Vec::new();
        let (clear, wr) = match self {
            Vehicle::Bus => (0.35, 0.5),
            _ => (0.18, rng.random_range(0.3..0.37)),
        };
        match self {
            Vehicle::Car => {
                let belt = rng.random_range(0.85..1.0);
                let roof = rng.random_range(1.4..1.55);
                out.push((local(0.0, 0.0, clear, l, w, belt - clear), paint));
                let cab = l * rng.random_range(0.45..0.6);
                out.push((local(-0.1 * l, 0.0, belt, cab, w * 0.9, roof - belt), glass));
                out.push((local(-0.1 * l, 0.0, roof - 0.04, cab * 0.8, w * 0.85, 0.04), paint));
            }
            Vehicle::Van => {
                let roof = rng.random_range(1.8..2.4);
                out.push((local(-0.1 * l, 0.0, clear, 0.8 * l, w, roof - clear), paint));
                out.push((local(0.4 * l, 0.0, clear, 0.2 * l, w * 0.98, 0.9), paint));
                out.push((local(0.28 * l, 0.0, 1.0, 0.06, w * 0.9, roof - 1.1), glass));
            }
            Vehicle::Bus => {
                let roof = rng.random_range(2.9..3.4);
                out.push((local(0.0, 0.0, clear, l, w, 0.6), paint));
                out.push((local(0.0, 0.0, clear + 0.6, l, w * 0.99, 1.2), glass));
                out.push((local(0.0, 0.0, clear + 1.8, l, w, roof - clear - 1.8), paint));
            }
        }
        let axle = 0.36 * l;
        for (x, y) in [(axle, w / 2.0 - 0.12), (axle, -w / 2.0 + 0.12), (-axle, w / 2.0 - 0.12), (-axle, -w / 2.0 + 0.12)] {
            out.push((wheel(x, y, wr, 0.22), 0.05));
        }
        out
    }
}

/// A bicycle standing or walked (x along the frame), wheels 0.33–0.36 m in radius.
pub fn bicycle<R: Rng + ?Sized>(rng: &mut R) -> Parts {
    let r = rng.random_range(0.33..0.36);
    let metal = rng.random_range(0.3..0.7);
    let cap = |a: V3, b: V3, rad: f64| Shape::Capsule { a, b, r: rad };
    let (rear, front) = ([-0.52, 0.0, r], [0.52, 0.0, r]);
    let seat = [-0.25, 0.0, 0.95];
    let bars = [0.38, 0.0, 1.05];
    let crank = [-0.05, 0.0, 0.3];
    vec![
        (wheel(rear[0], 0.0, r, 0.04), 0.2),
        (wheel(front[0], 0.0, r, 0.04), 0.2),
        (cap(rear, crank, 0.02), metal),
        (cap(crank, seat, 0.02), metal),
        (cap(seat, bars, 0.02), metal),
        (cap(crank, bars, 0.02), metal),
        (cap(bars, front, 0.02), metal),
        (cap([bars[0], -0.28, bars[2]], [bars[0], 0.28, bars[2]], 0.015), metal),
        (cap(rear, seat, 0.015), metal),
        (Shape::Ellipsoid { c: [seat[0], 0.0, seat[2] + 0.03], radii: [0.13, 0.07, 0.03], yaw: 0.0 }, 0.1),
    ]
}

/// A standing kick scooter (electric or not).
pub fn scooter<R: Rng + ?Sized>(rng: &mut R) -> Parts {
    let stem = rng.random_range(1.0..1.2);
    let cap = |a: V3, b: V3, rad: f64| Shape::Capsule { a, b, r: rad };
    vec![
        (local(0.0, 0.0, 0.08, 0.8, 0.16, 0.05), 0.3),
        (wheel(-0.4, 0.0, 0.1, 0.05), 0.1),
        (wheel(0.4, 0.0, 0.1, 0.05), 0.1),
        (cap([0.42, 0.0, 0.1], [0.38, 0.0, stem], 0.025), 0.5),
        (cap([0.38, -0.25, stem], [0.38, 0.25, stem], 0.02), 0.5),
    ]
}

/// A pushchair pushed from behind (x forward; its handle at x = 0).
pub fn stroller<R: Rng + ?Sized>(rng: &mut R) -> Parts {
    let cap = |a: V3, b: V3, rad: f64| Shape::Capsule { a, b, r: rad };
    let fabric = rng.random_range(0.1..0.5);
    vec![
        (cap([0.0, -0.25, 1.0], [0.0, 0.25, 1.0], 0.02), 0.4),
        (cap([0.0, 0.0, 1.0], [0.45, 0.0, 0.3], 0.02), 0.4),
        (Shape::Ellipsoid { c: [0.5, 0.0, 0.6], radii: [0.35, 0.27, 0.3], yaw: 0.0 }, fabric),
        (wheel(0.2, 0.22, 0.1, 0.04), 0.1),
        (wheel(0.2, -0.22, 0.1, 0.04), 0.1),
        (wheel(0.75, 0.22, 0.08, 0.04), 0.1),
        (wheel(0.75, -0.22, 0.08, 0.04), 0.1),
    ]
}

/// Street furniture and vegetation: things of a person's size or a person's outline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fixture {
    /// A lamp post (4–9 m).
    LampPost,
    /// A sign on a post, at 2–2.5 m.
    SignPost,
    /// A short post or bollard (0.6–1.2 m).
    Bollard,
    /// A litter bin or a wheelie bin.
    Bin,
    /// A bench.
    Bench,
    /// A tree: trunk, often a guard, and a crown.
    Tree,
    /// A bush or a hedge segment.
    Bush,
    /// A fire hydrant or a utility box.
    Hydrant,
    /// A parked bicycle (often at a rack).
    Bicycle,
    /// A parked kick scooter.
    Scooter,
    /// A planter or a potted plant.
    Planter,
    /// A traffic cone or a barrier.
    Cone,
    /// A kiosk, vending machine or ticket machine (person-tall box).
    Kiosk,
    /// An advertising or information pillar.
    Pillar,
    /// A café table with chairs.
    CafeTable,
}

impl Fixture {
    /// Every kind.
    pub const ALL: [Fixture; 15] = [
        Fixture::LampPost,
        Fixture::SignPost,
        Fixture::Bollard,
        Fixture::Bin,
        Fixture::Bench,
        Fixture::Tree,
        Fixture::Bush,
        Fixture::Hydrant,
        Fixture::Bicycle,
        Fixture::Scooter,
        Fixture::Planter,
        Fixture::Cone,
        Fixture::Kiosk,
        Fixture::Pillar,
        Fixture::CafeTable,
    ];

    /// A random kind.
    pub fn sample<R: Rng + ?Sized>(rng: &mut R) -> Self {
        Self::ALL[rng.random_range(0..Self::ALL.len())]
    }

    /// Its shapes in its own frame, the ground at z = 0.
    pub fn parts<R: Rng + ?Sized>(self, rng: &mut R) -> Parts {
        let cyl = |r: f64, z0: f64, z1: f64| Shape::Cylinder { c: [0.0, 0.0], r, z0, z1 };
        let cap = |a: V3, b: V3, rad: f64| Shape::Capsule { a, b, r: rad };
        match self {
            Fixture::LampPost => {
                let h = rng.random_range(4.0..9.0);
                let mut p = vec![(cyl(rng.random_range(0.06..0.12), 0.0, h), 0.5)];
                if rng.random_bool(0.6) {
                    p.push((cap([0.0, 0.0, h], [1.2, 0.0, h + 0.2], 0.05), 0.5));
                }
                p
            }
            Fixture::SignPost => {
                let h = rng.random_range(2.0..2.6);
                let mut p = vec![(cyl(0.035, 0.0, h), 0.5)];
                let (sw, sh) = (rng.random_range(0.4..0.9), rng.random_range(0.4..0.9));
                p.push((local(0.0, 0.0, h - sh, 0.03, sw, sh), 0.9));
                if rng.random_bool(0.3) {
                    p.push((local(0.0, 0.0, h - sh - 0.45, 0.03, sw * 0.8, 0.35), 0.9));
                }
                p
            }
            Fixture::Bollard => vec![(cyl(rng.random_range(0.06..0.15), 0.0, rng.random_range(0.6..1.2)), 0.6)],
            Fixture::Bin => {
                if rng.random_bool(0.5) {
                    vec![(cyl(rng.random_range(0.2..0.32), 0.0, rng.random_range(0.8..1.1)), 0.3)]
                } else {
                    vec![(local(0.0, 0.0, 0.0, rng.random_range(0.55..0.75), rng.random_range(0.5..0.6), rng.random_range(0.95..1.1)), 0.2)]
                }
            }
            Fixture::Bench => {
                let l = rng.random_range(1.4..2.2);
                let mut p = vec![(local(0.0, 0.0, 0.42, 0.45, l, 0.05), 0.4)];
                if rng.random_bool(0.7) {
                    p.push((local(-0.22, 0.0, 0.45, 0.05, l, 0.45), 0.4));
                }
                for y in [-l / 2.0 + 0.1, l / 2.0 - 0.1] {
                    p.push((local(0.0, y, 0.0, 0.4, 0.06, 0.42), 0.4));
                }
                p
            }
            Fixture::Tree => {
                let trunk = rng.random_range(1.8..3.5);
                let tr = rng.random_range(0.08..0.3);
                let mut p = vec![(cyl(tr, 0.0, trunk + 0.5), 0.3)];
                let r = rng.random_range(1.0..3.0);
                p.push((Shape::Foliage { c: [0.0, 0.0, trunk + r * 0.8], radii: [r, r, r * rng.random_range(0.8..1.3)], density: rng.random_range(1.5..5.0) }, 0.2));
                // Low branches reaching out from the trunk.
                for k in 0..rng.random_range(0..4) {
                    let a = k as f64 * 1.9 + rng.random_range(0.0..1.0);
                    let z0 = trunk * rng.random_range(0.6..1.0);
                    let reach = rng.random_range(0.5..1.2) * r;
                    p.push((Shape::Capsule { a: [0.0, 0.0, z0], b: [reach * a.cos(), reach * a.sin(), z0 + 0.6 * reach], r: tr * 0.35 }, 0.3));
                }
                if rng.random_bool(0.3) {
                    // A guard of four posts around young trees.
                    for (x, y) in [(0.35, 0.35), (-0.35, 0.35), (0.35, -0.35), (-0.35, -0.35)] {
                        p.push((cap([x, y, 0.0], [x, y, 1.4], 0.02), 0.5));
                    }
                    p.push((local(0.0, 0.0, 1.3, 0.72, 0.72, 0.04), 0.5));
                }
                p
            }
            Fixture::Bush => {
                let (rx, ry, rz) = (rng.random_range(0.3..1.5), rng.random_range(0.3..0.8), rng.random_range(0.35..0.9));
                vec![(Shape::Foliage { c: [0.0, 0.0, rz * 0.8], radii: [rx, ry, rz], density: rng.random_range(3.0..10.0) }, 0.2)]
            }
            Fixture::Hydrant => {
                if rng.random_bool(0.5) {
                    vec![(cyl(0.12, 0.0, 0.7), 0.6), (Shape::Ellipsoid { c: [0.0, 0.0, 0.7], radii: [0.13, 0.13, 0.1], yaw: 0.0 }, 0.6)]
                } else {
                    vec![(local(0.0, 0.0, 0.0, rng.random_range(0.3..0.6), rng.random_range(0.5..1.0), rng.random_range(0.9..1.5)), 0.4)]
                }
            }
            Fixture::Bicycle => {
                let mut p = bicycle(rng);
                if rng.random_bool(0.4) {
                    // A rack: an inverted U beside it.
                    p.push((cap([-0.4, 0.12, 0.0], [-0.4, 0.12, 0.8], 0.025), 0.6));
                    p.push((cap([0.4, 0.12, 0.0], [0.4, 0.12, 0.8], 0.025), 0.6));
                    p.push((cap([-0.4, 0.12, 0.8], [0.4, 0.12, 0.8], 0.025), 0.6));
                }
                p
            }
            Fixture::Scooter => scooter(rng),
            Fixture::Planter => {
                let pot = rng.random_range(0.3..0.8);
                let r = rng.random_range(0.2..0.5);
                vec![(cyl(r, 0.0, pot), 0.3), (Shape::Foliage { c: [0.0, 0.0, pot + r], radii: [r * 1.2, r * 1.2, r * rng.random_range(1.0..2.5)], density: rng.random_range(3.0..10.0) }, 0.2)]
            }
            Fixture::Cone => {
                if rng.random_bool(0.5) {
                    vec![(cap([0.0, 0.0, 0.1], [0.0, 0.0, 0.6], 0.08), 0.9), (local(0.0, 0.0, 0.0, 0.35, 0.35, 0.04), 0.3)]
                } else {
                    let l = rng.random_range(1.0..2.0);
                    vec![(local(0.0, 0.0, 0.7, 0.05, l, 0.3), 0.9), (local(0.0, -l / 2.0, 0.0, 0.4, 0.05, 1.0), 0.5), (local(0.0, l / 2.0, 0.0, 0.4, 0.05, 1.0), 0.5)]
                }
            }
            Fixture::Kiosk => vec![(local(0.0, 0.0, 0.0, rng.random_range(0.4..1.0), rng.random_range(0.5..1.2), rng.random_range(1.5..2.1)), 0.4)],
            Fixture::Pillar => vec![(cyl(rng.random_range(0.3..0.7), 0.0, rng.random_range(2.2..3.5)), 0.5)],
            Fixture::CafeTable => {
                let mut p = vec![(cyl(0.35, 0.72, 0.75), 0.5), (cyl(0.04, 0.0, 0.72), 0.5)];
                for k in 0..rng.random_range(1..4) {
                    let a = k as f64 * 2.1 + rng.random_range(-0.3..0.3);
                    let (x, y) = (0.6 * a.cos(), 0.6 * a.sin());
                    p.push((cuboid(x, y, 0.43, 0.42, 0.42, 0.04, a), 0.4));
                    let b = rot([0.2, 0.0, 0.0], a);
                    p.push((cuboid(x + b[0], y + b[1], 0.45, 0.04, 0.42, 0.42, a), 0.4));
                }
                p
            }
        }
    }
}

/// A fence or railing from `a` to `b` (ground points): posts every 1.5–3 m, rails or panels,
/// with gaps where it opens.
pub fn fence<R: Rng + ?Sized>(a: [f64; 2], b: [f64; 2], z: f64, rng: &mut R) -> Parts {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = dx.hypot(dy);
    let yaw = dy.atan2(dx);
    let h = rng.random_range(0.9..2.0);
    let step = rng.random_range(1.5..3.0);
    let kind = rng.random_range(0..4);
    let refl = rng.random_range(0.2..0.7);
    let mut out = Vec::new();
    let mut s = 0.0;
    while s < len {
        let e = (s + step).min(len);
        if rng.random_bool(0.08) {
            s = e; // a gap
            continue;
        }
        let p = [a[0] + dx * s / len, a[1] + dy * s / len];
        out.push((Shape::Cylinder { c: p, r: 0.04, z0: z, z1: z + h }, refl));
        let m = [a[0] + dx * (s + e) / 2.0 / len, a[1] + dy * (s + e) / 2.0 / len];
        match kind {
            // Rails: two or three thin bars.
            0 => {
                for k in 1..=3 {
                    let rz = z + h * k as f64 / 3.0 - 0.03;
                    out.push((cuboid(m[0], m[1], rz, e - s, 0.04, 0.04, yaw), refl));
                }
            }
            // A mesh or slatted panel: hit sparsely (low reflectivity raises dropouts).
            1 => out.push((cuboid(m[0], m[1], z + 0.05, e - s, 0.03, h - 0.1, yaw), 0.12)),
            // A solid panel or low wall.
            2 => out.push((cuboid(m[0], m[1], z, e - s, 0.15, h * 0.6, yaw), refl)),
            // A hedge: foliage along the line, no posts needed but left in.
            _ => {
                let hh = h * 0.6;
                let balls = ((e - s) / 0.8).ceil().max(1.0) as usize;
                for k in 0..balls {
                    let f = s + (k as f64 + 0.5) * (e - s) / balls as f64;
                    let c = [a[0] + dx * f / len, a[1] + dy * f / len, z + hh / 2.0];
                    out.push((Shape::Foliage { c, radii: [0.55, 0.55, hh / 2.0 + 0.1], density: rng.random_range(4.0..10.0) }, 0.2));
                }
            }
        }
        s = e;
    }
    out
}
