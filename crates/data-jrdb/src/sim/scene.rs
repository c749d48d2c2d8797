//! Scenes like JRDB's: corridors, halls and plazas with walls, pillars, furniture and person-sized
//! clutter, a moving robot, and people who move coherently from frame to frame.

use rand::Rng;

use super::geometry::{Shape, rot};
use super::objects::placed;
use super::people::{Activity, Body, place, tight_box};
use crate::box3d::Box3d;

/// The kind of place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SceneKind {
    /// A long indoor corridor with a ceiling, doors and benches.
    Corridor,
    /// An indoor hall (cafe, lab, auditorium, poster session) with furniture and pillars.
    Hall,
    /// An outdoor plaza between buildings, with trees, poles, benches and bins.
    Plaza,
    /// A street: a road with kerbs, sidewalks, parked and passing vehicles, posts, trees and
    /// facades or fences (`bench-v2`).
    Street,
    /// A campus: paved squares, raised lawns, stairs to terraces, railings, bicycle racks,
    /// a service road (`bench-v2`).
    Campus,
}

impl SceneKind {
    /// The kind a JRDB sequence name suggests.
    pub fn for_sequence(name: &str) -> Self {
        const CORRIDORS: [&str; 3] = ["basement", "elevators", "corridor"];
        const HALLS: [&str; 10] = ["cafe", "auditorium", "aud", "lab", "meeting", "poster", "stlc", "huang-2", "gates-159", "hall"];
        if name.contains("street") {
            SceneKind::Street
        } else if name.contains("campus") {
            SceneKind::Campus
        } else if CORRIDORS.iter().any(|k| name.contains(k)) {
            SceneKind::Corridor
        } else if HALLS.iter().any(|k| name.contains(k)) {
            SceneKind::Hall
        } else {
            SceneKind::Plaza
        }
    }
}

/// A surface of the scene and whose it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prim {
    /// Its geometry.
    pub shape: Shape,
    /// Fraction of the beam sent back (drives intensity and dropouts).
    pub reflectivity: f32,
}

#[derive(Debug, Clone)]
pub(super) struct Person {
    pub(super) body: Body,
    pub(super) activity: Activity,
    pub(super) x: f64,
    pub(super) y: f64,
    pub(super) yaw: f64,
    phase: f64,
    /// Where a walker is heading; followers of a group copy their leader with an offset.
    pub(super) goal: [f64; 2],
    pub(super) follow: Option<(usize, [f64; 2])>,
    /// What they carry or push (an umbrella, a pushchair, a bicycle), in their body frame: seen
    /// by the sensor, outside their labelled box.
    pub(super) extras: Vec<(Shape, f32)>,
}

/// A vehicle driving along its heading.
#[derive(Debug, Clone)]
pub(super) struct Mover {
    /// Its body in its own frame.
    pub(super) parts: Vec<(Shape, f32)>,
    /// Position, heading and speed (m/s).
    pub(super) pose: [f64; 4],
}

/// A scene that evolves over the frames of one sequence.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The layout it was built as.
    pub kind: SceneKind,
    /// Floor height in the world (= base) frame: the robot base is this far above the floor.
    pub floor: f64,
    /// Static surfaces (floor, ceiling, walls, furniture, clutter).
    pub statics: Vec<Prim>,
    /// Walkable area (xmin, xmax, ymin, ymax) for people and the robot.
    pub area: [f64; 4],
    pub(super) people: Vec<Person>,
    /// Robot pose in the world (x, y, yaw) and speed.
    pub robot: [f64; 3],
    pub(super) robot_speed: f64,
    /// Footprints (x, y, radius) of obstacles people avoid.
    pub(super) obstacles: Vec<[f64; 3]>,
    /// Ground raised above the floor (sidewalks, lawns, terraces): x0, x1, y0, y1 and its top.
    pub(super) raised: Vec<[f64; 5]>,
    /// Passing vehicles.
    pub(super) movers: Vec<Mover>,
    /// People are drawn from the varied crowd of `bench-v2` (`Body::sample_crowd`, things carried).
    pub(super) crowd: bool,
    /// People are placed at least this far from the sensor's platform (m).
    pub(super) keep_clear: f64,
}

/// A labelled person in one frame: world-frame box and stable id.
#[derive(Debug, Clone, PartialEq)]
pub struct PersonView {
    /// The person's id, stable over the sequence.
    pub id: usize,
    /// The labelled box in the world frame.
    pub bbox: Box3d,
}

fn cuboid(x: f64, y: f64, z0: f64, sx: f64, sy: f64, sz: f64, yaw: f64) -> Shape {
    Shape::Cuboid { c: [x, y, z0 + sz / 2.0], half: [sx / 2.0, sy / 2.0, sz / 2.0], yaw }
}

impl Scene {
    /// Builds a scene of `kind` with up to `max_people` people.
    pub fn generate<R: Rng + ?Sized>(kind: SceneKind, max_people: usize, rng: &mut R) -> Self {
        let floor = -rng.random_range(0.68..0.74);
        let mut s = Scene::empty(kind, floor);
        s.add(Shape::PlaneZ(floor), 0.25);
        match kind {
            SceneKind::Corridor => s.corridor(rng),
            SceneKind::Hall => s.hall(rng),
            SceneKind::Plaza => s.plaza(rng),
            SceneKind::Street => s.street(false, rng),
            SceneKind::Campus => s.campus(false, rng),
        }
        s.robot_speed = if rng.random_bool(0.4) { 0.0 } else { rng.random_range(0.2..0.8) };
        s.robot[2] = rng.random_range(-0.3..0.3);
        let n = match kind {
            SceneKind::Corridor => rng.random_range(0..=max_people.min(14)),
            _ => rng.random_range(max_people / 8..=max_people),
        };
        s.populate(n, rng);
        s
    }

    pub(super) fn empty(kind: SceneKind, floor: f64) -> Self {
        Scene {
            kind,
            floor,
            statics: Vec::new(),
            area: [0.0; 4],
            people: Vec::new(),
            robot: [0.0; 3],
            robot_speed: 0.0,
            obstacles: Vec::new(),
            raised: Vec::new(),
            movers: Vec::new(),
            crowd: false,
            keep_clear: 0.0,
        }
    }

    /// The ground's height at (x, y): the floor, or the top of the raised ground there.
    pub fn ground_at(&self, x: f64, y: f64) -> f64 {
        self.raised.iter().filter(|r| x >= r[0] && x <= r[1] && y >= r[2] && y <= r[3]).map(|r| r[4]).fold(self.floor, f64::max)
    }

    pub(super) fn add(&mut self, shape: Shape, reflectivity: f32) {
        self.statics.push(Prim { shape, reflectivity });
    }

    pub(super) fn obstacle(&mut self, shape: Shape, reflectivity: f32) {
        if let Some((c, r)) = shape.bounds_xy() {
            self.obstacles.push([c[0], c[1], r]);
        }
        self.add(shape, reflectivity);
    }

    /// Person-sized things that are not people: bins, poles, plants, signs, bollards.
    pub(super) fn clutter<R: Rng + ?Sized>(&mut self, x: f64, y: f64, rng: &mut R) {
        let f = self.floor;
        match rng.random_range(0..6) {
            0 => self.obstacle(Shape::Cylinder { c: [x, y], r: rng.random_range(0.18..0.3), z0: f, z1: f + rng.random_range(0.7..1.1) }, 0.4),
            1 => self.obstacle(Shape::Cylinder { c: [x, y], r: rng.random_range(0.03..0.08), z0: f, z1: f + rng.random_range(2.2..4.5) }, 0.5),
            2 => {
                let pot = rng.random_range(0.3..0.6);
                self.obstacle(Shape::Cylinder { c: [x, y], r: rng.random_range(0.15..0.25), z0: f, z1: f + pot }, 0.3);
                let rz = rng.random_range(0.3..0.6);
                let rr = rng.random_range(0.25..0.45);
                self.add(Shape::Ellipsoid { c: [x, y, f + pot + rz], radii: [rr, rr * 0.9, rz], yaw: rng.random_range(0.0..3.0) }, 0.2);
            }
            3 => {
                let yaw = rng.random_range(0.0..std::f64::consts::PI);
                self.obstacle(Shape::Cylinder { c: [x, y], r: 0.03, z0: f, z1: f + 1.2 }, 0.5);
                self.add(cuboid(x, y, f + 1.2, 0.05, 0.6, 0.8, yaw), 0.7);
            }
            4 => self.obstacle(Shape::Cylinder { c: [x, y], r: rng.random_range(0.08..0.15), z0: f, z1: f + rng.random_range(0.8..1.0) }, 0.6),
            _ => {
                // A coat stand / mannequin-like column with a round top.
                self.obstacle(Shape::Cylinder { c: [x, y], r: 0.04, z0: f, z1: f + 1.7 }, 0.4);
                self.add(Shape::Ellipsoid { c: [x, y, f + 1.55], radii: [0.25, 0.25, 0.2], yaw: 0.0 }, 0.2);
            }
        }
    }

    pub(super) fn table<R: Rng + ?Sized>(&mut self, x: f64, y: f64, yaw: f64, rng: &mut R) {
        let f = self.floor;
        let (sx, sy) = (rng.random_range(0.7..1.8), rng.random_range(0.6..0.9));
        let top = rng.random_range(0.72..0.76);
        self.obstacle(cuboid(x, y, f + top - 0.04, sx, sy, 0.04, yaw), 0.5);
        for (u, v) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
            let p = rot([u * (sx / 2.0 - 0.05), v * (sy / 2.0 - 0.05), 0.0], yaw);
            self.add(Shape::Cylinder { c: [x + p[0], y + p[1]], r: 0.025, z0: f, z1: f + top - 0.04 }, 0.5);
        }
    }

    pub(super) fn chair(&mut self, x: f64, y: f64, yaw: f64, seat: f64) {
        let f = self.floor;
        self.obstacle(cuboid(x, y, f + seat - 0.05, 0.45, 0.45, 0.05, yaw), 0.4);
        let b = rot([-0.22, 0.0, 0.0], yaw);
        self.add(cuboid(x + b[0], y + b[1], f + seat, 0.04, 0.42, 0.45, yaw), 0.4);
        for (u, v) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
            let p = rot([u * 0.19, v * 0.19, 0.0], yaw);
            self.add(Shape::Cylinder { c: [x + p[0], y + p[1]], r: 0.015, z0: f, z1: f + seat - 0.05 }, 0.5);
        }
    }

    /// A wall along x (`along_x`) or y from `a` to `b` at the other coordinate `at`, with door gaps.
    #[allow(clippy::too_many_arguments)] // one wall: its line, extent, height and doors
    pub(super) fn wall<R: Rng + ?Sized>(&mut self, along_x: bool, at: f64, a: f64, b: f64, height: f64, gaps: usize, rng: &mut R) {
        let mut cuts: Vec<(f64, f64)> = (0..gaps)
            .map(|_| {
                let c = rng.random_range(a + 2.0..b - 2.0);
                (c - 0.6, c + 0.6)
            })
            .collect();
        cuts.sort_by(|p, q| p.0.total_cmp(&q.0));
        let mut cur = a;
        let f = self.floor;
        let refl = rng.random_range(0.3..0.8);
        for (g0, g1) in cuts.into_iter().chain([(b, b)]) {
            if g0 - cur > 0.05 {
                let (len, mid) = (g0 - cur, (g0 + cur) / 2.0);
                let s = if along_x { cuboid(mid, at, f, len, 0.2, height, 0.0) } else { cuboid(at, mid, f, 0.2, len, height, 0.0) };
                self.add(s, refl);
            }
            cur = cur.max(g1);
        }
    }

    pub(super) fn corridor<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let w = rng.random_range(2.4..5.0);
        let (x0, x1) = (-rng.random_range(10.0..40.0), rng.random_range(20.0..60.0));
        let ceil = self.floor + rng.random_range(2.6..3.3);
        self.add(Shape::PlaneZ(ceil), 0.5);
        let hgt = ceil - self.floor;
        let doors = ((x1 - x0) / 8.0) as usize;
        self.wall(true, w / 2.0, x0, x1, hgt, doors, rng);
        self.wall(true, -w / 2.0, x0, x1, hgt, doors, rng);
        // Rooms behind the doors: back walls a few metres away.
        self.wall(true, w / 2.0 + 4.0, x0, x1, hgt, 0, rng);
        self.wall(true, -w / 2.0 - 4.0, x0, x1, hgt, 0, rng);
        self.wall(false, x0, -w / 2.0 - 4.0, w / 2.0 + 4.0, hgt, 0, rng);
        self.wall(false, x1, -w / 2.0 - 4.0, w / 2.0 + 4.0, hgt, 0, rng);
        for _ in 0..rng.random_range(3..10) {
            let x = rng.random_range(x0 + 1.0..x1 - 1.0);
            let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let y = side * (w / 2.0 - 0.35);
            if rng.random_bool(0.3) {
                self.obstacle(cuboid(x, y, self.floor, 1.6, 0.45, 0.45, 0.0), 0.4);
            } else {
                self.clutter(x, y, rng);
            }
        }
        if w > 3.5 {
            for k in 0..rng.random_range(0..4) {
                let x = x0 + (k as f64 + 0.5) * (x1 - x0) / 4.0;
                self.obstacle(cuboid(x, 0.0, self.floor, 0.5, 0.5, hgt, 0.0), 0.5);
            }
        }
        self.area = [x0 + 0.5, x1 - 0.5, -w / 2.0 + 0.4, w / 2.0 - 0.4];
        self.robot[1] = rng.random_range(-0.2..0.2);
    }

    pub(super) fn hall<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let (lx, ly) = (rng.random_range(15.0..35.0), rng.random_range(12.0..30.0));
        let (x0, y0) = (-rng.random_range(0.3..0.7) * lx, -rng.random_range(0.3..0.7) * ly);
        let (x1, y1) = (x0 + lx, y0 + ly);
        let hgt = rng.random_range(3.0..8.0);
        self.add(Shape::PlaneZ(self.floor + hgt), 0.5);
        for (ax, at, a, b) in [(true, y0, x0, x1), (true, y1, x0, x1), (false, x0, y0, y1), (false, x1, y0, y1)] {
            let gaps = rng.random_range(0..3);
            self.wall(ax, at, a, b, hgt, gaps, rng);
            // Whatever lies beyond a door: a wall 5 m further.
            let off = if at < 0.0 { -5.0 } else { 5.0 };
            self.wall(ax, at + off, a - 5.0, b + 5.0, hgt, 0, rng);
        }
        // Pillars on a grid.
        if rng.random_bool(0.6) {
            let step = rng.random_range(5.0..9.0);
            let round = rng.random_bool(0.5);
            let mut x = x0 + step;
            while x < x1 - 1.0 {
                let mut y = y0 + step;
                while y < y1 - 1.0 {
                    if x.hypot(y) > 1.5 {
                        let s = if round { Shape::Cylinder { c: [x, y], r: 0.3, z0: self.floor, z1: self.floor + hgt } } else { cuboid(x, y, self.floor, 0.6, 0.6, hgt, 0.0) };
                        self.obstacle(s, 0.5);
                    }
                    y += step;
                }
                x += step;
            }
        }
        let poster = rng.random_bool(0.3);
        for _ in 0..rng.random_range(6..20) {
            let (x, y) = (rng.random_range(x0 + 1.0..x1 - 1.0), rng.random_range(y0 + 1.0..y1 - 1.0));
            if x.hypot(y) < 2.0 {
                continue;
            }
            let yaw = if rng.random_bool(0.7) { 0.0 } else { rng.random_range(0.0..std::f64::consts::PI) };
            match rng.random_range(0..6) {
                _ if poster => self.obstacle(cuboid(x, y, self.floor, 1.2, 0.05, rng.random_range(1.8..2.2), yaw), 0.7),
                0 | 1 => {
                    self.table(x, y, yaw, rng);
                    for k in 0..rng.random_range(0..4) {
                        let p = rot([0.0, if k % 2 == 0 { 0.7 } else { -0.7 }, 0.0], yaw);
                        self.chair(x + p[0] + 0.3 * (k / 2) as f64, y + p[1], yaw + if k % 2 == 0 { -1.57 } else { 1.57 }, 0.45);
                    }
                }
                2 => self.obstacle(cuboid(x, y, self.floor, rng.random_range(1.5..4.0), 0.7, rng.random_range(0.9..1.1), yaw), 0.4),
                3 => self.obstacle(cuboid(x, y, self.floor, rng.random_range(0.8..2.0), 0.4, rng.random_range(1.6..2.2), yaw), 0.5),
                _ => self.clutter(x, y, rng),
            }
        }
        self.area = [x0 + 0.5, x1 - 0.5, y0 + 0.5, y1 - 0.5];
    }

    pub(super) fn plaza<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let (lx, ly) = (rng.random_range(40.0..90.0), rng.random_range(30.0..70.0));
        let (x0, y0) = (-rng.random_range(0.25..0.6) * lx, -rng.random_range(0.3..0.7) * ly);
        let (x1, y1) = (x0 + lx, y0 + ly);
        // Building facades, broken into blocks of different heights with streets between them.
        for (ax, at, a, b) in [(true, y0, x0, x1), (true, y1, x0, x1), (false, x0, y0, y1), (false, x1, y0, y1)] {
            let mut c = a;
            while c < b {
                let len = rng.random_range(8.0..30.0f64).min(b - c);
                let hgt = rng.random_range(6.0..20.0);
                let depth = 10.0;
                let mid = c + len / 2.0;
                let off = if at < 0.0 { -depth / 2.0 } else { depth / 2.0 };
                let s = if ax { cuboid(mid, at + off, self.floor, len, depth, hgt, 0.0) } else { cuboid(at + off, mid, self.floor, depth, len, hgt, 0.0) };
                self.add(s, rng.random_range(0.2..0.7));
                c += len + if rng.random_bool(0.3) { rng.random_range(4.0..12.0) } else { 0.0 };
            }
        }
        let (ax0, ax1, ay0, ay1) = (x0 + 1.0, x1 - 1.0, y0 + 1.0, y1 - 1.0);
        for _ in 0..rng.random_range(8..30) {
            let (x, y) = (rng.random_range(ax0..ax1), rng.random_range(ay0..ay1));
            if x.hypot(y) < 2.5 {
                continue;
            }
            match rng.random_range(0..7) {
                0 | 1 => {
                    // Tree: trunk and crown.
                    let trunk = rng.random_range(2.0..3.5);
                    self.obstacle(Shape::Cylinder { c: [x, y], r: rng.random_range(0.12..0.25), z0: self.floor, z1: self.floor + trunk }, 0.3);
                    let r = rng.random_range(1.2..2.8);
                    self.add(Shape::Ellipsoid { c: [x, y, self.floor + trunk + r * 0.8], radii: [r, r, r * 0.9], yaw: 0.0 }, 0.15);
                }
                2 => self.obstacle(Shape::Cylinder { c: [x, y], r: 0.08, z0: self.floor, z1: self.floor + rng.random_range(4.0..7.0) }, 0.6),
                3 => self.obstacle(cuboid(x, y, self.floor, 1.8, 0.5, 0.45, rng.random_range(0.0..std::f64::consts::PI)), 0.4),
                4 => self.obstacle(cuboid(x, y, self.floor, rng.random_range(2.0..6.0), rng.random_range(1.0..3.0), rng.random_range(0.4..0.8), 0.0), 0.3),
                _ => self.clutter(x, y, rng),
            }
        }
        self.area = [ax0, ax1, ay0, ay1];
    }

    pub(super) fn free<R: Rng + ?Sized>(&self, rng: &mut R, margin: f64) -> Option<[f64; 2]> {
        let [x0, x1, y0, y1] = self.area;
        for _ in 0..200 {
            // Most people within 25 m of the robot, as in JRDB's labels.
            let r = rng.random_range(1.2..30.0f64).min(rng.random_range(1.2..35.0));
            let a = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            let (x, y) = (self.robot[0] + r * a.cos(), self.robot[1] + r * a.sin());
            if x < x0 || x > x1 || y < y0 || y > y1 {
                continue;
            }
            if self.obstacles.iter().any(|o| (o[0] - x).hypot(o[1] - y) < o[2] + margin) {
                continue;
            }
            if self.people.iter().any(|p| (p.x - x).hypot(p.y - y) < 0.5 + margin) {
                continue;
            }
            if self.keep_clear > 0.0 && (self.robot[0] - x).hypot(self.robot[1] - y) < self.keep_clear {
                continue;
            }
            return Some([x, y]);
        }
        None
    }

    pub(super) fn populate<R: Rng + ?Sized>(&mut self, n: usize, rng: &mut R) {
        while self.people.len() < n {
            let Some([x, y]) = self.free(rng, 0.4) else { break };
            let roll = rng.random_range(0..10);
            let yaw = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            let group = if n - self.people.len() >= 2 && rng.random_bool(0.35) { rng.random_range(2..=4.min(n - self.people.len())) } else { 1 };
            if roll < 5 {
                let speed = rng.random_range(0.7..1.6);
                let goal = self.free(rng, 0.3).unwrap_or([x, y]);
                let lead = self.people.len();
                for k in 0..group {
                    let off = [-(k as f64 / 2.0).floor() * 0.8, if k % 2 == 0 { 0.0 } else { 0.65 }];
                    let follow = (k > 0).then_some((lead, off));
                    let o = rot([off[0], off[1], 0.0], yaw);
                    let body = self.body(rng);
                    let extras = if follow.is_none() { self.carried(&body, rng) } else { Vec::new() };
                    self.people.push(Person { body, activity: Activity::Walking { speed }, x: x + o[0], y: y + o[1], yaw, phase: rng.random_range(0.0..std::f64::consts::TAU), goal, follow, extras });
                }
            } else if roll < 8 || self.kind == SceneKind::Corridor {
                // A standing group faces its centre.
                let rad = if group == 1 { 0.0 } else { rng.random_range(0.45..0.8) };
                for k in 0..group {
                    let a = yaw + k as f64 * std::f64::consts::TAU / group as f64;
                    let (px, py) = (x + rad * a.cos(), y + rad * a.sin());
                    let face = if group == 1 { yaw } else { a + std::f64::consts::PI + rng.random_range(-0.3..0.3) };
                    let body = self.body(rng);
                    self.people.push(Person { body, activity: Activity::Standing, x: px, y: py, yaw: face, phase: 0.0, goal: [px, py], follow: None, extras: Vec::new() });
                }
            } else {
                let seat = rng.random_range(0.42..0.5);
                self.chair(x - 0.05 * yaw.cos(), y - 0.05 * yaw.sin(), yaw, seat);
                let body = self.body(rng);
                self.people.push(Person { body, activity: Activity::Sitting { seat }, x, y, yaw, phase: 0.0, goal: [x, y], follow: None, extras: Vec::new() });
            }
        }
    }

    /// Advances people and robot by `dt` seconds.
    pub fn step<R: Rng + ?Sized>(&mut self, dt: f64, rng: &mut R) {
        let [x0, x1, y0, y1] = self.area;
        for i in 0..self.people.len() {
            if let Some((lead, off)) = self.people[i].follow {
                let (lx, ly, lyaw, act) = (self.people[lead].x, self.people[lead].y, self.people[lead].yaw, self.people[lead].activity);
                let o = rot([off[0], off[1], 0.0], lyaw);
                let p = &mut self.people[i];
                p.x = lx + o[0];
                p.y = ly + o[1];
                p.yaw = lyaw;
                if let Activity::Walking { speed } = act {
                    p.phase += dt * speed * std::f64::consts::TAU / (0.75 * p.body.height);
                }
                continue;
            }
            let Activity::Walking { speed } = self.people[i].activity else {
                // Standing people shift a little.
                self.people[i].yaw += rng.random_range(-0.02..0.02);
                continue;
            };
            let p = &self.people[i];
            let (dx, dy) = (p.goal[0] - p.x, p.goal[1] - p.y);
            if dx.hypot(dy) < 1.0 {
                let g = self.free(rng, 0.3).unwrap_or([p.x, p.y]);
                self.people[i].goal = g;
                continue;
            }
            let want = dy.atan2(dx);
            let mut turn = (want - p.yaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
            // Steer around obstacles just ahead.
            let ahead = [p.x + 1.0 * p.yaw.cos(), p.y + 1.0 * p.yaw.sin()];
            if self.obstacles.iter().any(|o| (o[0] - ahead[0]).hypot(o[1] - ahead[1]) < o[2] + 0.4) {
                turn = 1.5;
            }
            let p = &mut self.people[i];
            p.yaw += turn.clamp(-1.2 * dt, 1.2 * dt);
            p.x = (p.x + speed * dt * p.yaw.cos()).clamp(x0, x1);
            p.y = (p.y + speed * dt * p.yaw.sin()).clamp(y0, y1);
            p.phase += dt * speed * std::f64::consts::TAU / (0.75 * p.body.height);
        }
        for m in &mut self.movers {
            let [x, y, yaw, v] = m.pose;
            m.pose = [x + v * dt * yaw.cos(), y + v * dt * yaw.sin(), yaw, v];
        }
        // The robot drives forward, turning back toward the middle near the area's edge.
        let [rx, ry, ryaw] = self.robot;
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        let near = rx < x0 + 4.0 || rx > x1 - 4.0 || ry < y0 + 1.0 || ry > y1 - 1.0;
        let mut yaw = ryaw + rng.random_range(-0.05..0.05) * dt;
        if near {
            let want = (cy - ry).atan2(cx - rx);
            let d = (want - yaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
            yaw += d.clamp(-0.8 * dt, 0.8 * dt);
        }
        self.robot = [rx + self.robot_speed * dt * yaw.cos(), ry + self.robot_speed * dt * yaw.sin(), yaw];
    }

    /// Every person's surfaces (world frame) and labelled box (world frame) now.
    pub fn people_now(&self) -> (Vec<Prim>, Vec<PersonView>) {
        let mut prims = Vec::new();
        let mut views = Vec::new();
        for (id, p) in self.people.iter().enumerate() {
            let parts = p.body.parts(p.activity, p.phase);
            let refl = 0.15 + 0.5 * ((id * 7919) % 100) as f32 / 100.0;
            let ground = self.ground_at(p.x, p.y);
            prims.extend(place(&parts, p.x, p.y, ground, p.yaw).into_iter().map(|shape| Prim { shape, reflectivity: refl }));
            for (shape, reflectivity) in placed(p.extras.clone(), p.x, p.y, ground, p.yaw) {
                prims.push(Prim { shape, reflectivity });
            }
            views.push(PersonView { id, bbox: tight_box(&parts, p.x, p.y, ground, p.yaw) });
        }
        (prims, views)
    }

    /// The passing vehicles' surfaces now (world frame).
    pub fn movers_now(&self) -> Vec<Prim> {
        let mut prims = Vec::new();
        for m in &self.movers {
            let [x, y, yaw, _] = m.pose;
            prims.extend(placed(m.parts.clone(), x, y, self.floor, yaw).into_iter().map(|(shape, reflectivity)| Prim { shape, reflectivity }));
        }
        prims
    }

    /// World frame → the robot's base frame at its current pose.
    pub fn to_base(&self, p: [f64; 3]) -> [f64; 3] {
        let q = rot([p[0] - self.robot[0], p[1] - self.robot[1], p[2]], -self.robot[2]);
        [q[0], q[1], q[2]]
    }

    /// Base frame → world frame.
    pub fn to_world(&self, p: [f64; 3]) -> [f64; 3] {
        let q = rot(p, self.robot[2]);
        [q[0] + self.robot[0], q[1] + self.robot[1], q[2]]
    }

    /// A world-frame box in the base frame.
    pub fn box_to_base(&self, b: &Box3d) -> Box3d {
        let c = self.to_base([b.cx, b.cy, b.cz]);
        Box3d { cx: c[0], cy: c[1], cz: c[2], rot_z: b.rot_z - self.robot[2], ..*b }
    }
}
