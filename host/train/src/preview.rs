//! A picture grid of training scenes with their landmarks: what the networks learn from.

use crate::scene::{face_free_frame, photo_face_frame, render_scene, SceneSource};
use gpmm_host::render::Renderer;
use image::{imageops, Rgb, RgbImage};

/// Side of a grid cell (px); each frame is letterboxed into one.
const CELL: u32 = 160;

/// The whole preview of the stream `seed`, six frames a row: four rows of rendered scenes, two of
/// real faces (when some backgrounds are photos of people), two of face-free frames.
pub fn preview(source: SceneSource<'_>, seed: u64) -> RgbImage {
    let mut parts = vec![scene_grid(source, seed, 4, 6)];
    parts.extend(photo_face_grid(source, seed, 2, 6));
    parts.push(face_free_grid(source, seed, 2, 6));
    let mut all = RgbImage::new(6 * CELL, parts.iter().map(RgbImage::height).sum());
    let mut top = 0;
    for part in &parts {
        imageops::overlay(&mut all, part, 0, top);
        top += i64::from(part.height());
    }
    all
}

/// `rows × cols` scenes of the stream `seed`, each letterboxed into a 160 px cell, landmarks in green.
pub fn scene_grid(source: SceneSource<'_>, seed: u64, rows: u32, cols: u32) -> RgbImage {
    let mut renderer = Renderer::new();
    grid(rows, cols, |i| {
        let scene = render_scene(source, seed, i, &mut renderer)?;
        let mut frame = scene.frame;
        for p in &scene.landmarks {
            put(&mut frame, p[0], p[1], Rgb([0, 255, 0]));
        }
        Some(frame)
    })
}

/// `rows × cols` real faces of the stream `seed` as the finder sees them (photos of people among
/// the backgrounds), each with its target box in blue and the initializer's points in green;
/// `None` without photos of people.
pub fn photo_face_grid(source: SceneSource<'_>, seed: u64, rows: u32, cols: u32) -> Option<RgbImage> {
    source.backgrounds.filter(|b| b.faces() > 0)?;
    Some(grid(rows, cols, |i| {
        let view = photo_face_frame(source, seed, i)?;
        let (mut frame, [cx, cy, size]) = (view.image, view.square);
        for p in &view.points {
            put(&mut frame, p[0], p[1], Rgb([0, 255, 0]));
        }
        let half = size * 0.5;
        for k in 0..=(2.0 * size) as u32 {
            let t = -half + k as f32 * 0.5;
            for (x, y) in [(cx + t, cy - half), (cx + t, cy + half), (cx - half, cy + t), (cx + half, cy + t)] {
                put(&mut frame, x, y, Rgb([40, 120, 255]));
            }
        }
        Some(frame)
    }))
}

/// `rows × cols` face-free frames of the stream `seed` (views of the backgrounds), as the finder
/// learns "no face" from them.
pub fn face_free_grid(source: SceneSource<'_>, seed: u64, rows: u32, cols: u32) -> RgbImage {
    grid(rows, cols, |i| Some(face_free_frame(source, seed, i)))
}

/// A `rows × cols` grid of 160 px cells, cell `i` (row-major) showing `frame(i)` letterboxed, or
/// left dark when it gives none.
fn grid(rows: u32, cols: u32, mut frame: impl FnMut(u64) -> Option<RgbImage>) -> RgbImage {
    let mut grid = RgbImage::from_pixel(cols * CELL, rows * CELL, Rgb([24, 24, 24]));
    for i in 0..rows * cols {
        if let Some(f) = frame(u64::from(i)) {
            place(&mut grid, &f, i % cols, i / cols);
        }
    }
    grid
}

/// Colours pixel (x, y) of `frame` if it lies inside.
fn put(frame: &mut RgbImage, x: f32, y: f32, c: Rgb<u8>) {
    let (x, y) = (x.floor() as i64, y.floor() as i64);
    if x >= 0 && y >= 0 && (x as u32) < frame.width() && (y as u32) < frame.height() {
        frame.put_pixel(x as u32, y as u32, c);
    }
}

/// Draws `frame` letterboxed into cell (`col`, `row`) of `grid`.
fn place(grid: &mut RgbImage, frame: &RgbImage, col: u32, row: u32) {
    let s = CELL as f32 / frame.width().max(frame.height()) as f32;
    let (w, h) = (((frame.width() as f32 * s) as u32).max(1), ((frame.height() as f32 * s) as u32).max(1));
    let small = imageops::resize(frame, w, h, imageops::FilterType::Triangle);
    let (cx, cy) = (col * CELL + (CELL - w) / 2, row * CELL + (CELL - h) / 2);
    imageops::overlay(grid, &small, i64::from(cx), i64::from(cy));
}
