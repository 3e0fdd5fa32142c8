//! Scenes to fly through (DESIGN.md section 4): four built-in procedural meshes standing in
//! for the paper's Hangar, Crane and Street scenes plus a curved-shapes park, and any mesh
//! (e.g. an STL model) with a default orbit fitted to its bounding box.

mod curved;
mod hangar;
mod revisit;
mod street;
mod truss;

pub use revisit::{
    REVISIT_TURN_RADIUS_M, SURVEY_ROW_SPACING_M, SURVEY_ROWS, revisit_frames, revisit_scene,
    survey_frames, survey_scene,
};

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
    /// A scene from any mesh, e.g. an STL model, with a fitted default orbit: a stadium loop
    /// (a circle for a square footprint) around the bounding box, its straights along the
    /// box's long horizontal side and as long as the long side minus the short side, its half
    /// circles of radius 0.7 x half the short side + 5 m, grown by 15 % until
    /// [`path_is_free`] (with open sky) holds for the whole loop, at the latest once the loop
    /// encloses the box. It flies at `min z + clamp(a quarter of the height, 3 m, 5 m)`: the
    /// Mid-360 looks only 7 deg below the horizon, so higher up it would see no ground within
    /// 70 m. The flight starts mid-way along a straight, facing the long side.
    ///
    /// With `ground`, a horizontal plane at the box's lowest z reaching 80 m beyond it is added
    /// (after fitting), as a simulator world has one; STL models usually do not.
    pub fn from_mesh(
        name: &str,
        mut mesh: TriangleMesh,
        ground: bool,
    ) -> Result<Scene, RaycastError> {
        let caster = Raycaster::new(&mesh)?;
        let bbox = mesh.bounding_box().ok_or(RaycastError::EmptyMesh)?;
        let (centre, extent) = (bbox.centre(), bbox.extent());
        let height = bbox.min.z + (0.25 * extent.z).clamp(3.0, 5.0);
        let (long, short, axis_yaw_rad) = if extent.x >= extent.y {
            (0.5 * extent.x, 0.5 * extent.y, 0.0)
        } else {
            (0.5 * extent.y, 0.5 * extent.x, std::f64::consts::FRAC_PI_2)
        };
        let enclosing_m = std::f64::consts::SQRT_2 * short + CLEARANCE_M + 1.0;
        let loop_with = |radius_m: f64| TrajectorySpec {
            straight_half_m: long - short,
            axis_yaw_rad,
            start_along_m: 0.5 * std::f64::consts::PI * radius_m + (long - short),
            ..TrajectorySpec::orbit(Point3::new(centre.x, centre.y, height), radius_m)
        };
        // Positions about 1 m apart around the whole loop.
        let positions = |spec: &TrajectorySpec| -> Vec<Point3<f64>> {
            let perimeter_m = 4.0 * spec.straight_half_m + std::f64::consts::TAU * spec.radius_m;
            let sampler = TrajectorySpec {
                speed_m_s: 10.0,
                ..*spec
            };
            sampler
                .world_from_lidar(perimeter_m.ceil() as usize + 2, 10.0)
                .iter()
                .map(|p| Point3::from(p.translation.vector))
                .collect()
        };
        let mut radius_m = 0.7 * short + 5.0;
        while radius_m < enclosing_m
            && !path_is_free(&caster, &positions(&loop_with(radius_m)), true)
        {
            radius_m = (radius_m * 1.15).min(enclosing_m);
        }
        if ground {
            let reach_m = 80.0;
            let (min, max) = (
                bbox.min - Vector3::repeat(reach_m),
                bbox.max + Vector3::repeat(reach_m),
            );
            mesh.push_heightfield([min.x, min.y], [max.x, max.y], 10.0, |_, _| bbox.min.z);
        }
        Ok(Scene {
            name: name.to_owned(),
            mesh,
            trajectory: loop_with(radius_m),
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
    fn fitted_orbit_hugs_an_elongated_block() {
        let mut mesh = TriangleMesh::new();
        mesh.push_box(
            Point3::new(-10.0, -40.0, 0.0),
            Point3::new(10.0, 40.0, 30.0),
        );
        let scene = Scene::from_mesh("block", mesh, false).expect("scene");
        let t = scene.trajectory;
        assert!(
            (t.centre.z - 5.0).abs() < 1e-9,
            "a quarter of 30 m, clamped to 5 m"
        );
        assert!((t.straight_half_m - 30.0).abs() < 1e-9);
        assert!((t.axis_yaw_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // The half circles clear the box corners (14.1 m from their centres); the 14 probe
        // rays see a nearby corner only roughly, so the margin may be under 2 m.
        assert!(t.radius_m > 14.2 && t.radius_m < 19.0, "{}", t.radius_m);
        let caster = Raycaster::new(&scene.mesh).expect("mesh");
        let positions: Vec<_> = t
            .world_from_lidar(2000, 10.0)
            .iter()
            .map(|p| Point3::from(p.translation.vector))
            .collect();
        assert!(path_is_free(&caster, &positions, true));
    }
}
