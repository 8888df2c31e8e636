//! Complete simulator configuration: sensor, optics, scene recipe and pixel model.

use std::path::PathBuf;

use evgate_core::SensorSize;
use serde::{Deserialize, Serialize};

use crate::camera::Intrinsics;
use crate::event_model::EventModel;
use crate::texture::TextureStyle;

/// The arrangement of the static world and where the camera stands in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Layout {
    /// A room seen at eye height: floor, walls, furniture panels; objects fly through it.
    Room,
    /// A room with the camera tilted down at the floor; objects slide on the floor.
    Floor,
    /// The camera faces a wall at close range; objects pass in front of it.
    Wall,
    /// The camera looks down at a table; small objects move on it.
    Table,
    /// A street: road, facades, roadside posts; the camera drives forward.
    Road,
}

/// The recipe for a random scene: what varies with the seed is drawn within these ranges.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct SceneParams {
    pub layout: Layout,
    /// Number of moving objects is drawn uniformly in `min-objects..=max-objects`.
    pub min_objects: u32,
    pub max_objects: u32,
    /// Typical object speed (m/s); each object gets 0.6–1.4× this.
    pub object_speed_mps: f32,
    /// Range of object sizes (longest side, metres).
    pub object_size_m: [f32; 2],
    /// Share of objects that are flat ellipses instead of boxes.
    pub flat_object_share: f32,
    /// Peak angular speed of the camera wobble (rad/s).
    pub ego_rotation_rad_s: f32,
    /// Peak speed of the camera's translational wobble (m/s).
    pub ego_translation_mps: f32,
    /// Constant forward speed of the camera (m/s), for driving.
    pub drive_mps: f32,
    pub world_texture: TextureStyle,
    pub object_texture: TextureStyle,
    /// PNG photographs that replace every procedural texture, world and objects alike, each
    /// surface drawing one at random (`crate::photo`); empty: procedural textures only.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub photographs: Vec<PathBuf>,
    /// Silhouettes, turning paths and occluders (`crate::variation`); none in the presets.
    #[serde(default, skip_serializing_if = "ObjectVariation::is_none")]
    pub variation: ObjectVariation,
}

/// How far the moving objects depart from the presets' boxes and discs on drifting paths.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", default, deny_unknown_fields)]
pub struct ObjectVariation {
    /// Share of the objects off the road cut to a silhouette (non-convex outline, thin parts,
    /// holes) of the same size instead of their box or disc.
    pub cutout_share: f32,
    /// Each path off the road turns at a rate drawn within ± this (rad per second of travel).
    pub turn_rate_rad_s: f32,
    /// Chance that one more object crosses in front of the filmed object, hiding it for a
    /// moment, off the road.
    pub occluder_chance: f32,
}

impl ObjectVariation {
    pub fn is_none(&self) -> bool {
        *self == ObjectVariation::default()
    }
}

/// Everything that determines a simulation besides the seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct SimConfig {
    /// Name of the preset this configuration started from.
    pub preset: String,
    pub sensor: SensorSize,
    pub intrinsics: Intrinsics,
    pub scene: SceneParams,
    #[serde(default)]
    pub events: EventModel,
}

impl SimConfig {
    /// The same camera with its resolution divided by `divisor` and the same field of view:
    /// small sensors keep tests and quick checks fast while the scene stays the preset's.
    pub fn at_reduced_resolution(mut self, divisor: u16) -> Self {
        let k = self.intrinsics;
        let scale = f32::from(divisor);
        self.sensor = SensorSize::new(self.sensor.width / divisor, self.sensor.height / divisor);
        self.intrinsics = Intrinsics {
            fx: k.fx / scale,
            fy: k.fy / scale,
            cx: k.cx / scale,
            cy: k.cy / scale,
        };
        self
    }
}
