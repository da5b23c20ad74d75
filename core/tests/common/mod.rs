//! Shared test helpers: a full-frame sink, mesh generators, a tiny RNG and a reference rasterizer.
#![allow(dead_code, clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

use gpmm_core::geometry::Vec3;
use gpmm_core::render::{ProjectedVertex, Tile, TileSink, NO_TRIANGLE};

/// Writes every tile into a full image (host only; tests may allocate).
pub struct FrameSink {
    pub width: usize,
    pub height: usize,
    pub color: Vec<Vec3>,
    pub tri: Vec<u32>,
    pub inv_w: Vec<f32>,
    pub bary: Vec<[f32; 3]>,
    /// How many tiles wrote each pixel (must end as exactly 1).
    pub writes: Vec<u32>,
}

impl FrameSink {
    pub fn new(width: u32, height: u32) -> Self {
        let n = (width * height) as usize;
        Self {
            width: width as usize,
            height: height as usize,
            color: vec![[0.0; 3]; n],
            tri: vec![NO_TRIANGLE; n],
            inv_w: vec![0.0; n],
            bary: vec![[0.0; 3]; n],
            writes: vec![0; n],
        }
    }

    pub fn covered(&self) -> usize {
        self.tri.iter().filter(|&&t| t != NO_TRIANGLE).count()
    }
}

impl<const TW: usize, const TH: usize> TileSink<TW, TH> for FrameSink {
    fn consume(&mut self, tile: &Tile<TW, TH>) {
        let (x0, y0) = tile.origin();
        let (w, h) = tile.size();
        assert!(w as usize <= TW && h as usize <= TH && w > 0 && h > 0);
        for ly in 0..h as usize {
            for lx in 0..w as usize {
                let (x, y) = (x0 as usize + lx, y0 as usize + ly);
                assert!(x < self.width && y < self.height, "tile outside the image");
                let i = y * self.width + x;
                self.writes[i] += 1;
                match tile.fragment(lx, ly) {
                    Some(f) => {
                        assert!(tile.is_covered(lx, ly));
                        self.color[i] = f.color;
                        self.tri[i] = f.triangle;
                        self.inv_w[i] = f.inv_w;
                        self.bary[i] = f.bary;
                    }
                    None => {
                        assert!(!tile.is_covered(lx, ly));
                        assert_eq!(tile.triangles()[ly][lx], NO_TRIANGLE);
                        self.tri[i] = NO_TRIANGLE;
                    }
                }
            }
        }
    }
}

/// xorshift64*: deterministic test randomness without a dependency.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.uniform()
    }
}

/// A screen-space vertex at constant depth with a colour.
pub fn sv(x: f32, y: f32, inv_w: f32, color: Vec3) -> ProjectedVertex {
    ProjectedVertex { x, y, inv_w, color }
}

/// A `nx × ny` grid of quads covering `[x0, x1] × [y0, y1]` in screen space, interior vertices
/// jittered by up to `jitter` cells and snapped to multiples of `snap` pixels (so that many
/// edges and vertices fall exactly on pixel centres). Triangles are counter-clockwise on screen.
pub fn screen_grid(rng: &mut Rng, nx: usize, ny: usize, rect: [f32; 4], jitter: f32, snap: f32) -> (Vec<ProjectedVertex>, Vec<[u32; 3]>) {
    let [x0, y0, x1, y1] = rect;
    let (cw, ch) = ((x1 - x0) / nx as f32, (y1 - y0) / ny as f32);
    let mut v = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            let mut x = x0 + i as f32 * cw;
            let mut y = y0 + j as f32 * ch;
            if i > 0 && i < nx {
                x += rng.range(-jitter, jitter) * cw;
            }
            if j > 0 && j < ny {
                y += rng.range(-jitter, jitter) * ch;
            }
            if snap > 0.0 && i > 0 && i < nx && j > 0 && j < ny {
                x = (x / snap).round() * snap;
                y = (y / snap).round() * snap;
            }
            let c = [i as f32 / nx as f32, j as f32 / ny as f32, 0.5];
            v.push(sv(x, y, 0.01, c));
        }
    }
    let mut t = Vec::new();
    let id = |i: usize, j: usize| (j * (nx + 1) + i) as u32;
    for j in 0..ny {
        for i in 0..nx {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            // Screen y is down: (a, d, c) goes counter-clockwise as viewed.
            if (i + j) % 2 == 0 {
                t.push([a, d, c]);
                t.push([a, c, b]);
            } else {
                t.push([a, d, b]);
                t.push([b, d, c]);
            }
        }
    }
    (v, t)
}

/// Positions, albedos and triangles.
pub type Mesh = (Vec<Vec3>, Vec<Vec3>, Vec<[u32; 3]>);

/// A closed, star-shaped "head": a UV sphere with single poles, radius modulated by `bump`,
/// scaled to an ellipsoid; triangles counter-clockwise seen from outside. Albedo varies smoothly.
pub fn head_mesh(stacks: usize, slices: usize, bump: f32, rng: Option<&mut Rng>) -> Mesh {
    let mut pos = Vec::new();
    let scale = [75.0f32, 100.0, 85.0];
    let mut rng = rng;
    let mut push = |theta: f32, phi: f32, pos: &mut Vec<Vec3>| {
        let mut r = 1.0 + bump * (3.0 * theta).sin() * (2.0 * phi).cos();
        if let Some(g) = rng.as_deref_mut() {
            r *= 1.0 + g.range(-0.03, 0.03);
        }
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        pos.push([r * st * sp * scale[0], r * ct * scale[1], r * st * cp * scale[2]]);
    };
    push(0.0, 0.0, &mut pos);
    for i in 1..stacks {
        let theta = std::f32::consts::PI * i as f32 / stacks as f32;
        for j in 0..slices {
            let phi = 2.0 * std::f32::consts::PI * j as f32 / slices as f32;
            push(theta, phi, &mut pos);
        }
    }
    push(std::f32::consts::PI, 0.0, &mut pos);
    let south = (pos.len() - 1) as u32;
    let ring = |i: usize, j: usize| (1 + (i - 1) * slices + j % slices) as u32;
    let mut tris = Vec::new();
    for j in 0..slices {
        tris.push([0, ring(1, j), ring(1, j + 1)]);
        for i in 1..stacks - 1 {
            let (a, b, c, d) = (ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j));
            tris.push([a, d, c]);
            tris.push([a, c, b]);
        }
        tris.push([south, ring(stacks - 1, j + 1), ring(stacks - 1, j)]);
    }
    // Orient every triangle outward (star-shaped around the origin).
    for t in tris.iter_mut() {
        let [a, b, c] = t.map(|i| pos[i as usize]);
        let n = cross(sub(b, a), sub(c, a));
        let centroid = [a[0] + b[0] + c[0], a[1] + b[1] + c[1], a[2] + b[2] + c[2]];
        if dot(n, centroid) < 0.0 {
            t.swap(1, 2);
        }
    }
    let albedo =
        pos.iter().map(|p| [0.5 + 0.4 * (p[0] / 23.0).sin(), 0.5 + 0.4 * (p[1] / 31.0).cos(), 0.4 + 0.3 * (p[2] / 17.0).sin()]).collect();
    (pos, albedo, tris)
}

pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
pub fn dot(a: Vec3, b: Vec3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Independent full-frame reference: per-pixel float barycentrics (f64), inclusive edges,
/// back faces (clockwise on screen) culled, nearest `1/w` wins, perspective-correct colour.
pub struct Reference {
    pub color: Vec<Vec3>,
    pub tri: Vec<u32>,
}

pub fn reference_render(v: &[ProjectedVertex], tris: &[[u32; 3]], width: usize, height: usize) -> Reference {
    let n = width * height;
    let mut color = vec![[0.0f32; 3]; n];
    let mut tri = vec![NO_TRIANGLE; n];
    let mut depth = vec![0.0f64; n];
    for (id, t) in tris.iter().enumerate() {
        let p = t.map(|i| v[i as usize]);
        if p.iter().any(|q| q.inv_w <= 0.0) {
            continue;
        }
        let (x0, y0, x1, y1, x2, y2) = (p[0].x as f64, p[0].y as f64, p[1].x as f64, p[1].y as f64, p[2].x as f64, p[2].y as f64);
        let area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
        // y down: area > 0 is clockwise on screen (a back face).
        if area >= 0.0 {
            continue;
        }
        let minx = x0.min(x1).min(x2).floor().max(0.0) as usize;
        let maxx = (x0.max(x1).max(x2).ceil() as isize).min(width as isize - 1);
        let miny = y0.min(y1).min(y2).floor().max(0.0) as usize;
        let maxy = (y0.max(y1).max(y2).ceil() as isize).min(height as isize - 1);
        if maxx < 0 || maxy < 0 {
            continue;
        }
        for py in miny..=maxy as usize {
            for px in minx..=maxx as usize {
                let (qx, qy) = (px as f64 + 0.5, py as f64 + 0.5);
                let l0 = ((x1 - qx) * (y2 - qy) - (x2 - qx) * (y1 - qy)) / area;
                let l1 = ((x2 - qx) * (y0 - qy) - (x0 - qx) * (y2 - qy)) / area;
                let l2 = 1.0 - l0 - l1;
                if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                    continue;
                }
                let w = [l0 * p[0].inv_w as f64, l1 * p[1].inv_w as f64, l2 * p[2].inv_w as f64];
                let iw = w[0] + w[1] + w[2];
                let i = py * width + px;
                if iw > depth[i] {
                    depth[i] = iw;
                    tri[i] = id as u32;
                    for (ch, out) in color[i].iter_mut().enumerate() {
                        *out = ((w[0] * p[0].color[ch] as f64 + w[1] * p[1].color[ch] as f64 + w[2] * p[2].color[ch] as f64) / iw) as f32;
                    }
                }
            }
        }
    }
    Reference { color, tri }
}
