//! glTF input: the first mesh's triangles, albedo sampled from a texture at the UVs, vertices split at UV seams welded again.

use super::common::{ColorSource, MeshIoError};
use crate::mesh::Mesh;
use std::collections::HashMap;
use std::path::Path;

/// An RGB texture in [0,1] with bilinear lookup.
pub(super) struct Texture {
    width: usize,
    height: usize,
    rgb: Vec<[f32; 3]>,
}

impl Texture {
    fn from_image(img: image::DynamicImage) -> Self {
        let rgb = img.to_rgb32f();
        let (width, height) = (rgb.width() as usize, rgb.height() as usize);
        let rgb = rgb.pixels().map(|p| p.0).collect();
        Texture { width, height, rgb }
    }

    fn from_gltf(data: &gltf::image::Data) -> Option<Self> {
        use gltf::image::Format;
        let (w, h) = (data.width as usize, data.height as usize);
        let channels = match data.format {
            Format::R8 => 1,
            Format::R8G8 => 2,
            Format::R8G8B8 => 3,
            Format::R8G8B8A8 => 4,
            _ => return None,
        };
        if w == 0 || h == 0 || data.pixels.len() < w * h * channels {
            return None;
        }
        let rgb = data
            .pixels
            .chunks_exact(channels)
            .take(w * h)
            .map(|p| {
                let g = |k: usize| f32::from(p[k.min(channels - 1)]) / 255.0;
                if channels < 3 {
                    [g(0), g(0), g(0)]
                } else {
                    [g(0), g(1), g(2)]
                }
            })
            .collect();
        Some(Texture { width: w, height: h, rgb })
    }

    /// Bilinear sample at texture coordinates (u right, v up: row = (1 - v) * height), wrapping.
    fn sample(&self, u: f64, v: f64) -> [f64; 3] {
        let (w, h) = (self.width as f64, self.height as f64);
        let x = u * w - 0.5;
        let y = (1.0 - v) * h - 0.5;
        if !x.is_finite() || !y.is_finite() || self.rgb.is_empty() {
            return [0.0; 3];
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let wrap = |i: f64, n: usize| -> usize { (i.rem_euclid(n as f64) as usize).min(n - 1) };
        let (xa, xb) = (wrap(x0, self.width), wrap(x0 + 1.0, self.width));
        let (ya, yb) = (wrap(y0, self.height), wrap(y0 + 1.0, self.height));
        let px = |xi: usize, yi: usize| self.rgb.get(yi * self.width + xi).copied().unwrap_or([0.0; 3]);
        let (p00, p10, p01, p11) = (px(xa, ya), px(xb, ya), px(xa, yb), px(xb, yb));
        let mut out = [0.0; 3];
        for k in 0..3 {
            let top = f64::from(p00[k]) * (1.0 - fx) + f64::from(p10[k]) * fx;
            let bottom = f64::from(p01[k]) * (1.0 - fx) + f64::from(p11[k]) * fx;
            out[k] = (top * (1.0 - fy) + bottom * fy).clamp(0.0, 1.0);
        }
        out
    }
}

/// Reads an image file as a texture; errors name the image.
pub(super) fn read_texture(path: &Path) -> Result<Texture, MeshIoError> {
    let reader = image::ImageReader::open(path)
        .map_err(|e| MeshIoError::texture(path, e.to_string()))?
        .with_guessed_format()
        .map_err(|e| MeshIoError::texture(path, e.to_string()))?;
    let img = reader.decode().map_err(|e| MeshIoError::texture(path, e.to_string()))?;
    if img.width() == 0 || img.height() == 0 {
        return Err(MeshIoError::texture(path, "the image is empty"));
    }
    Ok(Texture::from_image(img))
}

/// A glTF primitive's vertices before welding.
#[derive(Default)]
pub(super) struct RawVertices {
    positions: Vec<[f64; 3]>,
    colors: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
}

type Mat4 = [[f64; 4]; 4];

pub(super) fn mat_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    // Column-major like glTF: m[col][row].
    let mut out = [[0.0; 4]; 4];
    for (c, col) in out.iter_mut().enumerate() {
        for (r, v) in col.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    out
}

pub(super) fn transform_point(m: &Mat4, p: [f32; 3]) -> [f64; 3] {
    let p = [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])];
    let mut out = [0.0; 3];
    for (r, o) in out.iter_mut().enumerate() {
        *o = m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r];
    }
    let w = m[0][3] * p[0] + m[1][3] * p[1] + m[2][3] * p[2] + m[3][3];
    if w != 0.0 && w != 1.0 {
        for o in out.iter_mut() {
            *o /= w;
        }
    }
    out
}

const IDENTITY: Mat4 = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

pub(super) fn read_gltf(path: &Path, texture: Option<&Path>, default_color: Option<[f64; 3]>) -> Result<(Mesh, ColorSource), MeshIoError> {
    let bytes = std::fs::read(path).map_err(|e| MeshIoError::read(path, e))?;
    // The texture override is read first so that an unreadable texture is reported as such.
    let override_tex = match texture {
        Some(t) => Some(read_texture(t)?),
        None => None,
    };
    // The gltf crate validates documents, but guard against a panic on malformed data anyway.
    let result =
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read_gltf_inner(path, &bytes, override_tex, texture, default_color)));
    match result {
        Ok(r) => r,
        Err(_) => Err(MeshIoError::gltf(path, "malformed data")),
    }
}

pub(super) fn read_gltf_inner(
    path: &Path,
    bytes: &[u8],
    override_tex: Option<Texture>,
    texture_path: Option<&Path>,
    default_color: Option<[f64; 3]>,
) -> Result<(Mesh, ColorSource), MeshIoError> {
    let gltf::Gltf { document, blob } = gltf::Gltf::from_slice(bytes).map_err(|e| MeshIoError::gltf(path, e.to_string()))?;
    let base = path.parent();
    let buffers = gltf::import_buffers(&document, base, blob).map_err(|e| MeshIoError::gltf(path, format!("cannot load buffers: {e}")))?;

    // Collect (mesh, world transform) pairs: the default scene, else every mesh untransformed.
    let mut instances: Vec<(gltf::Mesh, Mat4)> = Vec::new();
    let scene = document.default_scene().or_else(|| document.scenes().next());
    if let Some(scene) = scene {
        let mut visited = vec![false; document.nodes().len()];
        let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, IDENTITY)).collect();
        while let Some((node, parent)) = stack.pop() {
            match visited.get_mut(node.index()) {
                Some(v) if !*v => *v = true,
                _ => continue,
            }
            let local = node.transform().matrix();
            let local: Mat4 = local.map(|c| c.map(f64::from));
            let world = mat_mul(&parent, &local);
            if let Some(mesh) = node.mesh() {
                instances.push((mesh, world));
            }
            for child in node.children() {
                stack.push((child, world));
            }
        }
        // Keep a deterministic order (by node traversal is fine, but sort by mesh index for clarity).
        instances.sort_by_key(|(m, _)| m.index());
    } else {
        instances = document.meshes().map(|m| (m, IDENTITY)).collect();
    }
    if instances.is_empty() {
        return Err(MeshIoError::gltf(path, "the file contains no meshes"));
    }

    // Embedded images are decoded only when needed.
    let mut images: Option<Vec<gltf::image::Data>> = None;
    let mut source = ColorSource::Vertex;
    let mut raw = RawVertices::default();
    for (mesh, world) in &instances {
        for prim in mesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                log::warn!(
                    "{}: skipping a primitive of mesh {} with mode {:?} (only triangles are read)",
                    path.display(),
                    mesh.index(),
                    prim.mode()
                );
                continue;
            }
            let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
            let positions: Vec<[f64; 3]> = reader
                .read_positions()
                .ok_or_else(|| MeshIoError::gltf(path, "a primitive has no POSITION"))?
                .map(|p| transform_point(world, p))
                .collect();
            let n = positions.len();
            let indices: Vec<u32> = match reader.read_indices() {
                Some(ix) => ix.into_u32().collect(),
                None => (0..n as u32).collect(),
            };
            if !indices.chunks_exact(3).remainder().is_empty() {
                return Err(MeshIoError::gltf(path, format!("a primitive has {} indices, not a multiple of 3", indices.len())));
            }
            // Colours of this primitive.
            let tex_info = prim.material().pbr_metallic_roughness().base_color_texture();
            let set = tex_info.as_ref().map_or(0, |t| t.tex_coord());
            let uvs: Option<Vec<[f32; 2]>> = reader.read_tex_coords(set).map(|t| t.into_f32().collect());
            let colors: Vec<[f64; 3]> = if let (Some(tex), Some(uvs)) = (&override_tex, &uvs) {
                source = ColorSource::Texture(texture_path.map(|p| p.display().to_string()).unwrap_or_default());
                sample_all(path, tex, uvs, n)?
            } else if let (Some(info), Some(uvs), None) = (&tex_info, &uvs, &override_tex) {
                if images.is_none() {
                    images = Some(
                        gltf::import_images(&document, base, &buffers)
                            .map_err(|e| MeshIoError::gltf(path, format!("cannot load images: {e}")))?,
                    );
                }
                let img_index = info.texture().source().index();
                let tex = images
                    .as_ref()
                    .and_then(|imgs| imgs.get(img_index))
                    .and_then(Texture::from_gltf)
                    .ok_or_else(|| MeshIoError::gltf(path, format!("image {img_index} has an unsupported format")))?;
                source = ColorSource::Texture(format!("{}#image{img_index}", path.display()));
                sample_all(path, &tex, uvs, n)?
            } else if let Some(cols) = reader.read_colors(0) {
                let cols: Vec<[f64; 3]> = cols.into_rgb_f32().map(|c| c.map(f64::from)).collect();
                if cols.len() != n {
                    return Err(MeshIoError::gltf(path, "COLOR_0 and POSITION counts differ"));
                }
                cols
            } else if let Some(c) = default_color {
                source = ColorSource::Default;
                vec![c; n]
            } else if override_tex.is_some() {
                return Err(MeshIoError::gltf(path, "a primitive has no TEXCOORD_0 to sample the texture at"));
            } else {
                return Err(MeshIoError::NoTexture { path: path.to_path_buf() });
            };
            let offset = raw.positions.len() as u64;
            for (t, tri) in indices.chunks_exact(3).enumerate() {
                let mut out = [0u32; 3];
                for k in 0..3 {
                    let i = tri[k];
                    if i as usize >= n {
                        return Err(MeshIoError::invalid(
                            path,
                            format!("triangle {t} of mesh {} refers to vertex {i} but the primitive has {n} vertices", mesh.index()),
                        ));
                    }
                    out[k] = u32::try_from(offset + u64::from(i)).map_err(|_| MeshIoError::gltf(path, "too many vertices"))?;
                }
                raw.triangles.push(out);
            }
            raw.positions.extend(positions);
            raw.colors.extend(colors);
        }
    }
    for (i, p) in raw.positions.iter().enumerate() {
        if p.iter().any(|v| !v.is_finite()) {
            return Err(MeshIoError::invalid(path, format!("vertex {i} has a non-finite coordinate")));
        }
    }
    Ok((weld(raw), source))
}

pub(super) fn sample_all(path: &Path, tex: &Texture, uvs: &[[f32; 2]], n: usize) -> Result<Vec<[f64; 3]>, MeshIoError> {
    if uvs.len() != n {
        return Err(MeshIoError::gltf(path, "TEXCOORD and POSITION counts differ"));
    }
    Ok(uvs.iter().map(|uv| tex.sample(f64::from(uv[0]), f64::from(uv[1]))).collect())
}

/// Welds vertices at the same position (within 1e-6 of the bounding-box
/// diagonal); the result is ordered lexicographically by position and colours
/// of merged vertices are averaged.
pub(super) fn weld(raw: RawVertices) -> Mesh {
    let n = raw.positions.len();
    if n == 0 {
        return Mesh { positions: raw.positions, colors: raw.colors, triangles: raw.triangles };
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &raw.positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    let tol = 1e-6 * diag;

    // Cluster vertices within `tol` (per axis) with union-find over a hash grid
    // of cell size `tol`: near vertices are in the same or a neighbouring cell.
    let cmp = |a: &[f64; 3], b: &[f64; 3]| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])).then(a[2].total_cmp(&b[2]));
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| cmp(&raw.positions[a], &raw.positions[b]).then(a.cmp(&b)));
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let cell = if tol > 0.0 { tol } else { 1.0 };
    let key = |p: &[f64; 3]| p.map(|v| (v / cell).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::with_capacity(n);
    for &a in &order {
        let pa = raw.positions[a];
        let ka = key(&pa);
        for dx in -1..=1i64 {
            for dy in -1..=1i64 {
                for dz in -1..=1i64 {
                    let kb = [ka[0].saturating_add(dx), ka[1].saturating_add(dy), ka[2].saturating_add(dz)];
                    let Some(list) = grid.get(&kb) else { continue };
                    for &b in list {
                        let pb = raw.positions[b];
                        if (0..3).all(|k| (pb[k] - pa[k]).abs() <= tol) {
                            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                            if ra != rb {
                                parent[ra.max(rb)] = ra.min(rb);
                            }
                        }
                    }
                }
            }
        }
        grid.entry(ka).or_default().push(a);
    }
    // Each cluster is represented by its smallest position; order clusters by that.
    let mut rep_pos: HashMap<usize, [f64; 3]> = HashMap::new();
    for &i in &order {
        let r = find(&mut parent, i);
        rep_pos.entry(r).or_insert(raw.positions[i]);
    }
    let mut roots: Vec<(usize, [f64; 3])> = rep_pos.into_iter().collect();
    roots.sort_by(|a, b| cmp(&a.1, &b.1).then(a.0.cmp(&b.0)));
    let mut new_index: HashMap<usize, u32> = HashMap::with_capacity(roots.len());
    for (k, (r, _)) in roots.iter().enumerate() {
        new_index.insert(*r, k as u32);
    }
    let m = roots.len();
    let positions: Vec<[f64; 3]> = roots.iter().map(|(_, p)| *p).collect();
    let mut sums = vec![[0.0; 3]; m];
    let mut counts = vec![0usize; m];
    let mut map = vec![0u32; n];
    for (i, (slot, color)) in map.iter_mut().zip(&raw.colors).enumerate() {
        let r = find(&mut parent, i);
        let k = new_index.get(&r).copied().unwrap_or(0);
        *slot = k;
        let ku = k as usize;
        counts[ku] += 1;
        for (sum, c) in sums[ku].iter_mut().zip(color) {
            *sum += c;
        }
    }
    let colors = sums.iter().zip(&counts).map(|(s, &c)| s.map(|v| v / c.max(1) as f64)).collect();
    let triangles = raw.triangles.iter().map(|t| t.map(|i| map[i as usize])).collect();
    Mesh { positions, colors, triangles }
}
