//! Cast shadows for the training scenes: the directional part of a scene's light taken away where
//! another part of the head (the nose, the brows, the hair, the chin over the neck) stands between
//! a vertex and the light. The renderer shades with low-order spherical harmonics, which darken a
//! surface turned from the light but cast no shadow; the independent test renders (a path-traced
//! sun) and photos have them, and the initializer read faces under an oblique sun worse
//! (docs/evaluation.md, stop 37). Opt-in (`gpmm train-init --shadows`): training with them did not
//! take that away.
//!
//! A depth map along the light (an orthographic view from the light's direction, cells of
//! [`CELL_MM`]) holds the surface nearest the light; a vertex more than a small bias behind it is in
//! shadow. Shadowed vertices keep only the light's ambient part: their albedo is scaled by the
//! ratio of ambient to full irradiance, so the renderer's shading of them is that of the
//! ambient light.

use crate::render::Instance;
use gpmm_core::geometry::mat_vec;
use gpmm_core::geometry::Vec3;
use gpmm_core::render::pose::Pose;
use gpmm_core::render::shading::vertex_normals;
use gpmm_core::render::ShLight;
use nalgebra::Vector3;

/// Side of a depth-map cell (mm): about a vertex spacing of the template's face.
pub const CELL_MM: f32 = 2.0;

/// Depth bias (mm) below which a vertex still counts as lit, plus [`SLOPE_BIAS`] cells per unit
/// of its surface's tangent against the light (grazing surfaces change depth fast across a cell).
const BIAS_MM: f32 = 2.0;
/// See [`BIAS_MM`].
const SLOPE_BIAS: f32 = 1.5;
/// Largest tangent [`SLOPE_BIAS`] counts: surfaces more grazing than this (about 83°) are taken
/// as lit, their shading already dark.
const MAX_SLOPE: f32 = 8.0;
/// Largest depth map side (cells); a scene larger than this many cells is coarsened.
const MAX_SIDE: usize = 512;

/// The light of a scene as drawn: an ambient part and one directional light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneLight {
    /// Ambient RGB.
    pub ambient: Vec3,
    /// Directional RGB.
    pub diffuse: Vec3,
    /// Direction toward the light, camera space (need not be unit length).
    pub direction: Vec3,
}

impl SceneLight {
    /// The spherical-harmonics light the renderer shades with.
    pub fn sh(&self) -> ShLight {
        ShLight::from_ambient_diffuse(self.ambient, self.diffuse, self.direction)
    }
}

/// Which of `points` (camera space) are lit by a light from direction `toward` (unit), given the
/// mesh `triangles` over them and each point's unit `normals`: `true` unless a triangle nearer
/// the light covers it.
pub fn lit(points: &[Vec3], normals: &[Vec3], triangles: &[[u32; 3]], toward: Vec3) -> Vec<bool> {
    let Some(d) = Vector3::from(toward).try_normalize(1e-9).filter(|d| d.iter().all(|c| c.is_finite())) else {
        return vec![true; points.len()];
    };
    // The light's image plane: any vector not along d, made perpendicular to it, and d × that.
    let helper = if d.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let Some(u) = d.cross(&helper).try_normalize(1e-9) else { return vec![true; points.len()] };
    let v = d.cross(&u);
    let light: Vec<[f32; 3]> = points.iter().map(|p| Vector3::from(*p)).map(|p| [p.dot(&u), p.dot(&v), p.dot(&d)]).collect();
    let finite = light.iter().filter(|q| q.iter().all(|c| c.is_finite()));
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for q in finite {
        lo = [lo[0].min(q[0]), lo[1].min(q[1])];
        hi = [hi[0].max(q[0]), hi[1].max(q[1])];
    }
    if !(lo[0] < hi[0] && lo[1] < hi[1]) {
        return vec![true; points.len()];
    }
    let cell = CELL_MM.max((hi[0] - lo[0]).max(hi[1] - lo[1]) / MAX_SIDE as f32);
    let (nx, ny) = (((hi[0] - lo[0]) / cell) as usize + 1, ((hi[1] - lo[1]) / cell) as usize + 1);
    let mut depth = vec![f32::NEG_INFINITY; nx * ny];
    let at = |x: f32, y: f32| -> Option<usize> {
        let (cx, cy) = (((x - lo[0]) / cell).floor(), ((y - lo[1]) / cell).floor());
        (cx >= 0.0 && cy >= 0.0 && (cx as usize) < nx && (cy as usize) < ny).then(|| cy as usize * nx + cx as usize)
    };
    for t in triangles {
        let (Some(a), Some(b), Some(c)) = (light.get(t[0] as usize), light.get(t[1] as usize), light.get(t[2] as usize)) else { continue };
        let area = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
        if !area.is_finite() {
            continue;
        }
        // The cells whose centres the triangle covers (and, for triangles under a cell, its corners).
        for p in [a, b, c] {
            if let Some(i) = at(p[0], p[1]) {
                depth[i] = depth[i].max(p[2]);
            }
        }
        if area.abs() < 1e-9 {
            continue;
        }
        let x0 = ((a[0].min(b[0]).min(c[0]) - lo[0]) / cell).floor().max(0.0) as usize;
        let x1 = (((a[0].max(b[0]).max(c[0]) - lo[0]) / cell).floor() as usize).min(nx - 1);
        let y0 = ((a[1].min(b[1]).min(c[1]) - lo[1]) / cell).floor().max(0.0) as usize;
        let y1 = (((a[1].max(b[1]).max(c[1]) - lo[1]) / cell).floor() as usize).min(ny - 1);
        for cy in y0..=y1 {
            for cx in x0..=x1 {
                let (px, py) = (lo[0] + (cx as f32 + 0.5) * cell, lo[1] + (cy as f32 + 0.5) * cell);
                let wa = ((b[0] - px) * (c[1] - py) - (c[0] - px) * (b[1] - py)) / area;
                let wb = ((c[0] - px) * (a[1] - py) - (a[0] - px) * (c[1] - py)) / area;
                let wc = 1.0 - wa - wb;
                if wa >= 0.0 && wb >= 0.0 && wc >= 0.0 {
                    let z = wa * a[2] + wb * b[2] + wc * c[2];
                    let i = cy * nx + cx;
                    depth[i] = depth[i].max(z);
                }
            }
        }
    }
    light
        .iter()
        .zip(normals)
        .map(|(q, n)| {
            let Some(i) = at(q[0], q[1]) else { return true };
            let cos = Vector3::from(*n).dot(&d).abs().clamp(0.05, 1.0);
            let slope = (1.0 - cos * cos).sqrt() / cos;
            q[2] >= depth[i] - BIAS_MM - SLOPE_BIAS * cell * slope.min(MAX_SLOPE)
        })
        .collect()
}

/// Darkens the albedos of `instance`'s vertices that the head, posed by `pose`, shadows from
/// `light`'s directional part: a shadowed vertex is shaded as by the ambient part alone.
/// Returns how many vertices are in shadow (0 when the light has no direction or the mesh
/// cannot be shaded).
pub fn cast_shadows(instance: &mut Instance, triangles: &[[u32; 3]], pose: &Pose, light: &SceneLight) -> usize {
    let n = instance.positions.len();
    let mut normals = vec![[0.0f32; 3]; n];
    if vertex_normals(&instance.positions, triangles, &mut normals).is_err() || light.diffuse.iter().all(|c| *c <= 0.0) {
        return 0;
    }
    let rot = pose.rotation();
    let points: Vec<Vec3> = instance.positions.iter().map(|p| pose.transform_point(*p)).collect();
    let normals: Vec<Vec3> = normals.into_iter().map(|n| mat_vec(&rot, n)).collect();
    let lit = lit(&points, &normals, triangles, light.direction);
    let (full, ambient) = (light.sh(), ShLight::ambient(light.ambient));
    let mut shadowed = 0;
    for ((albedo, n), on) in instance.albedos.iter_mut().zip(&normals).zip(lit) {
        if on {
            continue;
        }
        let (e, a) = (full.irradiance(*n), ambient.irradiance(*n));
        let mut darker = false;
        for ((v, e), a) in albedo.iter_mut().zip(e).zip(a) {
            if e > a && e > 1e-6 {
                *v *= a / e;
                darker = true;
            }
        }
        shadowed += usize::from(darker);
    }
    shadowed
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A flat floor of `side × side` vertices 2 mm apart in the plane z = 0 centred on the origin,
    /// facing +z, and above its middle a square lid at z = 40 mm: the floor's vertex ids, then the lid's four.
    fn floor_and_lid(side: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut points = Vec::new();
        for y in 0..side {
            for x in 0..side {
                points.push([x as f32 * 2.0 - (side - 1) as f32, y as f32 * 2.0 - (side - 1) as f32, 0.0]);
            }
        }
        let mut tris = Vec::new();
        for y in 0..side - 1 {
            for x in 0..side - 1 {
                let i = (y * side + x) as u32;
                let s = side as u32;
                tris.push([i, i + 1, i + s + 1]);
                tris.push([i, i + s + 1, i + s]);
            }
        }
        let base = points.len() as u32;
        points.extend([[-10.0, -10.0, 40.0], [10.0, -10.0, 40.0], [10.0, 10.0, 40.0], [-10.0, 10.0, 40.0]]);
        tris.push([base, base + 1, base + 2]);
        tris.push([base, base + 2, base + 3]);
        (points, tris)
    }

    #[test]
    fn a_lid_shadows_the_floor_under_it_along_the_light() {
        let side = 61;
        let (points, tris) = floor_and_lid(side);
        let normals = vec![[0.0, 0.0, 1.0]; points.len()];
        let vertex = |x: f32, y: f32| points.iter().position(|p| p[2] == 0.0 && (p[0] - x).abs() < 0.5 && (p[1] - y).abs() < 0.5).unwrap();
        // Light straight above: the floor under the lid is dark, the floor beyond it and the lid lit.
        let above = lit(&points, &normals, &tris, [0.0, 0.0, 1.0]);
        assert!(!above[vertex(0.0, 0.0)]);
        assert!(!above[vertex(6.0, -6.0)]);
        assert!(above[vertex(20.0, 0.0)]);
        assert!(above[vertex(0.0, -24.0)]);
        assert!(above[points.len() - 1]);
        // Light from 45° toward +x: the shadow moves 40 mm toward −x.
        let slant = lit(&points, &normals, &tris, [1.0, 0.0, 1.0]);
        assert!(slant[vertex(0.0, 0.0)]);
        assert!(!slant[vertex(-40.0 + 4.0, 0.0)]);
        assert!(slant[vertex(-40.0 + 16.0, 0.0)]);
        // The floor alone casts no shadow on itself at a grazing light.
        let floor = &tris[..tris.len() - 2];
        assert!(lit(&points, &normals, floor, [1.0, 0.2, 0.15]).iter().all(|l| *l));
        // No direction: everything lit.
        assert!(lit(&points, &normals, &tris, [0.0; 3]).iter().all(|l| *l));
    }

    #[test]
    fn shadowed_vertices_are_shaded_by_the_ambient_light_alone() {
        let (positions, tris) = floor_and_lid(41);
        let mut instance = Instance { albedos: vec![[0.5, 0.6, 0.7]; positions.len()], positions };
        let pose = Pose { yaw: 0.0, pitch: 0.0, roll: 0.0, translation: [0.0, 0.0, -500.0] };
        let light = SceneLight { ambient: [0.4; 3], diffuse: [0.8; 3], direction: [0.0, 0.0, 1.0] };
        let before = instance.albedos.clone();
        let shadowed = cast_shadows(&mut instance, &tris, &pose, &light);
        assert!(shadowed > 50 && shadowed < 200, "{shadowed}");
        let (full, amb) = (light.sh(), ShLight::ambient([0.4; 3]));
        let centre = instance.positions.iter().position(|p| p[0] == 0.0 && p[1] == 0.0 && p[2] == 0.0).unwrap();
        let n = [0.0, 0.0, 1.0];
        let seen = instance.albedos[centre][0] * full.irradiance(n)[0];
        assert!((seen - before[centre][0] * amb.irradiance(n)[0]).abs() < 1e-4);
        // Lit vertices keep their albedo; no light direction, no change.
        assert_eq!(instance.albedos[0], before[0]);
        let mut other = Instance { albedos: before.clone(), positions: instance.positions.clone() };
        let none = SceneLight { diffuse: [0.0; 3], ..light };
        assert_eq!(cast_shadows(&mut other, &tris, &pose, &none), 0);
        assert_eq!(other.albedos, before);
    }
}
