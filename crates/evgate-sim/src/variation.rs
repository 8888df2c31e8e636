//! Object variation of suite version 5 ([`ObjectVariation`]): silhouettes cut out of flat
//! plates, paths that turn at a constant rate, and an occluder that crosses in front of the
//! filmed object at a drawn moment.
//!
//! Applied after the preset's scene is built, drawing from the scene's generator only when
//! asked for, so that every preset's scene stays as it was.

use rand::Rng;

use crate::config::{Layout, ObjectVariation, SceneParams};
use crate::linalg::Vec3;
use crate::motion::{EgoMotion, ObjectPath, Vec3Def, Wobble};
use crate::scene::{MovingObject, Shape};
use crate::silhouette::{Silhouette, SilhouetteKind};
use crate::world::{random_box, random_spin_axis, NewTexture, ObjectRegion};

/// When the occluder crosses the line of sight to the filmed object (seconds): inside the
/// three-second sequences of the suite, with history before and a future after.
const CROSSING_S: std::ops::Range<f32> = 0.6..2.4;

/// Closest an occluder comes to the camera at the crossing (metres).
const OCCLUDER_MIN_DISTANCE_M: f32 = 0.6;

/// Applies `variation` to `objects`; an occluder, when drawn, is appended.
pub(crate) fn vary_objects(
    params: &SceneParams,
    bounds: &ObjectRegion,
    ego: &EgoMotion,
    objects: &mut Vec<MovingObject>,
    new_texture: &mut NewTexture<'_>,
    rng: &mut impl Rng,
) {
    let variation = &params.variation;
    if variation.is_none() || params.layout == Layout::Road {
        return;
    }
    for object in objects.iter_mut() {
        if rng.gen_bool(variation.cutout_share.clamp(0.0, 1.0) as f64) {
            cut_out(object, bounds, rng);
        }
        if variation.turn_rate_rad_s > 0.0 {
            let limit = variation.turn_rate_rad_s;
            object.path.turn_rate = rng.gen_range(-limit..=limit);
        }
    }
    if !objects.is_empty() && rng.gen_bool(variation.occluder_chance.clamp(0.0, 1.0) as f64) {
        let occluder = occluder(
            params,
            variation,
            bounds,
            ego,
            &objects[0],
            new_texture,
            rng,
        );
        objects.push(occluder);
    }
}

/// Longest side of a shape (metres).
fn size(shape: &Shape) -> f32 {
    shape
        .corners()
        .iter()
        .map(|c| c.x.abs().max(c.y.abs()).max(c.z.abs()))
        .fold(0.0, f32::max)
        * 2.0
}

fn random_silhouette(size: f32, rng: &mut impl Rng) -> Shape {
    let kind = SilhouetteKind::ALL[rng.gen_range(0..SilhouetteKind::ALL.len())];
    Shape::Cutout(Silhouette::random(kind, size, rng))
}

/// Replaces the object's shape by a silhouette of the same size; an object resting on a
/// surface keeps resting on it.
fn cut_out(object: &mut MovingObject, bounds: &ObjectRegion, rng: &mut impl Rng) {
    let old_half_height = object.shape.half_height();
    object.shape = random_silhouette(size(&object.shape), rng);
    if bounds.ground_y.is_some() {
        let rise = old_half_height - object.shape.half_height();
        object.path.lower.0[1] += rise;
        object.path.upper.0[1] += rise;
    }
}

/// An object that crosses the line of sight from the camera to `filmed` between the two at a
/// drawn moment (flying), or passes in front of it on the supporting surface, moving across
/// the view in a straight line.
fn occluder(
    params: &SceneParams,
    variation: &ObjectVariation,
    bounds: &ObjectRegion,
    ego: &EgoMotion,
    filmed: &MovingObject,
    new_texture: &mut NewTexture<'_>,
    rng: &mut impl Rng,
) -> MovingObject {
    let [min_size, max_size] = params.object_size_m;
    let size = rng.gen_range(min_size..=max_size.max(min_size)) * rng.gen_range(0.8..1.0);
    let shape = if rng.gen_bool(variation.cutout_share.clamp(0.0, 1.0) as f64) {
        random_silhouette(size, rng)
    } else {
        random_box(size, rng)
    };
    let crossing_s = rng.gen_range(CROSSING_S);
    let target = filmed
        .path
        .pose(crossing_s, ego.drive_offset(crossing_s))
        .translation;
    let camera = ego.pose(crossing_s).translation;
    let sight = target - camera;
    let crossing = match bounds.ground_y {
        None => {
            let distance = sight.length();
            let share = rng
                .gen_range(0.45f32..0.75)
                .max(OCCLUDER_MIN_DISTANCE_M / distance)
                .min(0.9);
            camera + sight * share
        }
        Some(ground) => {
            let towards_camera = Vec3::new(-sight.x, 0.0, -sight.z);
            let room = towards_camera.length();
            let gap =
                ((size + self::size(&filmed.shape)) * rng.gen_range(0.6..0.9)).min(room * 0.7);
            let mut on_ground = target + towards_camera.normalized() * gap;
            on_ground.y = ground - shape.half_height();
            on_ground
        }
    };
    let level_sight = Vec3::new(sight.x, 0.0, sight.z).normalized();
    let side = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
    let heading = Vec3::new(-level_sight.z, 0.0, level_sight.x) * side;
    let margin = 0.5;
    let lower = Vec3::new(
        bounds.lower.x.min(crossing.x) - margin,
        if bounds.ground_y.is_some() {
            crossing.y
        } else {
            bounds.lower.y.min(crossing.y) - margin
        },
        bounds.lower.z.min(crossing.z) - margin,
    );
    let upper = Vec3::new(
        bounds.upper.x.max(crossing.x) + margin,
        if bounds.ground_y.is_some() {
            crossing.y
        } else {
            bounds.upper.y.max(crossing.y) + margin
        },
        bounds.upper.z.max(crossing.z) + margin,
    );
    // Slow down where needed so that the way to the crossing stays inside the bounds: the
    // path then never bounces before it crosses.
    let room_behind = [0, 2]
        .into_iter()
        .filter(|&axis| heading.axis(axis).abs() > 1e-6)
        .map(|axis| {
            let d = -heading.axis(axis);
            let bound = if d > 0.0 {
                upper.axis(axis)
            } else {
                lower.axis(axis)
            };
            (bound - crossing.axis(axis)) / d
        })
        .fold(f32::INFINITY, f32::min);
    let speed =
        (params.object_speed_mps * rng.gen_range(0.6..1.4)).min(0.95 * room_behind / crossing_s);
    let velocity = heading * speed;
    let flying = bounds.ground_y.is_none();
    let spin_axis = random_spin_axis(flying, rng);
    MovingObject {
        shape,
        path: ObjectPath {
            start: (crossing - velocity * crossing_s).into(),
            velocity: velocity.into(),
            speed_modulation: (0.0, 0.0, 0.0),
            wobble: [Wobble::default(), Wobble::default(), Wobble::default()],
            lower: lower.into(),
            upper: upper.into(),
            follows_drive: false,
            base_rotation: [
                rng.gen_range(-std::f32::consts::PI..std::f32::consts::PI),
                0.0,
                0.0,
            ],
            spin_axis: Vec3Def::from(spin_axis),
            spin_rate: rng.gen_range(-1.0..1.0),
            spin_wobble: Wobble::default(),
            turn_rate: 0.0,
        },
        texture: new_texture(&params.object_texture, rng),
        texel_m: size / 128.0,
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::camera::project_world;
    use crate::preset::Preset;
    use crate::render::Snapshot;
    use crate::world::build_scene;

    fn varied(preset: Preset, variation: ObjectVariation) -> crate::SimConfig {
        let mut config = preset.config().at_reduced_resolution(2);
        config.scene.variation = variation;
        config
    }

    #[test]
    fn the_occluder_hides_the_filmed_object_for_a_moment() {
        let variation = ObjectVariation {
            occluder_chance: 1.0,
            ..ObjectVariation::default()
        };
        let mut hidden_in = 0;
        for seed in 0..6 {
            let config = varied(Preset::Boxes, variation);
            let scene = build_scene(&config, &[], &mut ChaCha8Rng::seed_from_u64(seed));
            let preset = build_scene(
                &Preset::Boxes.config().at_reduced_resolution(2),
                &[],
                &mut ChaCha8Rng::seed_from_u64(seed),
            );
            assert_eq!(scene.objects.len(), preset.objects.len() + 1);
            let occluder = scene.objects.len() as u16;
            let (width, height) = (config.sensor.width as f32, config.sensor.height as f32);
            let hidden = (0..600).any(|i| {
                let t = CROSSING_S.start + i as f32 * 0.003;
                let centre = scene.objects[0].path.pose(t, Vec3::default()).translation;
                project_world(&scene.intrinsics, &scene.ego.pose(t), centre).is_some_and(
                    |(x, y)| {
                        (0.0..width).contains(&x)
                            && (0.0..height).contains(&y)
                            && Snapshot::new(&scene, t).trace(x.floor(), y.floor()).surface
                                == occluder
                    },
                )
            });
            hidden_in += hidden as usize;
        }
        // The filmed object may be out of view at the crossing (the camera's wobble).
        assert!(hidden_in >= 4, "hidden in {hidden_in} of 6 scenes");
    }

    #[test]
    fn without_variation_the_scene_is_the_presets() {
        for preset in [Preset::Floor, Preset::Wall] {
            let config = varied(preset, ObjectVariation::default());
            let a = build_scene(&config, &[], &mut ChaCha8Rng::seed_from_u64(3));
            let b = build_scene(
                &preset.config().at_reduced_resolution(2),
                &[],
                &mut ChaCha8Rng::seed_from_u64(3),
            );
            assert_eq!(a.objects.len(), b.objects.len());
            for (a, b) in a.objects.iter().zip(&b.objects) {
                assert_eq!((a.shape, &a.path), (b.shape, &b.path));
            }
        }
    }

    #[test]
    fn cut_out_objects_on_the_floor_still_rest_on_it() {
        let variation = ObjectVariation {
            cutout_share: 1.0,
            turn_rate_rad_s: 1.0,
            occluder_chance: 1.0,
        };
        for seed in 0..10 {
            let scene = build_scene(
                &varied(Preset::Floor, variation),
                &[],
                &mut ChaCha8Rng::seed_from_u64(seed),
            );
            let floor_y = 1.0;
            for object in &scene.objects {
                assert!(matches!(object.shape, Shape::Cutout(_)));
                let lowest = object.path.lower.0[1] + object.shape.half_height();
                assert!((lowest - floor_y).abs() < 1e-4, "rests at {lowest}");
                assert_eq!(object.path.lower.0[1], object.path.upper.0[1]);
            }
            assert!(scene.objects[..scene.objects.len() - 1].iter().all(|o| o
                .path
                .turn_rate
                .abs()
                <= 1.0));
        }
    }
}
