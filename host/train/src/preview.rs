//! A picture grid of training scenes with their landmarks: what the networks learn from.

use crate::scene::{render_scene, SceneSource};
use gpmm_host::render::Renderer;
use image::{imageops, Rgb, RgbImage};

/// `rows × cols` scenes of the stream `seed`, each letterboxed into a 160 px cell, landmarks in green.
pub fn scene_grid(source: SceneSource<'_>, seed: u64, rows: u32, cols: u32) -> RgbImage {
    const CELL: u32 = 160;
    let mut grid = RgbImage::from_pixel(cols * CELL, rows * CELL, Rgb([24, 24, 24]));
    let mut renderer = Renderer::new();
    for i in 0..rows * cols {
        let Some(scene) = render_scene(source, seed, u64::from(i), &mut renderer) else { continue };
        let mut frame = scene.frame.clone();
        for p in &scene.landmarks {
            let (x, y) = (p[0].floor() as i64, p[1].floor() as i64);
            if x >= 0 && y >= 0 && (x as u32) < frame.width() && (y as u32) < frame.height() {
                frame.put_pixel(x as u32, y as u32, Rgb([0, 255, 0]));
            }
        }
        let s = CELL as f32 / frame.width().max(frame.height()) as f32;
        let (w, h) = (((frame.width() as f32 * s) as u32).max(1), ((frame.height() as f32 * s) as u32).max(1));
        let small = imageops::resize(&frame, w, h, imageops::FilterType::Triangle);
        let (cx, cy) = ((i % cols) * CELL + (CELL - w) / 2, (i / cols) * CELL + (CELL - h) / 2);
        imageops::overlay(&mut grid, &small, i64::from(cx), i64::from(cy));
    }
    grid
}
