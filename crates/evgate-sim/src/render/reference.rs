//! The per-pixel path, which the row renderer must match: one ray, the nearest surface along
//! it, and its shading.

use super::*;

impl<'a> Snapshot<'a> {
    /// What the ray through pixel centre (x, y) hits.
    pub fn trace(&self, x: f32, y: f32) -> Hit {
        let (direction, nearest_depth, nearest_panel) = self.nearest_panel_along(x, y);
        let (located, material) = self.nearest_surface(
            x,
            direction,
            nearest_depth,
            nearest_panel,
            &self.all_objects,
        );
        Hit {
            surface: located.surface,
            point: located.point,
            depth: located.depth,
            log_intensity: material.map_or(LOG_DARK, |material| {
                self.shade(&material, direction, located.depth)
            }),
        }
    }

    /// [`Snapshot::trace`] without the shading.
    pub fn locate(&self, x: f32, y: f32) -> Located {
        let (direction, nearest_depth, nearest_panel) = self.nearest_panel_along(x, y);
        self.nearest_surface(
            x,
            direction,
            nearest_depth,
            nearest_panel,
            &self.all_objects,
        )
        .0
    }

    /// Where the ray through pixel (`x`, `y`) meets the static world (the point
    /// [`Snapshot::trace`] reports where no object is nearer), without shading it: what the
    /// motion probe needs, at a fraction of the cost.
    pub fn static_point(&self, x: f32, y: f32) -> Option<Vec3> {
        let (direction, depth, panel) = self.nearest_panel_along(x, y);
        panel.map(|_| self.camera.translation + direction * depth)
    }

    /// The ray direction through pixel (`x`, `y`), and the depth and index of the nearest
    /// panel along it (infinity and `None` where there is none).
    pub(super) fn nearest_panel_along(&self, x: f32, y: f32) -> (Vec3, f32, Option<usize>) {
        let scene = self.scene;
        let direction = self.camera.rotation.apply(scene.intrinsics.ray(x, y));
        let origin = self.camera.translation;
        let mut nearest_depth = f32::INFINITY;
        let mut nearest_panel = None;
        for i in 0..scene.panels.len() {
            if !self.panel_bounds[i].contains_column(x) {
                continue;
            }
            let plane = &self.panel_planes[i];
            // Parallel rays give an infinite or NaN distance, which fails the comparison.
            let distance = plane.offset / plane.normal.dot(direction);
            if !(distance > NEAR_PLANE_M && distance < nearest_depth) {
                continue;
            }
            let panel = &scene.panels[i];
            if let Some((hu, hv)) = panel.half_extent {
                let relative = origin + direction * distance - panel.origin;
                if relative.dot(panel.axis_u).abs() > hu || relative.dot(panel.axis_v).abs() > hv {
                    continue;
                }
            }
            nearest_depth = distance;
            nearest_panel = Some(i);
        }
        (direction, nearest_depth, nearest_panel)
    }

    /// Finishes a ray in `direction` through column `x` whose nearest static surface is
    /// `panel` at `panel_depth`: tests the moving objects (those listed in `objects`) and
    /// returns the nearest surface with its material (none where nothing is hit).
    pub(super) fn nearest_surface(
        &self,
        x: f32,
        direction: Vec3,
        panel_depth: f32,
        panel: Option<usize>,
        objects: &[usize],
    ) -> (Located, Option<Material>) {
        let scene = self.scene;
        let origin = self.camera.translation;
        let mut best = Located {
            surface: 0,
            point: Vec3::default(),
            depth: panel_depth,
        };
        let mut best_material = panel.map(|i| {
            let panel = &scene.panels[i];
            best.point = origin + direction * best.depth;
            let relative = best.point - panel.origin;
            Material {
                texture: panel.texture,
                texels_per_m: self.panel_planes[i].texels_per_m,
                u: relative.dot(panel.axis_u),
                v: relative.dot(panel.axis_v),
                normal: self.panel_planes[i].normal,
                log_illumination: self.panel_planes[i].log_illumination,
            }
        });
        if let Some(hit) = self.nearest_object(x, direction, best.depth, objects) {
            best.surface = hit.id;
            best.point = hit.point;
            best.depth = hit.depth;
            best_material = Some(hit.material);
        }
        (best, best_material)
    }

    /// The nearest of the moving objects listed in `objects` that the ray in `direction`
    /// through column `x` meets closer than `depth_limit`.
    pub(super) fn nearest_object(
        &self,
        x: f32,
        direction: Vec3,
        depth_limit: f32,
        objects: &[usize],
    ) -> Option<ObjectHit> {
        let scene = self.scene;
        let mut best: Option<ObjectHit> = None;
        let mut best_depth = depth_limit;
        for &i in objects {
            let placed = &self.objects[i];
            if !placed.bounds.contains_column(x) {
                continue;
            }
            let object = &scene.objects[i];
            let local_origin = placed.local_camera;
            let local_direction = placed.inverse_rotation.apply(direction);
            let Some(local_hit) = intersect_shape(&object.shape, local_origin, local_direction)
            else {
                continue;
            };
            if local_hit.distance >= best_depth {
                continue;
            }
            best_depth = local_hit.distance;
            let normal = placed.pose.rotation.apply(local_hit.normal);
            best = Some(ObjectHit {
                id: i as u16 + 1,
                point: local_origin + local_direction * local_hit.distance,
                depth: local_hit.distance,
                material: Material {
                    texture: object.texture,
                    texels_per_m: placed.texels_per_m,
                    u: local_hit.u,
                    v: local_hit.v,
                    normal,
                    log_illumination: placed.log_illumination[local_hit.axis],
                },
            });
        }
        best
    }

    pub(super) fn shade(&self, material: &Material, direction: Vec3, depth: f32) -> f32 {
        let texel = self.material_texel(material, direction, depth);
        self.scene.textures[texel.texture].sample(texel.u, texel.v, texel.footprint)
            + texel.log_illumination
    }

    /// The width of a pixel's footprint, in metres, on a surface of normal `normal` met at
    /// `depth` along `direction` (grazing angles capped at a cosine of 0.05).
    pub(super) fn metres_per_pixel(&self, normal: Vec3, direction: Vec3, depth: f32) -> f32 {
        let cos_incidence = (normal.dot(direction).abs() / direction.length()).max(0.05);
        depth / (self.scene.intrinsics.fx * cos_incidence)
    }

    /// What [`Snapshot::shade`] samples, and the light it adds.
    #[inline(always)]
    pub(super) fn material_texel(
        &self,
        material: &Material,
        direction: Vec3,
        depth: f32,
    ) -> PanelTexel {
        let metres_per_pixel = self.metres_per_pixel(material.normal, direction, depth);
        PanelTexel {
            texture: material.texture,
            u: material.u * material.texels_per_m,
            v: material.v * material.texels_per_m,
            footprint: metres_per_pixel * material.texels_per_m,
            log_illumination: material.log_illumination,
        }
    }
}
