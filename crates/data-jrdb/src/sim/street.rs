//! `bench-v2`'s places: streets and campuses built here, JRDB's corridors, halls and plazas
//! furnished with the clutter of `objects`, and crowds of every age carrying things.

use rand::Rng;

use super::geometry::{Shape, rot};
use super::objects::{Fixture, Vehicle, bicycle, cuboid, fence, placed, stroller};
use super::people::Body;
use super::scene::{Mover, Scene, SceneKind};

impl Scene {
    /// A `bench-v2` scene of `kind` with up to `max_people` people, the floor at `floor`; the
    /// sensor's platform drives on the road when `on_road` (a car) and keeps people
    /// `keep_clear` metres away.
    pub fn generate_v2<R: Rng + ?Sized>(kind: SceneKind, max_people: usize, floor: f64, on_road: bool, keep_clear: f64, rng: &mut R) -> Self {
        let mut s = Scene::empty(kind, floor);
        s.crowd = true;
        s.add(Shape::PlaneZ(floor), rng.random_range(0.1..0.4));
        match kind {
            SceneKind::Corridor => s.corridor(rng),
            SceneKind::Hall => s.hall(rng),
            SceneKind::Plaza => s.plaza(rng),
            SceneKind::Street => s.street(on_road, rng),
            SceneKind::Campus => s.campus(on_road, rng),
        }
        let fixtures = match kind {
            SceneKind::Corridor => rng.random_range(2..8),
            SceneKind::Hall => rng.random_range(5..20),
            _ => rng.random_range(10..40),
        };
        s.furnish(fixtures, rng);
        s.robot_speed = match (on_road, rng.random_bool(0.35)) {
            (_, true) => 0.0,
            (true, false) => rng.random_range(1.0..8.0),
            (false, false) => rng.random_range(0.2..1.2),
        };
        if !on_road {
            s.robot[2] = rng.random_range(-0.3..0.3);
        }
        s.keep_clear = keep_clear;
        let n = match kind {
            SceneKind::Corridor => rng.random_range(0..=max_people.min(14)),
            _ => rng.random_range(max_people / 10..=max_people),
        };
        s.populate(n, rng);
        if kind == SceneKind::Street {
            s.onto_sidewalks(rng);
        }
        s
    }

    /// Objects other than people within `range` of the sensor (footprints; a parked vehicle is
    /// two) and passing vehicles within it.
    pub fn clutter_within(&self, range: f64) -> (usize, usize) {
        let near = |x: f64, y: f64| (x - self.robot[0]).hypot(y - self.robot[1]) <= range;
        (self.obstacles.iter().filter(|o| near(o[0], o[1])).count(), self.movers.iter().filter(|m| near(m.pose[0], m.pose[1])).count())
    }

    /// A body: bench-v1's adults, or with `crowd` children to tall adults.
    pub(super) fn body<R: Rng + ?Sized>(&self, rng: &mut R) -> Body {
        if self.crowd { Body::sample_crowd(rng) } else { Body::sample(rng) }
    }

    /// What a walker of the crowd carries or pushes, in their body frame (nothing outside `crowd`).
    pub(super) fn carried<R: Rng + ?Sized>(&self, body: &Body, rng: &mut R) -> Vec<(Shape, f32)> {
        if !self.crowd {
            return Vec::new();
        }
        match rng.random_range(0..20) {
            // An open umbrella over the head.
            0 => {
                let z = body.height + 0.2;
                vec![
                    (Shape::Capsule { a: [0.15, 0.15, 0.9 * body.height * 0.55], b: [0.1, 0.1, z], r: 0.012 }, 0.3),
                    (Shape::Ellipsoid { c: [0.1, 0.1, z], radii: [0.5, 0.5, 0.12], yaw: 0.0 }, rng.random_range(0.1..0.5)),
                ]
            }
            // A pushchair ahead.
            1 if body.height > 1.5 => placed(stroller(rng), 0.35, 0.0, 0.0, 0.0),
            // A bicycle walked at the side.
            2 if body.height > 1.4 => placed(bicycle(rng), 0.2, -0.45, 0.0, 0.0),
            // A shopping bag or a case in one hand.
            3..=4 => vec![(cuboid(0.0, 0.35, 0.25, rng.random_range(0.1..0.4), 0.12, rng.random_range(0.3..0.45), 0.0), rng.random_range(0.1..0.6))],
            _ => Vec::new(),
        }
    }

    /// Places `n` fixtures (posts, bins, bicycles, trees…) on free ground of the walkable area.
    fn furnish<R: Rng + ?Sized>(&mut self, n: usize, rng: &mut R) {
        let [x0, x1, y0, y1] = self.area;
        if x1 - x0 < 1.0 || y1 - y0 < 1.0 {
            return;
        }
        for _ in 0..n {
            let (x, y) = (rng.random_range(x0..x1), rng.random_range(y0..y1));
            if (x - self.robot[0]).hypot(y - self.robot[1]) < 3.0 + self.keep_clear {
                continue;
            }
            let kind = Fixture::sample(rng);
            let yaw = rng.random_range(0.0..std::f64::consts::TAU);
            let parts = kind.parts(rng);
            self.fixture(parts, x, y, yaw);
        }
    }

    /// Adds object-frame parts at (x, y) on the ground there, as one obstacle.
    fn fixture(&mut self, parts: Vec<(Shape, f32)>, x: f64, y: f64, yaw: f64) {
        let z = self.ground_at(x, y);
        let parts = placed(parts, x, y, z, yaw);
        // Only what stands on the ground up to head height blocks a walker.
        let r = parts.iter().filter(|(s, _)| s.top() < z + 2.5 || matches!(s, Shape::Cylinder { .. })).filter_map(|(s, _)| s.bounds_xy()).map(|(c, r)| (c[0] - x).hypot(c[1] - y) + r).fold(0.0, f64::max);
        if r > 0.0 {
            self.obstacles.push([x, y, r.min(3.0)]);
        }
        for (s, refl) in parts {
            self.add(s, refl);
        }
    }

    /// A vehicle parked at (x, y), heading `yaw`, as an obstacle.
    fn parked<R: Rng + ?Sized>(&mut self, kind: Vehicle, x: f64, y: f64, yaw: f64, rng: &mut R) {
        let parts = kind.parts(rng);
        let [l, w] = kind.footprint();
        // Two footprint circles along its length keep walkers off it.
        for s in [-0.25, 0.25] {
            let o = rot([s * l, 0.0, 0.0], yaw);
            self.obstacles.push([x + o[0], y + o[1], 0.3 * l.max(w)]);
        }
        for (s, refl) in placed(parts, x, y, self.floor, yaw) {
            self.add(s, refl);
        }
    }

    /// A raised slab (sidewalk, lawn, terrace) from `floor` up to `top`.
    fn slab(&mut self, x0: f64, x1: f64, y0: f64, y1: f64, top: f64, reflectivity: f32) {
        self.add(cuboid((x0 + x1) / 2.0, (y0 + y1) / 2.0, self.floor, x1 - x0, y1 - y0, top - self.floor, 0.0), reflectivity);
        self.raised.push([x0, x1, y0, y1, top]);
    }

    /// Building fronts along y = `at` (facing the street), broken by gaps and recessed doors.
    fn facades<R: Rng + ?Sized>(&mut self, at: f64, x0: f64, x1: f64, rng: &mut R) {
        let side = at.signum();
        let mut c = x0;
        while c < x1 {
            let len = rng.random_range(6.0..30.0f64).min(x1 - c);
            let depth = 8.0;
            let hgt = rng.random_range(3.5..20.0);
            let setback = if rng.random_bool(0.3) { rng.random_range(0.3..2.0) } else { 0.0 };
            let y = at + side * (setback + depth / 2.0);
            self.add(cuboid(c + len / 2.0, y, self.floor, len, depth, hgt, 0.0), rng.random_range(0.15..0.7));
            // Glass shop fronts: dark, so returns drop out.
            if rng.random_bool(0.4) {
                self.add(cuboid(c + len / 2.0, at + side * (setback - 0.02), self.floor + 0.5, len * 0.8, 0.04, 2.2, 0.0), 0.05);
            }
            self.facade_detail(c, c + len, at + side * setback, side, hgt, rng);
            c += len + if rng.random_bool(0.25) { rng.random_range(3.0..12.0) } else { 0.0 };
        }
    }

    /// What stands against a building front at y = `face` from x0 to x1 (the street on the side
    /// opposite `side`): pilasters, drainpipes, a doorway's frame, and along its foot bicycles,
    /// bins, bushes, A-boards and café tables.
    fn facade_detail<R: Rng + ?Sized>(&mut self, x0: f64, x1: f64, face: f64, side: f64, hgt: f64, rng: &mut R) {
        let step = rng.random_range(2.5..8.0);
        let pilaster = rng.random_bool(0.5);
        let mut x = x0 + step / 2.0;
        while x < x1 {
            match rng.random_range(0..6) {
                0 | 1 if pilaster => {
                    let d = rng.random_range(0.1..0.35);
                    self.add(cuboid(x, face - side * d / 2.0, self.floor, rng.random_range(0.3..0.7), d, hgt.min(6.0), 0.0), 0.5);
                }
                2 => self.add(Shape::Cylinder { c: [x, face - side * 0.08], r: 0.05, z0: self.floor, z1: self.floor + hgt.min(10.0) }, 0.5),
                3 => {
                    // A doorway's frame: two jambs proud of the wall.
                    for dx in [-0.6, 0.6] {
                        self.add(cuboid(x + dx, face - side * 0.08, self.floor, 0.15, 0.16, 2.3, 0.0), 0.5);
                    }
                }
                _ => {}
            }
            if rng.random_bool(0.35) {
                let kind = [Fixture::Bicycle, Fixture::Bin, Fixture::Bush, Fixture::Kiosk, Fixture::CafeTable, Fixture::Planter, Fixture::Scooter, Fixture::SignPost][rng.random_range(0..8)];
                let parts = kind.parts(rng);
                let off = match kind {
                    Fixture::CafeTable => 1.2,
                    Fixture::Bicycle | Fixture::Scooter => 0.35,
                    _ => 0.5,
                };
                let yaw = if matches!(kind, Fixture::Bicycle | Fixture::Scooter) { rng.random_range(-0.2..0.2) } else { 0.0 };
                self.fixture(parts, x + rng.random_range(-1.0..1.0), face - side * off, yaw);
            }
            x += step;
        }
    }

    pub(super) fn street<R: Rng + ?Sized>(&mut self, on_road: bool, rng: &mut R) {
        let f = self.floor;
        let half = rng.random_range(3.0..7.5);
        let kerb = rng.random_range(0.08..0.2);
        let (x0, x1) = (-rng.random_range(50.0..90.0), rng.random_range(50.0..90.0));
        let mut outer = [0.0; 2];
        for (i, side) in [-1.0f64, 1.0].into_iter().enumerate() {
            let sw = rng.random_range(1.8..6.0);
            let (a, b) = (side * half, side * (half + sw));
            self.slab(x0 - 20.0, x1 + 20.0, a.min(b), a.max(b), f + kerb, rng.random_range(0.15..0.4));
            outer[i] = b;
            match rng.random_range(0..4) {
                0 => {
                    // A fence or hedge with a lawn behind it.
                    self.slab(x0 - 20.0, x1 + 20.0, (b + side * 0.01).min(b + side * 30.0), (b + side * 0.01).max(b + side * 30.0), f + kerb + 0.05, 0.2);
                    let parts = fence([x0, b], [x1, b], f + kerb, rng);
                    for (s, r) in parts {
                        self.add(s, r);
                    }
                    self.facades(b + side * rng.random_range(10.0..25.0), x0, x1, rng);
                }
                _ => self.facades(b, x0, x1, rng),
            }
            // The kerb-side row: lamps, signs, trees, bollards, bins at regular spacing.
            let row_y = side * (half + rng.random_range(0.35..0.8));
            let tree_row = rng.random_bool(0.4);
            let mut x = x0 + rng.random_range(0.0..6.0);
            while x < x1 {
                let k = rng.random_range(0..10);
                let kind = match k {
                    _ if tree_row && k <= 2 => Fixture::Tree,
                    0..=1 => Fixture::LampPost,
                    2..=3 => Fixture::SignPost,
                    4..=5 => Fixture::Bollard,
                    6 => Fixture::Bin,
                    7 => Fixture::Bicycle,
                    8 => Fixture::Hydrant,
                    _ => Fixture::Scooter,
                };
                let parts = kind.parts(rng);
                let yaw = if matches!(kind, Fixture::Bicycle | Fixture::Scooter) { rng.random_range(0.0..std::f64::consts::TAU) } else { 0.0 };
                self.fixture(parts, x, row_y, yaw);
                x += rng.random_range(2.0..14.0);
            }
            // Parked vehicles along the kerb, with gaps.
            if half > 4.0 || rng.random_bool(0.5) {
                let mut x = x0;
                while x < x1 {
                    let kind = Vehicle::sample(rng);
                    let [l, w] = kind.footprint();
                    if rng.random_bool(0.7) {
                        let y = side * (half - w / 2.0 - rng.random_range(0.15..0.4));
                        let yaw = if side > 0.0 { 0.0 } else { std::f64::consts::PI } + rng.random_range(-0.05..0.05);
                        self.parked(kind, x + l / 2.0, y, yaw, rng);
                    }
                    x += l + rng.random_range(0.8..8.0);
                }
            }
        }
        // A railing down the middle of a wide road, now and then.
        if half > 5.5 && rng.random_bool(0.3) {
            for (s, r) in fence([x0, 0.0], [x1, 0.0], f, rng) {
                self.add(s, r);
            }
        }
        // Passing traffic in the lanes beside the platform's.
        let lane = half / 2.0;
        let ego_lane = if rng.random_bool(0.5) { -lane / 2.0 } else { lane / 2.0 };
        for _ in 0..rng.random_range(0..7) {
            let kind = Vehicle::sample(rng);
            let dir = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let y = -dir * lane / 2.0;
            if on_road && (y - ego_lane).abs() < 0.5 && rng.random_bool(0.7) {
                continue;
            }
            let x = rng.random_range(x0..x1);
            if on_road && (x - 0.0).abs() < 8.0 && (y - ego_lane).abs() < 0.5 {
                continue;
            }
            let parts = kind.parts(rng);
            let yaw = if dir > 0.0 { 0.0 } else { std::f64::consts::PI };
            self.movers.push(Mover { parts, pose: [x, y, yaw, rng.random_range(2.0..12.0)] });
        }
        let (ylo, yhi) = (outer[0].min(outer[1]), outer[0].max(outer[1]));
        self.area = [x0 + 1.0, x1 - 1.0, ylo + 0.3, yhi - 0.3];
        self.robot = if on_road { [0.0, ego_lane, 0.0] } else { [0.0, if rng.random_bool(0.5) { outer[1] - 1.0 } else { outer[0] + 1.0 }, 0.0] };
    }

    pub(super) fn campus<R: Rng + ?Sized>(&mut self, on_road: bool, rng: &mut R) {
        let f = self.floor;
        // A service road along x with parked cars on one side; the platform may drive on it.
        let half = rng.random_range(2.5..4.0);
        self.plaza(rng);
        let [x0, x1, y0, y1] = self.area;
        let mut x = x0;
        while x < x1 {
            let kind = Vehicle::sample(rng);
            let [l, w] = kind.footprint();
            if rng.random_bool(0.5) {
                self.parked(kind, x + l / 2.0, half + w / 2.0 + 0.3, 0.0, rng);
            }
            x += l + rng.random_range(0.8..10.0);
        }
        // Raised lawns with kerbs and terraces reached by stairs, railings along their edges.
        for _ in 0..rng.random_range(1..4) {
            let (cx, cy) = (rng.random_range(x0..x1), rng.random_range(y0..y1));
            if cy.abs() < half + 3.0 {
                continue;
            }
            let (lx, ly) = (rng.random_range(4.0..20.0), rng.random_range(3.0..12.0));
            let terrace = rng.random_bool(0.4);
            let top = if terrace { f + rng.random_range(0.45..1.0) } else { f + rng.random_range(0.1..0.25) };
            self.slab(cx - lx / 2.0, cx + lx / 2.0, cy - ly / 2.0, cy + ly / 2.0, top, if terrace { 0.4 } else { 0.15 });
            if terrace {
                // Stairs down towards the road, 0.15 m risers, 0.3 m treads.
                let steps = ((top - f) / 0.15).round().max(1.0) as usize;
                let dir = -cy.signum();
                let edge = if dir > 0.0 { cy + ly / 2.0 } else { cy - ly / 2.0 };
                let width = rng.random_range(2.0..5.0);
                for k in 0..steps {
                    let h = f + (steps - k) as f64 * (top - f) / steps as f64;
                    let yy = edge + dir * (0.15 + 0.3 * k as f64);
                    self.add(cuboid(cx, yy, f, width, 0.3, h - f, 0.0), 0.4);
                }
                for (s, r) in fence([cx - lx / 2.0, edge], [cx - width / 2.0, edge], top, rng) {
                    self.add(s, r);
                }
            }
        }
        self.robot = if on_road { [0.0, -half / 2.0, 0.0] } else { [0.0, rng.random_range(-half..half), 0.0] };
        let _ = y1;
    }

    /// Moves street walkers and standers off the road onto the nearer sidewalk, all but a few.
    fn onto_sidewalks<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        let road = self.raised.iter().filter(|r| r[4] > self.floor).map(|r| r[2].abs().min(r[3].abs())).fold(f64::INFINITY, f64::min);
        if !road.is_finite() {
            return;
        }
        let leaders: Vec<usize> = self.people.iter().filter_map(|p| p.follow.map(|f| f.0)).collect();
        for i in 0..self.people.len() {
            if self.people[i].follow.is_some() || leaders.contains(&i) || self.people[i].y.abs() >= road || rng.random_bool(0.15) {
                continue;
            }
            let side = if self.people[i].y >= 0.0 { 1.0 } else { -1.0 };
            let y = side * (road + rng.random_range(0.4..1.6));
            if self.obstacles.iter().any(|o| (o[0] - self.people[i].x).hypot(o[1] - y) < o[2] + 0.3) {
                continue;
            }
            self.people[i].y = y;
            // Walk along the street.
            let dir = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let p = &mut self.people[i];
            p.yaw = if dir > 0.0 { 0.0 } else { std::f64::consts::PI } + rng.random_range(-0.2..0.2);
            p.goal = [p.x + dir * 40.0, y];
        }
    }
}
