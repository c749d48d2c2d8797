//! People as sets of body parts (legs, feet, torso, arms, neck, head, optional backpack), posed for
//! standing, walking or sitting, and their tight boxes.
//!
//! A body is built in its own frame (origin on the floor under the pelvis, x along the heading, y
//! to the left) and then turned by the heading and moved to its place.

use rand::Rng;

use super::geometry::{Shape, V3, rot};
use crate::box3d::Box3d;

/// What a person is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Activity {
    /// Standing still (weight shifting slightly).
    Standing,
    /// Walking at `speed` m/s with swinging legs and arms.
    Walking {
        /// Walking speed (m/s).
        speed: f64,
    },
    /// Sitting on a seat of the given height.
    Sitting {
        /// Seat height above the floor (m).
        seat: f64,
    },
}

/// How the arms are held.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Arms {
    /// Hanging, swinging when walking.
    Hanging,
    /// One forearm raised in front (phone, cup).
    Holding,
    /// Arms folded in front of the chest.
    Folded,
}

/// The body of one person: sizes that stay fixed over a sequence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    /// Standing height (m).
    pub height: f64,
    /// Half the shoulder width (m).
    pub shoulder: f64,
    /// Half the distance between the hip joints (m).
    pub hip: f64,
    /// The torso's half depth, front to back (m).
    pub depth: f64,
    /// Leg radius (m).
    pub leg_r: f64,
    /// Arm radius (m).
    pub arm_r: f64,
    /// The head's semi-axes: front to back, side to side, up (m).
    pub head: V3,
    /// How the arms are held.
    pub arms: Arms,
    /// A backpack on the back: one of the cues to which way the person faces.
    pub backpack: bool,
    /// Long coat or dress: a wider lower torso.
    pub coat: bool,
}

impl Body {
    /// A random adult body (heights 1.5–1.95 m, varied widths).
    pub fn sample<R: Rng + ?Sized>(rng: &mut R) -> Self {
        let height: f64 = rng.random_range(1.5..1.95);
        let girth: f64 = rng.random_range(0.85..1.25);
        let shoulder = height * rng.random_range(0.115..0.135) * girth.sqrt();
        Body {
            height,
            shoulder,
            hip: shoulder * rng.random_range(0.5..0.65),
            depth: rng.random_range(0.09..0.13) * girth,
            leg_r: rng.random_range(0.055..0.075) * girth.sqrt(),
            arm_r: rng.random_range(0.038..0.05) * girth.sqrt(),
            head: [rng.random_range(0.09..0.105), rng.random_range(0.075..0.09), rng.random_range(0.11..0.125)],
            arms: match rng.random_range(0..10) {
                0..=6 => Arms::Hanging,
                7..=8 => Arms::Holding,
                _ => Arms::Folded,
            },
            backpack: rng.random_bool(0.25),
            coat: rng.random_bool(0.15),
        }
    }

    /// A body of `bench-v2`'s crowd: one in ten a child (1.0–1.45 m), adults 1.45–2.0 m, more
    /// coats and bags than `sample`'s.
    pub fn sample_crowd<R: Rng + ?Sized>(rng: &mut R) -> Self {
        let child = rng.random_bool(0.1);
        let mut b = Self::sample(rng);
        let height = if child { rng.random_range(1.0..1.45) } else { rng.random_range(1.45..2.0) };
        // Widths scale with height; a child is slimmer for their size.
        let k = height / b.height * if child { 0.92 } else { 1.0 };
        b.shoulder *= k;
        b.hip *= k;
        b.depth *= k.max(0.8);
        b.leg_r *= k.max(0.75);
        b.arm_r *= k.max(0.75);
        b.height = height;
        b.coat = rng.random_bool(0.3);
        b.backpack = rng.random_bool(0.3);
        b
    }

    /// The body parts in the body frame for an activity at gait phase `phase` (radians).
    pub fn parts(&self, activity: Activity, phase: f64) -> Vec<Shape> {
        let h = self.height;
        let mut out = Vec::with_capacity(12);
        let cap = |a: V3, b: V3, r: f64| Shape::Capsule { a, b, r };
        let (hip_z, torso_x, lean) = match activity {
            Activity::Sitting { seat } => (seat + self.leg_r, -0.02, -0.08),
            _ => (0.52 * h, 0.0, 0.04),
        };
        let shoulder_z = hip_z + 0.30 * h;
        // Legs and feet.
        match activity {
            Activity::Sitting { seat } => {
                for side in [-1.0, 1.0] {
                    let y = side * self.hip;
                    let knee = [0.42 * h * 0.55 + 0.05, y * 1.1, seat + self.leg_r];
                    out.push(cap([0.0, y, hip_z], knee, self.leg_r));
                    out.push(cap(knee, [knee[0] + 0.04, y * 1.1, self.leg_r * 0.8], self.leg_r * 0.85));
                    out.push(cap([knee[0], y * 1.1, 0.04], [knee[0] + 0.2, y * 1.1, 0.04], 0.04));
                }
            }
            _ => {
                let amp = match activity {
                    Activity::Walking { speed } => 0.22 + 0.12 * speed,
                    _ => 0.0,
                };
                let leg = hip_z - 0.05;
                for (side, sign) in [(-1.0, 1.0), (1.0, -1.0)] {
                    let a = sign * amp * phase.sin();
                    let y = side * self.hip * if amp == 0.0 { 1.15 } else { 1.0 };
                    // The leg swinging forward bends its knee and lifts its foot; the other stands.
                    let swing = if amp > 0.0 { (sign * phase.cos()).max(0.0) } else { 0.0 };
                    let foot = [leg * a.sin(), y, 0.08 + 0.06 * swing];
                    let knee = [0.5 * leg * (a + 0.3 * swing).sin(), y, hip_z - 0.5 * leg * a.cos()];
                    out.push(cap([0.0, y, hip_z], knee, self.leg_r));
                    out.push(cap(knee, foot, self.leg_r * 0.8));
                    let fz = foot[2] - 0.04;
                    out.push(cap([foot[0] - 0.04, y, fz], [foot[0] + 0.16, y, fz], 0.04));
                }
            }
        }
        // Torso (pelvis to shoulders), leaning a little forward, or back when seated.
        let mid_z = (hip_z + shoulder_z) / 2.0;
        let half_z = (shoulder_z - hip_z) / 2.0 + 0.06;
        out.push(Shape::Ellipsoid { c: [torso_x + lean * half_z, 0.0, mid_z], radii: [self.depth, self.shoulder * 0.88, half_z], yaw: 0.0 });
        if self.coat && !matches!(activity, Activity::Sitting { .. }) {
            out.push(Shape::Ellipsoid { c: [0.0, 0.0, hip_z - 0.12], radii: [self.depth * 1.25, self.hip * 1.6, 0.3], yaw: 0.0 });
        }
        if self.backpack {
            out.push(Shape::Cuboid { c: [torso_x - self.depth - 0.08, 0.0, shoulder_z - 0.22], half: [0.08, 0.15, 0.2], yaw: 0.0 });
        }
        // Arms.
        let arm = 0.36 * h;
        let swing = match activity {
            Activity::Walking { speed } => 0.25 * speed * phase.sin(),
            _ => 0.0,
        };
        for (side, sign) in [(-1.0, -1.0), (1.0, 1.0)] {
            let s = [torso_x + lean * half_z * 1.5, side * self.shoulder, shoulder_z - 0.04];
            let posture = match (activity, self.arms) {
                (Activity::Sitting { .. }, _) => Arms::Folded,
                (_, a) => a,
            };
            match posture {
                Arms::Hanging => {
                    let a = sign * swing;
                    let hand = [s[0] + arm * a.sin(), s[1] + side * 0.05, s[2] - arm * a.cos()];
                    out.push(cap(s, hand, self.arm_r));
                }
                Arms::Holding if side > 0.0 => {
                    let elbow = [s[0] + 0.02, s[1] + side * 0.03, s[2] - 0.5 * arm];
                    out.push(cap(s, elbow, self.arm_r));
                    out.push(cap(elbow, [elbow[0] + 0.25, s[1] * 0.5, elbow[2] + 0.12], self.arm_r * 0.9));
                }
                Arms::Holding => {
                    out.push(cap(s, [s[0], s[1] + side * 0.05, s[2] - arm], self.arm_r));
                }
                Arms::Folded => {
                    let elbow = [s[0] + 0.03, s[1] + side * 0.04, s[2] - 0.48 * arm];
                    out.push(cap(s, elbow, self.arm_r));
                    out.push(cap(elbow, [s[0] + self.depth + 0.06, -side * 0.08, elbow[2] + 0.08], self.arm_r * 0.9));
                }
            }
        }
        // Neck and head.
        let neck_top = shoulder_z + 0.06;
        out.push(cap([torso_x, 0.0, shoulder_z - 0.02], [torso_x + 0.01, 0.0, neck_top], 0.055));
        out.push(Shape::Ellipsoid { c: [torso_x + 0.02, 0.0, neck_top + self.head[2] * 0.85], radii: self.head, yaw: 0.0 });
        out
    }
}

/// Places body-frame parts in the world: heading `yaw`, floor point `(x, y, floor)`.
pub fn place(parts: &[Shape], x: f64, y: f64, floor: f64, yaw: f64) -> Vec<Shape> {
    parts.iter().map(|s| s.placed(x, y, floor, yaw)).collect()
}

/// The tight box of body-frame parts, in the world (l along the heading `yaw`).
pub fn tight_box(parts: &[Shape], x: f64, y: f64, floor: f64, yaw: f64) -> Box3d {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    let mut grow = |p: V3, r: V3| {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k] - r[k]);
            hi[k] = hi[k].max(p[k] + r[k]);
        }
    };
    for s in parts {
        match *s {
            Shape::Capsule { a, b, r } => {
                grow(a, [r; 3]);
                grow(b, [r; 3]);
            }
            // Parts are built axis-aligned in the body frame (their own yaw is 0 there).
            Shape::Ellipsoid { c, radii, .. } | Shape::Foliage { c, radii, .. } => grow(c, radii),
            Shape::Cuboid { c, half, .. } => grow(c, half),
            Shape::Cylinder { c, r, z0, z1 } => {
                grow([c[0], c[1], z0], [r, r, 0.0]);
                grow([c[0], c[1], z1], [r, r, 0.0]);
            }
            Shape::PlaneZ(_) => {}
        }
    }
    lo[2] = lo[2].max(0.0);
    let centre = rot([(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, 0.0], yaw);
    Box3d {
        cx: x + centre[0],
        cy: y + centre[1],
        cz: floor + (lo[2] + hi[2]) / 2.0,
        l: hi[0] - lo[0],
        w: hi[1] - lo[1],
        h: hi[2] - lo[2],
        rot_z: yaw,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn boxes_are_person_sized_and_hold_the_parts() {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for i in 0..40 {
            let b = Body::sample(&mut r);
            let act = match i % 3 {
                0 => Activity::Standing,
                1 => Activity::Walking { speed: 1.3 },
                _ => Activity::Sitting { seat: 0.45 },
            };
            let parts = b.parts(act, i as f64);
            let bx = tight_box(&parts, 3.0, -2.0, -0.7, 1.0);
            assert!(bx.l > 0.15 && bx.l < 1.2 && bx.w > 0.3 && bx.w < 1.0, "{act:?} {bx:?}");
            match act {
                Activity::Sitting { .. } => assert!(bx.h > 1.0 && bx.h < 1.5 && bx.l > bx.w * 0.9),
                _ => assert!((bx.h - b.height).abs() < 0.12, "{} vs {}", bx.h, b.height),
            }
            assert!((bx.cz - bx.h / 2.0 + 0.7).abs() < 1e-9);
        }
    }
}
