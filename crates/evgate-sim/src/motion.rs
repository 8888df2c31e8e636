//! Smooth, deterministic motion as closed-form functions of time, so a pose can be evaluated at
//! any instant (the flow and mask ground truth need poses at t + horizon).

use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::linalg::{Mat3, RigidTransform, Vec3};

/// Range of the random factor on each wobble term's amplitude.
const AMPLITUDE_SPREAD: (f32, f32) = (0.6, 1.4);

/// A sum of sinusoids: smooth motion with curves and accelerations that never repeats exactly
/// within a sequence.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Wobble {
    /// (amplitude, angular frequency in rad/s, phase in rad) per term.
    pub terms: Vec<(f32, f32, f32)>,
}

impl Wobble {
    /// `count` terms with frequencies in `[min_hz, max_hz]`; the amplitudes are chosen so that
    /// the peak speed of the sum is about `peak_speed` (units per second).
    pub fn random(
        count: usize,
        peak_speed: f32,
        min_hz: f32,
        max_hz: f32,
        rng: &mut impl Rng,
    ) -> Wobble {
        if count == 0 || peak_speed == 0.0 {
            return Wobble::default();
        }
        let terms = (0..count)
            .map(|_| {
                let omega = std::f32::consts::TAU * rng.gen_range(min_hz..=max_hz);
                let amplitude = peak_speed / (count as f32).sqrt() / omega
                    * rng.gen_range(AMPLITUDE_SPREAD.0..AMPLITUDE_SPREAD.1);
                (amplitude, omega, rng.gen_range(0.0..std::f32::consts::TAU))
            })
            .collect();
        Wobble { terms }
    }

    /// Like [`Wobble::random`], with the lowest frequency raised where needed so that no term's
    /// amplitude exceeds `max_amplitude`: the motion keeps its peak speed but swings less far
    /// (a term's amplitude is its speed over its angular frequency).
    pub fn random_bounded(
        count: usize,
        peak_speed: f32,
        max_amplitude: f32,
        min_hz: f32,
        max_hz: f32,
        rng: &mut impl Rng,
    ) -> Wobble {
        let slowest_hz = AMPLITUDE_SPREAD.1 * peak_speed
            / ((count.max(1) as f32).sqrt() * max_amplitude * std::f32::consts::TAU);
        Wobble::random(
            count,
            peak_speed,
            min_hz.max(slowest_hz).min(max_hz),
            max_hz,
            rng,
        )
    }

    pub fn value(&self, t: f32) -> f32 {
        self.terms
            .iter()
            .map(|&(a, w, p)| a * (w * t + p).sin())
            .sum()
    }
}

/// Folds `x` into `[lower, upper]` by reflection: a path that crosses a bound bounces back.
pub fn bounce(x: f32, lower: f32, upper: f32) -> f32 {
    let span = upper - lower;
    if span <= 0.0 {
        return lower;
    }
    let m = (x - lower).rem_euclid(2.0 * span);
    lower + if m > span { 2.0 * span - m } else { m }
}

/// Camera motion: a base pose plus rotation-dominated wobble (hand-held or robot-mounted),
/// small translations that produce parallax, and an optional constant drive velocity.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EgoMotion {
    pub base_position: Vec3Def,
    /// Yaw, pitch, roll in radians.
    pub base_attitude: [f32; 3],
    pub drive_velocity: Vec3Def,
    /// Yaw, pitch, roll wobble in radians.
    pub attitude_wobble: [Wobble; 3],
    /// x, y, z wobble in metres.
    pub position_wobble: [Wobble; 3],
}

impl EgoMotion {
    /// Camera-to-world pose at `t` seconds.
    pub fn pose(&self, t: f32) -> RigidTransform {
        let [yaw, pitch, roll] = self.base_attitude;
        let rotation = Mat3::from_yaw_pitch_roll(
            yaw + self.attitude_wobble[0].value(t),
            pitch + self.attitude_wobble[1].value(t),
            roll + self.attitude_wobble[2].value(t),
        );
        let drive: Vec3 = self.drive_velocity.into();
        let wobble = Vec3::new(
            self.position_wobble[0].value(t),
            self.position_wobble[1].value(t),
            self.position_wobble[2].value(t),
        );
        RigidTransform {
            rotation,
            translation: Vec3::from(self.base_position) + drive * t + wobble,
        }
    }

    /// How far the drive has carried the camera along z at `t` (objects of a driving scene keep
    /// their distance relative to it).
    pub fn drive_offset(&self, t: f32) -> Vec3 {
        Vec3::from(self.drive_velocity) * t
    }
}

/// Path of an independently moving object: a drift with time-warped speed (accelerations and
/// decelerations) plus curved wobble, bounced inside a box, and a spin about its own axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectPath {
    pub start: Vec3Def,
    pub velocity: Vec3Def,
    /// (relative amplitude < 1, angular frequency, phase): speed multiplier 1 + a·cos(ωt + φ).
    pub speed_modulation: (f32, f32, f32),
    pub wobble: [Wobble; 3],
    pub lower: Vec3Def,
    pub upper: Vec3Def,
    /// When true the bounce box moves with the camera's drive (traffic around a moving car).
    pub follows_drive: bool,
    pub base_rotation: [f32; 3],
    pub spin_axis: Vec3Def,
    pub spin_rate: f32,
    pub spin_wobble: Wobble,
    /// The drift turns about the vertical at this rate (rad per second of travel): a curve of
    /// constant curvature that the object's history predicts; 0 drifts straight.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub turn_rate: f32,
}

fn is_zero(value: &f32) -> bool {
    *value == 0.0
}

impl ObjectPath {
    /// Object-to-world pose at `t` seconds; `drive` is the camera's drive offset at `t`.
    pub fn pose(&self, t: f32, drive: Vec3) -> RigidTransform {
        let (a, w, p) = self.speed_modulation;
        // Integral of 1 + a·cos(ωt + φ): the distance travelled at unit speed.
        let travelled = if w > 0.0 {
            t + a / w * ((w * t + p).sin() - p.sin())
        } else {
            t
        };
        let start = Vec3::from(self.start);
        let velocity = Vec3::from(self.velocity);
        let (lower, upper) = (Vec3::from(self.lower), Vec3::from(self.upper));
        let drift = self.drift(velocity, travelled);
        let free = |axis: usize| start.axis(axis) + drift.axis(axis) + self.wobble[axis].value(t);
        let mut position = Vec3::new(
            bounce(free(0), lower.x, upper.x),
            bounce(free(1), lower.y, upper.y),
            bounce(free(2), lower.z, upper.z),
        );
        if self.follows_drive {
            position = position + drive;
        }
        let [yaw, pitch, roll] = self.base_rotation;
        let spin = self.spin_rate * t + self.spin_wobble.value(t);
        let rotation = Mat3::from_axis_angle(Vec3::from(self.spin_axis), spin)
            * Mat3::from_yaw_pitch_roll(yaw, pitch, roll);
        RigidTransform {
            rotation,
            translation: position,
        }
    }
}

impl ObjectPath {
    /// Displacement after `travelled` seconds at unit speed: `velocity · travelled` turned about
    /// the vertical by `turn_rate · travelled` along the way (the integral of the turning
    /// velocity, a circular arc in x–z).
    fn drift(&self, velocity: Vec3, travelled: f32) -> Vec3 {
        let w = self.turn_rate;
        if w == 0.0 {
            return velocity * travelled;
        }
        let angle = w * travelled;
        let along = angle.sin() / w;
        let aside = (1.0 - angle.cos()) / w;
        Vec3::new(
            velocity.x * along + velocity.z * aside,
            velocity.y * travelled,
            velocity.z * along - velocity.x * aside,
        )
    }
}

/// Serialisable form of [`Vec3`] (`[x, y, z]`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vec3Def(pub [f32; 3]);

impl From<Vec3Def> for Vec3 {
    fn from(v: Vec3Def) -> Vec3 {
        Vec3::new(v.0[0], v.0[1], v.0[2])
    }
}

impl From<Vec3> for Vec3Def {
    fn from(v: Vec3) -> Vec3Def {
        Vec3Def([v.x, v.y, v.z])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn bounce_reflects_at_both_bounds() {
        assert_eq!(bounce(0.5, 0.0, 1.0), 0.5);
        assert!((bounce(1.25, 0.0, 1.0) - 0.75).abs() < 1e-6);
        assert!((bounce(-0.25, 0.0, 1.0) - 0.25).abs() < 1e-6);
        assert!((bounce(2.25, 0.0, 1.0) - 0.25).abs() < 1e-6);
    }

    #[test]
    fn a_turning_path_keeps_its_speed_and_curves_at_the_turn_rate() {
        let path = ObjectPath {
            start: Vec3Def([0.0, 0.0, 2.0]),
            velocity: Vec3Def([1.0, 0.0, 0.5]),
            speed_modulation: (0.0, 0.0, 0.0),
            wobble: Default::default(),
            lower: Vec3Def([-100.0; 3]),
            upper: Vec3Def([100.0; 3]),
            follows_drive: false,
            base_rotation: [0.0; 3],
            spin_axis: Vec3Def([0.0, 1.0, 0.0]),
            spin_rate: 0.0,
            spin_wobble: Wobble::default(),
            turn_rate: 0.8,
        };
        let at = |t: f32| path.pose(t, Vec3::default()).translation;
        let dt = 1e-3;
        let velocity_at = |t: f32| (at(t + dt) - at(t - dt)) * (0.5 / dt);
        let speed = Vec3::new(1.0, 0.0, 0.5).length();
        for t in [0.3f32, 1.0, 2.5] {
            let (v0, v1) = (velocity_at(t), velocity_at(t + 0.1));
            assert!(
                (v0.length() - speed).abs() < 1e-2,
                "speed {} at {t}",
                v0.length()
            );
            let turned = (v0.x * v1.z - v0.z * v1.x).atan2(v0.x * v1.x + v0.z * v1.z);
            assert!(
                (turned.abs() - 0.08).abs() < 2e-3,
                "turned {turned} in 0.1 s at {t}"
            );
        }
        let straight = ObjectPath {
            turn_rate: 0.0,
            ..path.clone()
        };
        let line = straight.pose(2.0, Vec3::default()).translation;
        assert!((line - Vec3::new(2.0, 0.0, 3.0)).length() < 1e-5);
    }

    #[test]
    fn wobble_peak_speed_is_near_the_request() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let wobble = Wobble::random(3, 2.0, 0.2, 1.0, &mut rng);
        let dt = 1e-3;
        let peak = (0..20_000)
            .map(|i| ((wobble.value(i as f32 * dt + dt) - wobble.value(i as f32 * dt)) / dt).abs())
            .fold(0.0f32, f32::max);
        assert!(peak > 0.8 && peak < 5.0, "peak speed {peak}");
    }
}
