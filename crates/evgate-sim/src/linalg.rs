//! The small amount of 3-D linear algebra the renderer needs, in `f32` for speed.

use std::ops::{Add, Mul, Neg, Sub};

/// A 3-vector (points and directions alike).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vec3 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

impl Vec3 {
    pub const fn new(x: f32, y: f32, z: f32) -> Self {
        Self { x, y, z }
    }

    pub fn dot(self, other: Vec3) -> f32 {
        self.x * other.x + self.y * other.y + self.z * other.z
    }

    pub fn cross(self, other: Vec3) -> Vec3 {
        Vec3::new(
            self.y * other.z - self.z * other.y,
            self.z * other.x - self.x * other.z,
            self.x * other.y - self.y * other.x,
        )
    }

    pub fn length(self) -> f32 {
        self.dot(self).sqrt()
    }

    pub fn normalized(self) -> Vec3 {
        self * (1.0 / self.length())
    }

    /// Component `i` (0 = x, 1 = y, 2 = z).
    pub fn axis(self, i: usize) -> f32 {
        match i {
            0 => self.x,
            1 => self.y,
            _ => self.z,
        }
    }
}

impl Add for Vec3 {
    type Output = Vec3;
    fn add(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl Sub for Vec3 {
    type Output = Vec3;
    fn sub(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl Neg for Vec3 {
    type Output = Vec3;
    fn neg(self) -> Vec3 {
        Vec3::new(-self.x, -self.y, -self.z)
    }
}

impl Mul<f32> for Vec3 {
    type Output = Vec3;
    fn mul(self, s: f32) -> Vec3 {
        Vec3::new(self.x * s, self.y * s, self.z * s)
    }
}

/// A 3×3 matrix stored by rows; used for rotations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mat3 {
    pub rows: [Vec3; 3],
}

impl Mat3 {
    pub const IDENTITY: Mat3 = Mat3 {
        rows: [
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ],
    };

    /// Rotation about the x axis (pitch in the camera convention x right, y down, z forward).
    pub fn rotation_x(angle: f32) -> Mat3 {
        let (s, c) = angle.sin_cos();
        Mat3 {
            rows: [
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, c, -s),
                Vec3::new(0.0, s, c),
            ],
        }
    }

    /// Rotation about the y axis (yaw).
    pub fn rotation_y(angle: f32) -> Mat3 {
        let (s, c) = angle.sin_cos();
        Mat3 {
            rows: [
                Vec3::new(c, 0.0, s),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(-s, 0.0, c),
            ],
        }
    }

    /// Rotation about the z axis (roll).
    pub fn rotation_z(angle: f32) -> Mat3 {
        let (s, c) = angle.sin_cos();
        Mat3 {
            rows: [
                Vec3::new(c, -s, 0.0),
                Vec3::new(s, c, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
            ],
        }
    }

    /// Yaw, then pitch, then roll applied in the body frame: `Ry(yaw) · Rx(pitch) · Rz(roll)`.
    pub fn from_yaw_pitch_roll(yaw: f32, pitch: f32, roll: f32) -> Mat3 {
        Mat3::rotation_y(yaw) * Mat3::rotation_x(pitch) * Mat3::rotation_z(roll)
    }

    /// Rotation by `angle` radians about the unit vector `axis` (Rodrigues' formula).
    pub fn from_axis_angle(axis: Vec3, angle: f32) -> Mat3 {
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        let Vec3 { x, y, z } = axis;
        Mat3 {
            rows: [
                Vec3::new(t * x * x + c, t * x * y - s * z, t * x * z + s * y),
                Vec3::new(t * x * y + s * z, t * y * y + c, t * y * z - s * x),
                Vec3::new(t * x * z - s * y, t * y * z + s * x, t * z * z + c),
            ],
        }
    }

    pub fn transpose(&self) -> Mat3 {
        let [a, b, c] = self.rows;
        Mat3 {
            rows: [
                Vec3::new(a.x, b.x, c.x),
                Vec3::new(a.y, b.y, c.y),
                Vec3::new(a.z, b.z, c.z),
            ],
        }
    }

    pub fn apply(&self, v: Vec3) -> Vec3 {
        Vec3::new(
            self.rows[0].dot(v),
            self.rows[1].dot(v),
            self.rows[2].dot(v),
        )
    }

    /// Column `i` (the image of the i-th basis vector).
    pub fn column(&self, i: usize) -> Vec3 {
        Vec3::new(
            self.rows[0].axis(i),
            self.rows[1].axis(i),
            self.rows[2].axis(i),
        )
    }
}

impl Mul for Mat3 {
    type Output = Mat3;
    fn mul(self, o: Mat3) -> Mat3 {
        let columns = [o.column(0), o.column(1), o.column(2)];
        let row = |r: Vec3| Vec3::new(r.dot(columns[0]), r.dot(columns[1]), r.dot(columns[2]));
        Mat3 {
            rows: [row(self.rows[0]), row(self.rows[1]), row(self.rows[2])],
        }
    }
}

/// A rigid transform from a local frame to the world: `world = rotation · local + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidTransform {
    pub rotation: Mat3,
    pub translation: Vec3,
}

impl RigidTransform {
    pub fn to_world(&self, local: Vec3) -> Vec3 {
        self.rotation.apply(local) + self.translation
    }

    pub fn to_local(&self, world: Vec3) -> Vec3 {
        self.rotation.transpose().apply(world - self.translation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn rotations_are_orthonormal_and_invert_by_transpose() {
        let r = Mat3::from_yaw_pitch_roll(0.3, -0.7, 1.1);
        let v = Vec3::new(0.2, -1.5, 3.0);
        assert!(close(r.transpose().apply(r.apply(v)), v));
        assert!((r.apply(v).length() - v.length()).abs() < 1e-5);
    }

    #[test]
    fn yaw_turns_forward_axis_towards_positive_x() {
        let forward = Mat3::rotation_y(std::f32::consts::FRAC_PI_2).apply(Vec3::new(0.0, 0.0, 1.0));
        assert!(close(forward, Vec3::new(1.0, 0.0, 0.0)));
    }

    #[test]
    fn axis_angle_matches_elementary_rotation() {
        let a = Mat3::from_axis_angle(Vec3::new(0.0, 1.0, 0.0), 0.7);
        let b = Mat3::rotation_y(0.7);
        let v = Vec3::new(1.0, 2.0, 3.0);
        assert!(close(a.apply(v), b.apply(v)));
    }

    #[test]
    fn rigid_transform_round_trips() {
        let pose = RigidTransform {
            rotation: Mat3::from_yaw_pitch_roll(1.0, 0.2, -0.4),
            translation: Vec3::new(1.0, 2.0, 3.0),
        };
        let p = Vec3::new(-0.5, 0.25, 2.0);
        assert!(close(pose.to_local(pose.to_world(p)), p));
    }
}
