//! Named scene presets: five mirror the paper's EVIMO sequences at 346×260 (boxes, floor, wall,
//! table, fast, tabletop) and one is a driving scene at 640×480.

use std::fmt;
use std::str::FromStr;

use evgate_core::SensorSize;
use serde::{Deserialize, Serialize};

use crate::camera::Intrinsics;
use crate::config::{Layout, ObjectVariation, SceneParams, SimConfig};
use crate::event_model::EventModel;
use crate::texture::TextureStyle;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    Boxes,
    Floor,
    Wall,
    Table,
    Fast,
    Tabletop,
    Driving,
}

/// A preset name that is not one of [`Preset::ALL`].
#[derive(Debug, thiserror::Error)]
#[error("unknown preset {name:?}; accepted: boxes, floor, wall, table, fast, tabletop, driving")]
pub struct UnknownPreset {
    pub name: String,
}

impl Preset {
    pub const ALL: [Preset; 7] = [
        Preset::Boxes,
        Preset::Floor,
        Preset::Wall,
        Preset::Table,
        Preset::Fast,
        Preset::Tabletop,
        Preset::Driving,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Preset::Boxes => "boxes",
            Preset::Floor => "floor",
            Preset::Wall => "wall",
            Preset::Table => "table",
            Preset::Fast => "fast",
            Preset::Tabletop => "tabletop",
            Preset::Driving => "driving",
        }
    }

    /// The full configuration of this preset.
    pub fn config(self) -> SimConfig {
        let davis346 = (
            SensorSize::new(346, 260),
            // DAVIS346 (18.5 µm pixels) behind a 4.5 mm lens, as in EVIMO.
            Intrinsics {
                fx: 243.0,
                fy: 243.0,
                cx: 173.0,
                cy: 130.0,
            },
        );
        let (sensor, intrinsics) = match self {
            Preset::Driving => (
                SensorSize::new(640, 480),
                Intrinsics {
                    fx: 460.0,
                    fy: 460.0,
                    cx: 320.0,
                    cy: 240.0,
                },
            ),
            _ => davis346,
        };
        let cardboard = TextureStyle {
            mean: 0.5,
            contrast: 0.7,
            noise: 0.6,
            shape_density: 1.2,
            stripes: 0.0,
            ..TextureStyle::default()
        };
        let office = TextureStyle {
            mean: 0.45,
            contrast: 0.8,
            noise: 0.5,
            shape_density: 0.8,
            stripes: 0.0,
            ..TextureStyle::default()
        };
        let carpet = TextureStyle {
            mean: 0.35,
            contrast: 0.8,
            noise: 1.0,
            shape_density: 1.0,
            stripes: 0.2,
            ..TextureStyle::default()
        };
        let poster = TextureStyle {
            mean: 0.5,
            contrast: 0.9,
            noise: 0.7,
            shape_density: 2.0,
            stripes: 0.0,
            ..TextureStyle::default()
        };
        let wood = TextureStyle {
            mean: 0.45,
            contrast: 0.75,
            noise: 0.6,
            shape_density: 0.7,
            stripes: 0.8,
            ..TextureStyle::default()
        };
        let toy = TextureStyle {
            mean: 0.55,
            contrast: 0.75,
            noise: 0.3,
            shape_density: 2.0,
            stripes: 0.3,
            ..TextureStyle::default()
        };
        let scene = match self {
            Preset::Boxes => SceneParams {
                layout: Layout::Room,
                min_objects: 1,
                max_objects: 3,
                object_speed_mps: 0.8,
                object_size_m: [0.2, 0.4],
                flat_object_share: 0.0,
                ego_rotation_rad_s: 0.6,
                ego_translation_mps: 0.15,
                drive_mps: 0.0,
                world_texture: office,
                object_texture: cardboard,
                photographs: Vec::new(),
                variation: ObjectVariation::default(),
            },
            Preset::Floor => SceneParams {
                layout: Layout::Floor,
                min_objects: 1,
                max_objects: 2,
                object_speed_mps: 0.6,
                object_size_m: [0.12, 0.3],
                flat_object_share: 0.0,
                ego_rotation_rad_s: 0.5,
                ego_translation_mps: 0.15,
                drive_mps: 0.0,
                world_texture: carpet,
                object_texture: cardboard,
                photographs: Vec::new(),
                variation: ObjectVariation::default(),
            },
            Preset::Wall => SceneParams {
                layout: Layout::Wall,
                min_objects: 1,
                max_objects: 2,
                object_speed_mps: 0.5,
                object_size_m: [0.1, 0.22],
                flat_object_share: 0.4,
                ego_rotation_rad_s: 0.5,
                ego_translation_mps: 0.12,
                drive_mps: 0.0,
                world_texture: poster,
                object_texture: toy,
                photographs: Vec::new(),
                variation: ObjectVariation::default(),
            },
            Preset::Table => SceneParams {
                layout: Layout::Table,
                min_objects: 1,
                max_objects: 2,
                object_speed_mps: 0.35,
                object_size_m: [0.08, 0.18],
                flat_object_share: 0.0,
                ego_rotation_rad_s: 0.5,
                ego_translation_mps: 0.1,
                drive_mps: 0.0,
                world_texture: wood,
                object_texture: toy,
                photographs: Vec::new(),
                variation: ObjectVariation::default(),
            },
            Preset::Fast => SceneParams {
                layout: Layout::Room,
                min_objects: 1,
                max_objects: 2,
                object_speed_mps: 3.0,
                object_size_m: [0.15, 0.3],
                flat_object_share: 0.3,
                ego_rotation_rad_s: 1.6,
                ego_translation_mps: 0.3,
                drive_mps: 0.0,
                world_texture: office,
                object_texture: toy,
                photographs: Vec::new(),
                variation: ObjectVariation::default(),
            },
            Preset::Tabletop => SceneParams {
                layout: Layout::Table,
                min_objects: 2,
                max_objects: 4,
                object_speed_mps: 0.2,
                object_size_m: [0.06, 0.14],
                flat_object_share: 0.2,
                ego_rotation_rad_s: 0.3,
                ego_translation_mps: 0.06,
                drive_mps: 0.0,
                world_texture: wood,
                object_texture: toy,
                photographs: Vec::new(),
                variation: ObjectVariation::default(),
            },
            Preset::Driving => SceneParams {
                layout: Layout::Road,
                min_objects: 3,
                max_objects: 6,
                object_speed_mps: 4.0,
                object_size_m: [1.6, 4.5],
                flat_object_share: 0.0,
                ego_rotation_rad_s: 0.15,
                ego_translation_mps: 0.2,
                drive_mps: 8.0,
                world_texture: office,
                object_texture: cardboard,
                photographs: Vec::new(),
                variation: ObjectVariation::default(),
            },
        };
        SimConfig {
            preset: self.name().to_string(),
            sensor,
            intrinsics,
            scene,
            events: EventModel::default(),
        }
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Preset {
    type Err = UnknownPreset;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| UnknownPreset {
                name: s.to_string(),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_lists_accepted() {
        for preset in Preset::ALL {
            assert_eq!(preset.name().parse::<Preset>().unwrap(), preset);
        }
        let err = "boxs".parse::<Preset>().unwrap_err().to_string();
        assert!(err.contains("boxs") && err.contains("tabletop"), "{err}");
    }

    #[test]
    fn evimo_presets_use_davis346_and_driving_vga() {
        assert_eq!(Preset::Table.config().sensor, SensorSize::new(346, 260));
        assert_eq!(Preset::Driving.config().sensor, SensorSize::new(640, 480));
    }
}
