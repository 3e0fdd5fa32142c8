//! A Livox Mid-360-like sensor (DESIGN.md section 4): FoV 360 deg x [-7, +52] deg,
//! 200,000 points/s at 10 Hz (20,000 rays per frame), range 0.1-70 m, Gaussian range noise
//! sigma 2 cm, and the non-repetitive single-beam pattern used by the MARSIM simulator.
//!
//! Time `t` runs on across frames (ray `i` of frame `k` is fired at
//! `t = k / frame_rate + i / (rays_per_frame * frame_rate)`), so successive frames sample
//! different directions. [`Mid360::scan`] casts every ray of a frame from one pose (a still
//! frame); [`Mid360::scan_moving`] casts each ray from the pose at its own firing time, as a
//! real sensor on a moving platform does, and reports each point's time.

use crate::Raycaster;
use nalgebra::{Isometry3, Point3, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use std::f64::consts::PI;

/// Sensor parameters; `Default` is the Mid-360 of DESIGN.md section 4.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mid360 {
    /// Rays fired per frame (20,000 = 200,000 points/s at 10 Hz). Fewer rays sample the same
    /// 0.1 s of the pattern more sparsely.
    pub rays_per_frame: usize,
    /// Frame rate (Hz).
    pub frame_rate_hz: f64,
    /// Closest range (m) that returns a point.
    pub min_range_m: f64,
    /// Farthest range (m) that returns a point.
    pub max_range_m: f64,
    /// Sigma (m) of the Gaussian noise added along each ray.
    pub range_noise_m: f64,
    /// Lowest elevation (deg) of the field of view.
    pub min_elevation_deg: f64,
    /// Highest elevation (deg) of the field of view.
    pub max_elevation_deg: f64,
}

impl Default for Mid360 {
    fn default() -> Self {
        Self {
            rays_per_frame: 20_000,
            frame_rate_hz: 10.0,
            min_range_m: 0.1,
            max_range_m: 70.0,
            range_noise_m: 0.02,
            min_elevation_deg: -7.0,
            max_elevation_deg: 52.0,
        }
    }
}

/// Azimuth and elevation (deg) of the beam at time `t_s` (the MARSIM Mid-360 pattern).
pub fn pattern_deg(t_s: f64) -> (f64, f64) {
    let t = t_s;
    let azimuth =
        (62050.63 * t - 3.11 * (314159.2 * t).cos() * (1256.636 * t).sin()).rem_euclid(360.0);
    let elevation = 25.5 * (20.0 * PI * t).cos()
        + 4.0 * (2.0 * PI * t / 0.006).cos() * (10000.0 * PI * t).cos()
        + 22.5;
    (azimuth, elevation)
}

impl Mid360 {
    /// Time (s) at which ray `ray` of frame `frame` is fired.
    pub fn ray_time_s(&self, frame: usize, ray: usize) -> f64 {
        let rays = self.rays_per_frame.max(1) as f64;
        (frame as f64 + ray as f64 / rays) / self.frame_rate_hz
    }

    /// Unit direction (sensor frame: x forward, z up) of the beam at `t_s`, or `None` when its
    /// elevation leaves the field of view (beyond rounding, which is clamped).
    pub fn direction_at(&self, t_s: f64) -> Option<Vector3<f64>> {
        let (azimuth, elevation) = pattern_deg(t_s);
        const SLACK_DEG: f64 = 1e-6;
        if elevation < self.min_elevation_deg - SLACK_DEG
            || elevation > self.max_elevation_deg + SLACK_DEG
        {
            return None;
        }
        let elevation = elevation
            .clamp(self.min_elevation_deg, self.max_elevation_deg)
            .to_radians();
        let azimuth = azimuth.to_radians();
        Some(Vector3::new(
            elevation.cos() * azimuth.cos(),
            elevation.cos() * azimuth.sin(),
            elevation.sin(),
        ))
    }

    /// The beam directions of frame `frame`, in firing order (rays outside the FoV dropped).
    pub fn frame_directions(&self, frame: usize) -> Vec<Vector3<f64>> {
        (0..self.rays_per_frame)
            .filter_map(|ray| self.direction_at(self.ray_time_s(frame, ray)))
            .collect()
    }

    /// One frame taken at `world_from_lidar`: the points (sensor frame, m) where the rays of
    /// frame `frame` first hit `scene` within range, with range noise drawn from `rng` (one
    /// draw per ray, hit or not, so the stream does not depend on the scene). Rays without a
    /// hit give no point. Parallel and serial casting give identical points.
    pub fn scan(
        &self,
        scene: &Raycaster,
        world_from_lidar: &Isometry3<f64>,
        frame: usize,
        rng: &mut impl Rng,
        parallel: bool,
    ) -> Vec<Point3<f64>> {
        let dirs_in_lidar = self.frame_directions(frame);
        let dirs_in_world: Vec<_> = dirs_in_lidar
            .iter()
            .map(|d| world_from_lidar.rotation * d)
            .collect();
        let origin = Point3::from(world_from_lidar.translation.vector);
        let ranges = scene.cast_all(&origin, &dirs_in_world, self.max_range_m, parallel);
        // `max` maps a NaN sigma to 0, so the distribution always exists.
        let noise = Normal::new(0.0, self.range_noise_m.max(0.0)).ok();
        dirs_in_lidar
            .iter()
            .zip(ranges)
            .filter_map(|(dir, range)| {
                let noisy = noise.map_or(0.0, |n| n.sample(rng));
                let range_m = range.filter(|&r| r >= self.min_range_m)?;
                Some(Point3::from(dir * (range_m + noisy)))
            })
            .collect()
    }
}

impl Mid360 {
    /// One frame taken while moving: ray `i` leaves from `world_from_lidar_at(t_i)` at its
    /// firing time `t_i` ([`Self::ray_time_s`]). The points are in the lidar frame at their
    /// own time (what a driver reports), with each point's time after the frame's first ray
    /// (s, f32). Range noise as [`Self::scan`] draws it; parallel and serial give identical
    /// points. A constant `world_from_lidar_at` gives exactly [`Self::scan`]'s points.
    pub fn scan_moving(
        &self,
        scene: &Raycaster,
        world_from_lidar_at: &(dyn Fn(f64) -> Isometry3<f64> + Sync),
        frame: usize,
        rng: &mut impl Rng,
        parallel: bool,
    ) -> (Vec<Point3<f64>>, Vec<f32>) {
        let start_s = self.ray_time_s(frame, 0);
        let rays: Vec<(f64, Vector3<f64>)> = (0..self.rays_per_frame)
            .filter_map(|ray| {
                let t = self.ray_time_s(frame, ray);
                self.direction_at(t).map(|d| (t, d))
            })
            .collect();
        let one = |(t, dir): &(f64, Vector3<f64>)| {
            let pose = world_from_lidar_at(*t);
            let origin = Point3::from(pose.translation.vector);
            scene.cast(&origin, &(pose.rotation * dir), self.max_range_m)
        };
        let ranges: Vec<Option<f64>> = if parallel {
            rays.par_iter().with_min_len(256).map(one).collect()
        } else {
            rays.iter().map(one).collect()
        };
        let noise = Normal::new(0.0, self.range_noise_m.max(0.0)).ok();
        let mut points = Vec::with_capacity(rays.len());
        let mut times_s = Vec::with_capacity(rays.len());
        for ((t, dir), range) in rays.iter().zip(ranges) {
            let noisy = noise.map_or(0.0, |n| n.sample(rng));
            let Some(range_m) = range.filter(|&r| r >= self.min_range_m) else {
                continue;
            };
            points.push(Point3::from(dir * (range_m + noisy)));
            times_s.push((t - start_s) as f32);
        }
        (points, times_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::TriangleMesh;
    use rand::{SeedableRng, rngs::StdRng};

    #[test]
    fn pattern_stays_in_the_fov_and_does_not_repeat() {
        let sensor = Mid360::default();
        let (mut lowest, mut highest) = (f64::MAX, f64::MIN);
        for frame in 0..5 {
            let dirs = sensor.frame_directions(frame);
            assert_eq!(dirs.len(), 20_000, "no ray leaves the FoV");
            for d in &dirs {
                let elevation = d.z.asin().to_degrees();
                lowest = lowest.min(elevation);
                highest = highest.max(elevation);
                assert!((d.norm() - 1.0).abs() < 1e-12);
            }
        }
        assert!((-7.0 - 1e-9..-6.5).contains(&lowest), "{lowest}");
        assert!(highest <= 52.0 + 1e-9 && highest > 51.5, "{highest}");
        let (a, b) = (sensor.frame_directions(0), sensor.frame_directions(1));
        assert!(
            (a[0] - b[0]).norm() > 1e-3,
            "consecutive frames start differently"
        );
        let shared = a
            .iter()
            .zip(&b)
            .filter(|(x, y)| (*x - *y).norm() < 1e-6)
            .count();
        assert!(shared < 10, "{shared} identical rays");
        // The whole azimuth circle is covered within one frame.
        let mut bins = [0usize; 36];
        for d in &a {
            let az = d.y.atan2(d.x).to_degrees().rem_euclid(360.0);
            bins[(az / 10.0) as usize % 36] += 1;
        }
        assert!(bins.iter().all(|&n| n > 200), "{bins:?}");
    }

    /// Within 0.1 m of a wall of the test room (-6..7 x -5..4 x -1.5..3 m).
    fn on_a_wall(p: &Point3<f64>) -> bool {
        let d = [
            p.x + 6.0,
            7.0 - p.x,
            p.y + 5.0,
            4.0 - p.y,
            p.z + 1.5,
            3.0 - p.z,
        ];
        d.iter().any(|v| v.abs() < 0.1)
    }

    /// Held still, the moving scan is the still scan; moving, each point lies on the room's
    /// walls seen from the pose at its own time, and serial and parallel casts agree.
    #[test]
    fn a_moving_scan_casts_each_ray_from_its_own_pose() {
        let mut room = TriangleMesh::new();
        room.push_box(Point3::new(-6.0, -5.0, -1.5), Point3::new(7.0, 4.0, 3.0));
        let caster = Raycaster::new(&room).expect("room");
        let sensor = Mid360 {
            rays_per_frame: 4000,
            ..Mid360::default()
        };
        let pose = Isometry3::translation(0.5, 0.2, 0.0);
        let still = sensor.scan(&caster, &pose, 3, &mut StdRng::seed_from_u64(1), true);
        let (held, times) =
            sensor.scan_moving(&caster, &|_| pose, 3, &mut StdRng::seed_from_u64(1), true);
        assert_eq!(still, held);
        assert!(times.windows(2).all(|t| t[0] <= t[1]) && times[0] == 0.0);
        assert!((0.099..0.1).contains(&times[times.len() - 1]));
        let start_s = sensor.ray_time_s(3, 0);
        let moving = |t: f64| {
            Isometry3::new(
                nalgebra::Vector3::new(3.0 * (t - start_s), 0.0, 0.0),
                nalgebra::Vector3::new(0.0, 0.0, 2.0 * (t - start_s)),
            )
        };
        let (points, times) =
            sensor.scan_moving(&caster, &moving, 3, &mut StdRng::seed_from_u64(1), true);
        let serial = sensor.scan_moving(&caster, &moving, 3, &mut StdRng::seed_from_u64(1), false);
        assert_eq!((points.clone(), times.clone()), serial);
        let at_own_time = points
            .iter()
            .zip(&times)
            .filter(|(p, t)| on_a_wall(&(moving(start_s + f64::from(**t)) * **p)))
            .count();
        let at_stamp = points
            .iter()
            .filter(|p| on_a_wall(&(moving(start_s) * **p)))
            .count();
        assert!(at_own_time as f64 > 0.99 * points.len() as f64);
        assert!((at_stamp as f64) < 0.9 * points.len() as f64, "{at_stamp}");
    }

    #[test]
    fn a_closed_room_returns_almost_every_ray() {
        let mut room = TriangleMesh::new();
        room.push_box(Point3::new(-6.0, -5.0, -1.5), Point3::new(7.0, 4.0, 3.0));
        let caster = Raycaster::new(&room).expect("room");
        let sensor = Mid360::default();
        let pose = Isometry3::translation(0.5, 0.2, 0.0);
        let points = sensor.scan(&caster, &pose, 3, &mut StdRng::seed_from_u64(1), true);
        assert!(points.len() >= 19_990, "{}", points.len());
        let on_wall = points.iter().map(|p| pose * p).filter(on_a_wall).count();
        assert!(on_wall as f64 > 0.99 * points.len() as f64);
        let serial = sensor.scan(&caster, &pose, 3, &mut StdRng::seed_from_u64(1), false);
        assert_eq!(points, serial);
    }
}
