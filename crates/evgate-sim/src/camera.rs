//! Pinhole camera: intrinsics and projection of world points through a camera pose.

use serde::{Deserialize, Serialize};

use crate::linalg::{RigidTransform, Vec3};

/// Pinhole intrinsics in pixels (no distortion: the simulator renders an ideal lens).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct Intrinsics {
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl Intrinsics {
    /// The 3×3 matrix K, row-major, as stored in the sequence file.
    pub fn matrix(&self) -> [[f64; 3]; 3] {
        [
            [self.fx as f64, 0.0, self.cx as f64],
            [0.0, self.fy as f64, self.cy as f64],
            [0.0, 0.0, 1.0],
        ]
    }

    /// Direction in the camera frame through the centre of pixel (x, y), scaled so that z = 1
    /// (then the ray parameter of a hit is its depth).
    pub fn ray(&self, x: f32, y: f32) -> Vec3 {
        Vec3::new(
            (x + 0.5 - self.cx) / self.fx,
            (y + 0.5 - self.cy) / self.fy,
            1.0,
        )
    }

    /// Pixel coordinates (x, y) of a camera-frame point, in the convention where pixel centres
    /// sit at integer coordinates; `None` behind the camera.
    pub fn project(&self, camera_point: Vec3) -> Option<(f32, f32)> {
        if camera_point.z <= 1e-4 {
            return None;
        }
        let inv_z = 1.0 / camera_point.z;
        Some((
            self.fx * camera_point.x * inv_z + self.cx - 0.5,
            self.fy * camera_point.y * inv_z + self.cy - 0.5,
        ))
    }
}

/// Projects a world point through a camera whose pose maps camera coordinates to the world.
pub fn project_world(
    intrinsics: &Intrinsics,
    camera: &RigidTransform,
    world: Vec3,
) -> Option<(f32, f32)> {
    intrinsics.project(camera.to_local(world))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::Mat3;

    #[test]
    fn ray_through_pixel_projects_back_to_it() {
        let k = Intrinsics {
            fx: 250.0,
            fy: 250.0,
            cx: 173.0,
            cy: 130.0,
        };
        let pose = RigidTransform {
            rotation: Mat3::from_yaw_pitch_roll(0.1, 0.2, 0.3),
            translation: Vec3::new(0.5, -0.2, 1.0),
        };
        let point = pose.to_world(k.ray(17.0, 200.0) * 3.0);
        let (x, y) = project_world(&k, &pose, point).unwrap();
        assert!(
            (x - 17.0).abs() < 1e-3 && (y - 200.0).abs() < 1e-3,
            "{x} {y}"
        );
    }

    #[test]
    fn points_behind_the_camera_do_not_project() {
        let k = Intrinsics {
            fx: 1.0,
            fy: 1.0,
            cx: 0.0,
            cy: 0.0,
        };
        assert!(k.project(Vec3::new(0.0, 0.0, -1.0)).is_none());
    }
}
