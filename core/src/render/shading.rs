//! Per-vertex stage: area-weighted vertex normals, SH Lambert shading and projection.
//!
//! All outputs go to caller-provided slices (one entry per vertex); nothing allocates.
//! Shading uses the normal rotated by the pose (the light is fixed in camera space), so a
//! light-only change needs [`shade_vertices`] again, a pose change both [`shade_vertices`] and
//! [`project_vertices`], and a shape change [`vertex_normals`] too ([`vertex_stage`] does all).

use crate::geometry::{mat_vec, TriIndex, Vec3};
use crate::render::camera::Camera;
use crate::render::light::{lambert_basis, ShLight, SH_COEFFS};
use crate::render::pose::Pose;

/// Why the vertex stage refused its input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum VertexError {
    /// Slices that need one entry per vertex have different lengths.
    LengthMismatch,
    /// A triangle refers to a vertex index `>=` the number of vertices.
    IndexOutOfRange,
    /// A position, albedo, pose, camera or light value is NaN or infinite.
    NonFinite,
}

/// One vertex after the per-vertex stage: screen position, reciprocal depth and shaded colour.
///
/// `inv_w == 0.0` marks a vertex in front of the camera's near plane (or otherwise not
/// projectable): the rasterizer skips every triangle using it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectedVertex {
    /// Pixel x (right; pixel centres at `i + 0.5`).
    pub x: f32,
    /// Pixel y (down; pixel centres at `j + 0.5`).
    pub y: f32,
    /// `1 / w` with `w` the camera-space depth in mm (`0.0`: not projectable).
    pub inv_w: f32,
    /// Shaded linear RGB: albedo ⊙ irradiance.
    pub color: Vec3,
}

impl ProjectedVertex {
    /// An unprojectable vertex (all zero).
    pub const INVALID: Self = Self { x: 0.0, y: 0.0, inv_w: 0.0, color: [0.0; 3] };
}

fn finite3(v: &Vec3) -> bool {
    v.iter().all(|c| c.is_finite())
}

fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Area-weighted unit vertex normals (model space) of a counter-clockwise-outward mesh.
///
/// Each triangle adds its unnormalized cross product `(b − a) × (c − a)` (twice its area times
/// its unit normal) to its three vertices; sums are then normalized. Vertices in no (non-degenerate)
/// triangle get `[0, 0, 0]`, which shades with the ambient (band-0) light only.
pub fn vertex_normals<I: TriIndex>(positions: &[Vec3], triangles: &[[I; 3]], normals: &mut [Vec3]) -> Result<(), VertexError> {
    if normals.len() != positions.len() {
        return Err(VertexError::LengthMismatch);
    }
    if !positions.iter().all(finite3) {
        return Err(VertexError::NonFinite);
    }
    let n = positions.len();
    if triangles.iter().any(|t| t.iter().any(|i| i.index() >= n)) {
        return Err(VertexError::IndexOutOfRange);
    }
    normals.fill([0.0; 3]);
    for t in triangles {
        let [ia, ib, ic] = t.map(TriIndex::index);
        let (Some(&a), Some(&b), Some(&c)) = (positions.get(ia), positions.get(ib), positions.get(ic)) else {
            continue;
        };
        let f = face_normal(a, b, c);
        for i in [ia, ib, ic] {
            if let Some(nv) = normals.get_mut(i) {
                nv[0] += f[0];
                nv[1] += f[1];
                nv[2] += f[2];
            }
        }
    }
    for nv in normals.iter_mut() {
        *nv = unit_or_zero(*nv);
    }
    Ok(())
}

/// A triangle's unnormalized normal `(b − a) × (c − a)`: twice its area times its unit normal,
/// what [`vertex_normals`] adds to each of its corners.
pub(crate) fn face_normal(a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    cross(sub(b, a), sub(c, a))
}

/// A summed vertex normal made unit, as [`vertex_normals`] does (zero when it is zero or not finite).
pub(crate) fn unit_or_zero(v: Vec3) -> Vec3 {
    let len2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    if len2 > 0.0 && len2.is_finite() {
        let inv = 1.0 / libm::sqrtf(len2);
        [v[0] * inv, v[1] * inv, v[2] * inv]
    } else {
        [0.0; 3]
    }
}

/// Sets `out[i].color = albedo[i] ⊙ light.irradiance(R · normal[i])` (R: the pose rotation).
pub fn shade_vertices(
    albedos: &[Vec3],
    normals: &[Vec3],
    pose: &Pose,
    light: &ShLight,
    out: &mut [ProjectedVertex],
) -> Result<(), VertexError> {
    if albedos.len() != out.len() || normals.len() != out.len() {
        return Err(VertexError::LengthMismatch);
    }
    if !albedos.iter().all(finite3) || !normals.iter().all(finite3) || !light.coeffs.iter().all(finite3) || !pose_finite(pose) {
        return Err(VertexError::NonFinite);
    }
    let r = pose.rotation();
    for ((o, a), n) in out.iter_mut().zip(albedos).zip(normals) {
        let e = light.irradiance(mat_vec(&r, *n));
        o.color = [a[0] * e[0], a[1] * e[1], a[2] * e[2]];
    }
    Ok(())
}

/// Caller-provided memory for shading a sequence of instances (one entry per vertex each): the
/// Lambert basis of each rotated normal and each vertex's irradiance, kept between calls of
/// [`ShadingCache::shade`].
#[derive(Debug)]
pub struct ShadingBuffers<'b> {
    /// Per vertex, [`lambert_basis`] of the rotated normal.
    pub basis: &'b mut [[f32; SH_COEFFS]],
    /// Per vertex, the irradiance.
    pub irradiance: &'b mut [Vec3],
}

/// [`shade_vertices`] that keeps what did not change: the rotated normals' Lambert bases (while
/// the normals and rotation stay) and the irradiance (while the light stays too), so a change of
/// colour costs three products per vertex and a change of light 27 multiply-adds. The same
/// arithmetic in the same order as [`shade_vertices`]: the same colours to the bit.
#[derive(Debug)]
pub struct ShadingCache<'b> {
    bufs: ShadingBuffers<'b>,
    basis_key: Option<(u64, [u32; 3])>,
    irradiance_key: Option<(u64, [u32; 3], [[u32; 3]; SH_COEFFS])>,
    finite_albedos: Option<u64>,
}

impl<'b> ShadingCache<'b> {
    /// A cache over `bufs`; `Err` unless both have `vertices` entries.
    pub fn new(bufs: ShadingBuffers<'b>, vertices: usize) -> Result<Self, VertexError> {
        if bufs.basis.len() != vertices || bufs.irradiance.len() != vertices {
            return Err(VertexError::LengthMismatch);
        }
        Ok(Self { bufs, basis_key: None, irradiance_key: None, finite_albedos: None })
    }

    /// Forgets what it holds.
    pub fn clear(&mut self) {
        self.basis_key = None;
        self.irradiance_key = None;
        self.finite_albedos = None;
    }

    /// [`shade_vertices`], where `albedos` and `normals` are named by `albedos_id` and
    /// `normals_id` (the same id must mean the same values in every call).
    #[allow(clippy::too_many_arguments)]
    pub fn shade(
        &mut self,
        albedos: &[Vec3],
        albedos_id: u64,
        normals: &[Vec3],
        normals_id: u64,
        pose: &Pose,
        light: &ShLight,
        out: &mut [ProjectedVertex],
    ) -> Result<(), VertexError> {
        let n = out.len();
        if albedos.len() != n || normals.len() != n || self.bufs.basis.len() != n || self.bufs.irradiance.len() != n {
            return Err(VertexError::LengthMismatch);
        }
        if !light.coeffs.iter().all(finite3) || !pose_finite(pose) {
            return Err(VertexError::NonFinite);
        }
        // Albedos already found finite are not checked again.
        if self.finite_albedos != Some(albedos_id) {
            if !albedos.iter().all(finite3) {
                return Err(VertexError::NonFinite);
            }
            self.finite_albedos = Some(albedos_id);
        }
        let angles = [pose.yaw, pose.pitch, pose.roll].map(f32::to_bits);
        if self.basis_key != Some((normals_id, angles)) {
            self.clear();
            if !normals.iter().all(finite3) {
                return Err(VertexError::NonFinite);
            }
            let r = pose.rotation();
            for (b, nv) in self.bufs.basis.iter_mut().zip(normals) {
                *b = lambert_basis(mat_vec(&r, *nv));
            }
            self.basis_key = Some((normals_id, angles));
        }
        let light_key = light.coeffs.map(|c| c.map(f32::to_bits));
        if self.irradiance_key != Some((normals_id, angles, light_key)) {
            for (e, b) in self.bufs.irradiance.iter_mut().zip(self.bufs.basis.iter()) {
                *e = light.irradiance_of(b);
            }
            self.irradiance_key = Some((normals_id, angles, light_key));
        }
        for ((o, a), e) in out.iter_mut().zip(albedos).zip(self.bufs.irradiance.iter()) {
            o.color = [a[0] * e[0], a[1] * e[1], a[2] * e[2]];
        }
        Ok(())
    }
}

fn pose_finite(pose: &Pose) -> bool {
    pose.yaw.is_finite() && pose.pitch.is_finite() && pose.roll.is_finite() && finite3(&pose.translation)
}

/// Sets `out[i].x, y, inv_w` from `camera.project(pose · positions[i])`; unprojectable vertices get `inv_w = 0`.
pub fn project_vertices(positions: &[Vec3], pose: &Pose, camera: &Camera, out: &mut [ProjectedVertex]) -> Result<(), VertexError> {
    if positions.len() != out.len() {
        return Err(VertexError::LengthMismatch);
    }
    let cam_ok = camera.focal.is_finite() && camera.principal.iter().all(|c| c.is_finite()) && camera.near.is_finite();
    if !positions.iter().all(finite3) || !pose_finite(pose) || !cam_ok {
        return Err(VertexError::NonFinite);
    }
    let r = pose.rotation();
    let t = pose.translation;
    for (o, p) in out.iter_mut().zip(positions) {
        let q = mat_vec(&r, *p);
        match camera.project([q[0] + t[0], q[1] + t[1], q[2] + t[2]]) {
            Some(s) => {
                o.x = s.x;
                o.y = s.y;
                o.inv_w = s.inv_w;
            }
            None => {
                o.x = 0.0;
                o.y = 0.0;
                o.inv_w = 0.0;
            }
        }
    }
    Ok(())
}

/// The whole per-vertex stage: normals into `normals` (scratch, one per vertex), then shading and projection into `out`.
///
/// # Examples
///
/// A grey triangle facing the camera 500 mm away under the frontal light, then rasterized with
/// back faces culled:
///
/// ```
/// use gpmm_core::render::{vertex_stage, Camera, Cull, Pose, ProjectedVertex, ShLight, Tile, TileRasterizer};
///
/// // Model space (mm, y up): counter-clockwise seen from +z, where the camera is.
/// let positions = [[0.0, 0.0, 0.0], [50.0, 0.0, 0.0], [0.0, 50.0, 0.0]];
/// let (albedos, triangles) = ([[0.5; 3]; 3], [[0u32, 1, 2]]);
/// let (pose, camera) = (Pose::frontal(500.0), Camera::centered(64, 64, 200.0));
/// let (mut normals, mut out) = ([[0.0; 3]; 3], [ProjectedVertex::INVALID; 3]);
/// vertex_stage(&positions, &albedos, &triangles, &pose, &camera, &ShLight::frontal(), &mut normals, &mut out)?;
///
/// // The origin lands on the image centre; 50 mm at 500 mm is 20 px with a 200 px focal length.
/// assert_eq!((out[0].x, out[0].y, out[0].inv_w), (32.0, 32.0, 1.0 / 500.0));
/// assert_eq!((out[1].x, out[2].y), (52.0, 12.0));
/// // Facing the light: irradiance 0.8 ambient + 0.2 diffuse, times the albedo.
/// assert!(out.iter().flat_map(|v| v.color).all(|c| (c - 0.5).abs() < 1e-5));
///
/// let mut ignore = |_: &Tile<16, 16>| {};
/// let stats = TileRasterizer::<16, 16, 8>::new().render(&out, &triangles, 64, 64, Cull::Clockwise, &mut ignore)?;
/// assert_eq!(stats.drawn, 1); // a front face
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn vertex_stage<I: TriIndex>(
    positions: &[Vec3],
    albedos: &[Vec3],
    triangles: &[[I; 3]],
    pose: &Pose,
    camera: &Camera,
    light: &ShLight,
    normals: &mut [Vec3],
    out: &mut [ProjectedVertex],
) -> Result<(), VertexError> {
    if albedos.len() != positions.len() || out.len() != positions.len() {
        return Err(VertexError::LengthMismatch);
    }
    vertex_normals(positions, triangles, normals)?;
    shade_vertices(albedos, normals, pose, light, out)?;
    project_vertices(positions, pose, camera, out)
}
