//! Scenes to fly through (DESIGN.md section 4): four built-in procedural meshes standing in
//! for the paper's Hangar, Crane and Street scenes plus a curved-shapes park, and any mesh
//! (e.g. an STL model) with a default orbit fitted to its bounding box.

mod curved;
mod hangar;
mod street;
mod truss;

use crate::{RaycastError, Raycaster, TrajectorySpec, TriangleMesh};
use nalgebra::{Point3, Vector3};

/// The built-in procedural scenes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BuiltinScene {
    /// Barrel-vault hangar with an aircraft inside.
    Hangar,
    /// Domes, cylinders, tori, a sphere and a saddle roof on undulating ground.
    Curved,
    /// Tower crane of thin lattice members, building frames, containers.
    Truss,
    /// Street with building blocks, poles, trees, cars and clutter.
    Street,
}

impl BuiltinScene {
    /// Every built-in scene.
    pub const ALL: [BuiltinScene; 4] = [Self::Hangar, Self::Curved, Self::Truss, Self::Street];

    /// The name used on the command line and in meta.json.
    pub fn name(self) -> &'static str {
        match self {
            Self::Hangar => "hangar",
            Self::Curved => "curved",
            Self::Truss => "truss",
            Self::Street => "street",
        }
    }

    /// The scene called `name`, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// Builds the mesh and its default trajectory (deterministic, no randomness).
    pub fn build(self) -> Scene {
        let (mesh, trajectory) = match self {
            Self::Hangar => hangar::build(),
            Self::Curved => curved::build(),
            Self::Truss => truss::build(),
            Self::Street => street::build(),
        };
        Scene {
            name: self.name().to_owned(),
            mesh,
            trajectory,
        }
    }
}

/// A mesh to simulate in, with the trajectory that suits it.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Scene name (built-in name or file stem), recorded in meta.json.
    pub name: String,
    /// The world geometry (m).
    pub mesh: TriangleMesh,
    /// Default flight through free space.
    pub trajectory: TrajectorySpec,
}

/// Distance (m) the sensor keeps from any surface on a fitted orbit.
pub const CLEARANCE_M: f64 = 2.0;

/// True if the polyline through `positions` stays out of the geometry: no surface within
/// [`CLEARANCE_M`] of any position (14 probe rays), none crossed between consecutive
/// positions, and, with `open_sky`, nothing above any position (so a path around a model of
/// unknown shape is not inside it).
pub fn path_is_free(caster: &Raycaster, positions: &[Point3<f64>], open_sky: bool) -> bool {
    let mut probes: Vec<Vector3<f64>> = Vec::new();
    for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
        probes.extend([axis, -axis]);
    }
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                probes.push(Vector3::new(sx, sy, sz).normalize());
            }
        }
    }
    let clear_around = |p: &Point3<f64>| {
        probes
            .iter()
            .all(|d| caster.cast(p, d, CLEARANCE_M).is_none())
            && !(open_sky && caster.cast(p, &Vector3::z(), f64::MAX).is_some())
    };
    let segment_clear = |a: &Point3<f64>, b: &Point3<f64>| {
        let d = b - a;
        let length = d.norm();
        length < 1e-12 || caster.cast(a, &(d / length), length).is_none()
    };
    positions.iter().all(clear_around) && positions.windows(2).all(|w| segment_clear(&w[0], &w[1]))
}

impl Scene {
    /// A scene from any mesh, e.g. an STL model, with a fitted default orbit: centred on the
    /// bounding box, at `min z + clamp(half the height, 2 m, 30 m)`, of radius 0.7 x the
    /// horizontal half-diagonal + 5 m, grown by 15 % until [`path_is_free`] holds for the
    /// whole circle (at the latest once it clears the box). Fails on an unusable mesh.
    pub fn from_mesh(name: &str, mesh: TriangleMesh) -> Result<Scene, RaycastError> {
        let caster = Raycaster::new(&mesh)?;
        let bbox = mesh.bounding_box().ok_or(RaycastError::EmptyMesh)?;
        let (centre, extent) = (bbox.centre(), bbox.extent());
        let height = bbox.min.z + (0.5 * extent.z).clamp(2.0, 30.0);
        let half_diagonal = 0.5 * extent.xy().norm();
        let outside_m = half_diagonal + CLEARANCE_M + 1.0;
        let mut radius_m = 0.7 * half_diagonal + 5.0;
        let circle = |r: f64| -> Vec<Point3<f64>> {
            let steps = ((std::f64::consts::TAU * r).ceil() as usize).max(16);
            (0..=steps)
                .map(|k| {
                    let a = std::f64::consts::TAU * k as f64 / steps as f64;
                    Point3::new(centre.x + r * a.cos(), centre.y + r * a.sin(), height)
                })
                .collect()
        };
        while radius_m < outside_m && !path_is_free(&caster, &circle(radius_m), true) {
            radius_m = (radius_m * 1.15).min(outside_m);
        }
        let trajectory = TrajectorySpec::orbit(Point3::new(centre.x, centre.y, height), radius_m);
        Ok(Scene {
            name: name.to_owned(),
            mesh,
            trajectory,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_trajectories_fly_in_free_space() {
        for scene in BuiltinScene::ALL.map(BuiltinScene::build) {
            let caster = Raycaster::new(&scene.mesh).expect("mesh");
            let poses = scene.trajectory.world_from_lidar(300, 10.0);
            let positions: Vec<_> = poses
                .iter()
                .map(|p| Point3::from(p.translation.vector))
                .collect();
            // Flights inside the hangar, under the canopy and the crane's jib have no open sky.
            let open_sky = scene.name == "street";
            let free = path_is_free(&caster, &positions, open_sky);
            assert!(free, "{}: default path hits geometry", scene.name);
        }
    }

    #[test]
    fn fitted_orbit_clears_a_block() {
        let mut mesh = TriangleMesh::new();
        mesh.push_box(
            Point3::new(-40.0, -10.0, 0.0),
            Point3::new(40.0, 10.0, 30.0),
        );
        let scene = Scene::from_mesh("block", mesh).expect("scene");
        let t = scene.trajectory;
        assert!((t.centre.z - 15.0).abs() < 1e-9);
        assert!(t.radius_m > 40.0 + CLEARANCE_M - 1e-9, "{}", t.radius_m);
    }
}
