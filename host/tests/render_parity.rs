//! Parity of the host renderer (core vertex stage + `TileRasterizer` + `ImageSink`) with an
//! independent full-frame reference rasterizer written here: f64 pose and projection, per-pixel
//! barycentrics, inclusive edges, z-buffer on 1/w, perspective-correct colour. The cropped template
//! at several poses and two image sizes must agree on >= 99% of covered pixels, colours within 2/255.

use gpmm_core::render::{Cull, ShLight};
use gpmm_host::mesh::template::{load_template, Template, TemplateOptions};
use gpmm_host::render::{to_u8, Background, Framing, Instance, RenderSettings, Renderer, View};
use std::path::PathBuf;

fn data_dir() -> Option<PathBuf> {
    gpmm_host::data::data_dir_for_tests()
}

fn template() -> Option<Template> {
    let dir = data_dir()?.join("template/lee-perry-smith");
    Some(load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &TemplateOptions::default()).unwrap())
}

/// The reference frame: RGBA8 with alpha 255 where covered.
fn reference(inst: &Instance, tris: &[[u32; 3]], view: View, framing: &Framing, s: &RenderSettings) -> Vec<[u8; 4]> {
    let (w, h) = (s.width as usize, s.height as usize);
    // Rotation R = Rz(roll) Ry(yaw) Rx(pitch), in f64, written out independently of the core.
    let (y, p, r) = (f64::from(view.yaw).to_radians(), f64::from(view.pitch).to_radians(), f64::from(view.roll).to_radians());
    let rz = [[r.cos(), -r.sin(), 0.0], [r.sin(), r.cos(), 0.0], [0.0, 0.0, 1.0]];
    let ry = [[y.cos(), 0.0, y.sin()], [0.0, 1.0, 0.0], [-y.sin(), 0.0, y.cos()]];
    let rx = [[1.0, 0.0, 0.0], [0.0, p.cos(), -p.sin()], [0.0, p.sin(), p.cos()]];
    let mul = |a: [[f64; 3]; 3], b: [[f64; 3]; 3]| a.map(|row| [0, 1, 2].map(|j| (0..3).map(|k| row[k] * b[k][j]).sum::<f64>()));
    let rot = mul(mul(rz, ry), rx);
    let apply = |v: [f64; 3]| [0, 1, 2].map(|i| rot[i][0] * v[0] + rot[i][1] * v[1] + rot[i][2] * v[2]);
    let c = framing.center.map(f64::from);
    let focal = f64::from(s.camera().focal);
    let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
    // Vertex normals (area-weighted, f64), rotated into camera space; shading via the SH light.
    let pos: Vec<[f64; 3]> = inst.positions.iter().map(|p| p.map(f64::from)).collect();
    let mut normals = vec![[0.0f64; 3]; pos.len()];
    for t in tris {
        let [a, b, cc] = t.map(|i| pos[i as usize]);
        let (u, v) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [cc[0] - a[0], cc[1] - a[1], cc[2] - a[2]]);
        let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        for i in t {
            for (acc, v) in normals[*i as usize].iter_mut().zip(n) {
                *acc += v;
            }
        }
    }
    struct V {
        x: f64,
        y: f64,
        iw: f64,
        col: [f64; 3],
    }
    let verts: Vec<V> = pos
        .iter()
        .zip(&normals)
        .zip(&inst.albedos)
        .map(|((p, n), a)| {
            let q = apply([p[0] - c[0], p[1] - c[1], p[2] - c[2]]);
            let wdepth = f64::from(framing.distance) - q[2];
            let nc = apply(*n);
            let e = s.light.irradiance(nc.map(|v| v as f32));
            V {
                x: cx + focal * q[0] / wdepth,
                y: cy - focal * q[1] / wdepth,
                iw: 1.0 / wdepth,
                col: [0, 1, 2].map(|k| f64::from(a[k]) * f64::from(e[k])),
            }
        })
        .collect();
    let mut depth = vec![0.0f64; w * h];
    let mut out = vec![[0u8; 4]; w * h];
    for t in tris {
        let [a, b, cc] = t.map(|i| &verts[i as usize]);
        let area = (b.x - a.x) * (cc.y - a.y) - (cc.x - a.x) * (b.y - a.y);
        // y down: area < 0 is counter-clockwise as viewed, i.e. a front face.
        if area >= 0.0 {
            continue;
        }
        let x0 = a.x.min(b.x).min(cc.x).floor().max(0.0) as usize;
        let x1 = (a.x.max(b.x).max(cc.x).ceil() as isize).min(w as isize - 1);
        let y0 = a.y.min(b.y).min(cc.y).floor().max(0.0) as usize;
        let y1 = (a.y.max(b.y).max(cc.y).ceil() as isize).min(h as isize - 1);
        if x1 < 0 || y1 < 0 {
            continue;
        }
        for py in y0..=y1 as usize {
            for px in x0..=x1 as usize {
                let (qx, qy) = (px as f64 + 0.5, py as f64 + 0.5);
                let l0 = ((b.x - qx) * (cc.y - qy) - (cc.x - qx) * (b.y - qy)) / area;
                let l1 = ((cc.x - qx) * (a.y - qy) - (a.x - qx) * (cc.y - qy)) / area;
                let l2 = 1.0 - l0 - l1;
                if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                    continue;
                }
                let ws = [l0 * a.iw, l1 * b.iw, l2 * cc.iw];
                let iw = ws[0] + ws[1] + ws[2];
                let i = py * w + px;
                if iw > depth[i] {
                    depth[i] = iw;
                    let col = [0, 1, 2].map(|k| ((ws[0] * a.col[k] + ws[1] * b.col[k] + ws[2] * cc.col[k]) / iw) as f32);
                    out[i] = [to_u8(col[0]), to_u8(col[1]), to_u8(col[2]), 255];
                }
            }
        }
    }
    out
}

struct Agreement {
    union: usize,
    coverage_agree: usize,
    shared: usize,
    color_close: usize,
    max_diff: u8,
}

fn compare(tile: &image::RgbaImage, reference: &[[u8; 4]]) -> Agreement {
    let mut a = Agreement { union: 0, coverage_agree: 0, shared: 0, color_close: 0, max_diff: 0 };
    for (p, r) in tile.pixels().zip(reference) {
        let (ct, cr) = (p[3] == 255, r[3] == 255);
        if !(ct || cr) {
            continue;
        }
        a.union += 1;
        if ct == cr {
            a.coverage_agree += 1;
            a.shared += 1;
            let d = (0..3).map(|k| p[k].abs_diff(r[k])).max().unwrap_or(0);
            a.max_diff = a.max_diff.max(d);
            if d <= 2 {
                a.color_close += 1;
            }
        }
    }
    a
}

const VIEWS: [View; 6] = [
    View { yaw: 0.0, pitch: 0.0, roll: 0.0 },
    View { yaw: 30.0, pitch: 0.0, roll: 0.0 },
    View { yaw: -30.0, pitch: 0.0, roll: 0.0 },
    View { yaw: 0.0, pitch: 15.0, roll: 0.0 },
    View { yaw: 0.0, pitch: 0.0, roll: 10.0 },
    View { yaw: 20.0, pitch: -10.0, roll: 5.0 },
];

#[test]
fn tile_renderer_matches_full_frame_reference_on_the_template() {
    let Some(t) = template() else { return };
    let inst = Instance::of_mesh(&t.mesh);
    let tris = &t.mesh.triangles;
    let mut renderer = Renderer::new();
    for size in [128u32, 256] {
        for view in VIEWS {
            let s = RenderSettings {
                width: size,
                height: size,
                light: ShLight::from_ambient_diffuse([0.6; 3], [0.4; 3], [-0.5, 0.4, 0.77]),
                background: Background::Transparent,
                ..RenderSettings::default()
            };
            let framing = Framing::fit(&inst.positions, &[view], &s).unwrap();
            let (img, stats) = renderer.render(&inst, tris, &framing.pose(view), &s).unwrap();
            let reference = reference(&inst, tris, view, &framing, &s);
            let a = compare(&img, &reference);
            let cov = a.coverage_agree as f64 / a.union as f64;
            let col = a.color_close as f64 / a.shared as f64;
            eprintln!(
                "{size}x{size} {view:?}: covered {} (tile) / union {}, coverage agreement {:.4}%, colours within 2/255 {:.4}% (max diff {}), {} drawn, {} culled",
                stats.covered_pixels,
                a.union,
                100.0 * cov,
                100.0 * col,
                a.max_diff,
                stats.drawn,
                stats.culled
            );
            assert!(a.union as f64 > 0.2 * f64::from(size * size), "the face covers a good part of the image");
            assert!(cov >= 0.99, "{size} {view:?}: coverage agreement {cov}");
            assert!(col >= 0.99, "{size} {view:?}: colour agreement {col}");
            assert_eq!(stats.covered_pixels as usize, img.pixels().filter(|p| p[3] == 255).count());
        }
    }
}

#[test]
fn back_face_culling_keeps_the_front_of_the_template() {
    let Some(t) = template() else { return };
    let inst = Instance::of_mesh(&t.mesh);
    let mut renderer = Renderer::new();
    for view in [View::FRONTAL, View::yaw(30.0)] {
        let s = RenderSettings { width: 128, height: 128, background: Background::Transparent, ..RenderSettings::default() };
        let framing = Framing::fit(&inst.positions, &[view], &s).unwrap();
        let pose = framing.pose(view);
        let render = |r: &mut Renderer, cull| r.render(&inst, &t.mesh.triangles, &pose, &RenderSettings { cull, ..s }).unwrap();
        let (front, fs) = render(&mut renderer, Cull::Clockwise);
        let (both, _) = render(&mut renderer, Cull::None);
        let (back, bs) = render(&mut renderer, Cull::CounterClockwise);
        // Front faces are the nearest surface: culling back faces changes (almost) nothing.
        let same = front.pixels().zip(both.pixels()).filter(|(a, b)| a == b).count();
        assert!(same as f64 >= 0.99 * f64::from(128 * 128), "{view:?}: {same}");
        // Most triangles of a face seen from the front face the camera.
        assert!(fs.drawn > 2 * bs.drawn, "{view:?}: front {} vs back {}", fs.drawn, bs.drawn);
        assert!(front.pixels().filter(|p| p[3] == 255).count() > back.pixels().filter(|p| p[3] == 255).count());
    }
}

#[test]
fn face_is_upright_and_centred() {
    let Some(t) = template() else { return };
    let inst = Instance::of_mesh(&t.mesh);
    let s = RenderSettings { width: 128, height: 128, background: Background::Transparent, ..RenderSettings::default() };
    let framing = Framing::fit(&inst.positions, &[View::FRONTAL], &s).unwrap();
    let (img, _) = Renderer::new().render(&inst, &t.mesh.triangles, &framing.pose(View::FRONTAL), &s).unwrap();
    let covered: Vec<(u32, u32)> = img.enumerate_pixels().filter(|(_, _, p)| p[3] == 255).map(|(x, y, _)| (x, y)).collect();
    let n = covered.len() as f64;
    let mx = covered.iter().map(|c| f64::from(c.0)).sum::<f64>() / n;
    let my = covered.iter().map(|c| f64::from(c.1)).sum::<f64>() / n;
    assert!((mx - 64.0).abs() < 8.0 && (my - 64.0).abs() < 12.0, "centroid ({mx}, {my})");
    // The fit leaves the margin free: nothing within 2 px of the border.
    assert!(covered.iter().all(|&(x, y)| x >= 2 && y >= 2 && x < 126 && y < 126));
    // Upright: the nose tip (landmark 30) is above the chin (8) in the image.
    let project = |v: u32| {
        let p = framing.pose(View::FRONTAL).transform_point(inst.positions[v as usize]);
        s.camera().project(p).unwrap()
    };
    assert!(project(t.landmarks[30]).y < project(t.landmarks[8]).y);
    // The subject's right eye corner (36) is on the image left.
    assert!(project(t.landmarks[36]).x < project(t.landmarks[45]).x);
}
