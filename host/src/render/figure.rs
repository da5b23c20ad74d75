//! Figures: labelled image grids (8×8 bitmap font), the sample grid of `gpmm sample -o`, the
//! paper's kernel figure of `gpmm figure kernels`, and compact PNG output.

use crate::gp::kernel::ModelKernel;
use crate::gp::lowrank::{NystromOptions, RankSpec};
use crate::gp::model::{build_model, BuildOptions, GpModel};
use crate::mesh::template::Template;
use crate::mesh::Mesh;
use crate::render::{Background, Framing, Instance, RenderError, RenderSettings, Renderer, View};
use gpmm_core::render::ShLight;
use image::{ImageEncoder, Rgba, RgbaImage};
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::path::Path;

/// Height of one text line at scale 1 (pixels).
pub const GLYPH: u32 = 8;

/// Width in pixels of `text` drawn at `scale`.
pub fn text_width(text: &str, scale: u32) -> u32 {
    text.chars().count() as u32 * GLYPH * scale
}

/// Draws ASCII `text` with its top-left corner at `(x, y)`, each font pixel a `scale × scale` block (clipped to the image).
pub fn draw_text(image: &mut RgbaImage, x: u32, y: u32, text: &str, scale: u32, color: Rgba<u8>) {
    let mut cx = x;
    for ch in text.chars() {
        let glyph = font8x8::legacy::BASIC_LEGACY.get(ch as usize).copied().unwrap_or([0; 8]);
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8u32 {
                if bits >> col & 1 == 0 {
                    continue;
                }
                for dy in 0..scale {
                    for dx in 0..scale {
                        let (px, py) = (cx + col * scale + dx, y + row as u32 * scale + dy);
                        if px < image.width() && py < image.height() {
                            image.put_pixel(px, py, color);
                        }
                    }
                }
            }
        }
        cx += GLYPH * scale;
    }
}

/// Layout of a labelled grid of equally sized cells.
#[derive(Debug, Clone, PartialEq)]
pub struct GridStyle {
    /// Figure background.
    pub background: Rgba<u8>,
    /// Text colour.
    pub ink: Rgba<u8>,
    /// Text scale (font pixels per glyph pixel).
    pub text_scale: u32,
    /// Space between cells and around the grid (pixels).
    pub gap: u32,
}

impl Default for GridStyle {
    fn default() -> Self {
        Self { background: Rgba([255, 255, 255, 255]), ink: Rgba([0, 0, 0, 255]), text_scale: 2, gap: 4 }
    }
}

/// Puts `rows` of equally sized images on a grid, with optional labels left of each row and above each column.
///
/// All cells must have the size of the first one (smaller ones are drawn at their size, larger ones clipped).
pub fn compose_grid(rows: &[Vec<RgbaImage>], row_labels: &[String], col_labels: &[String], style: &GridStyle) -> RgbaImage {
    let Some(first) = rows.iter().flatten().next() else {
        return RgbaImage::from_pixel(1, 1, style.background);
    };
    let (cw, ch) = first.dimensions();
    let cols = rows.iter().map(Vec::len).max().unwrap_or(0) as u32;
    let line = GLYPH * style.text_scale;
    let label_w = row_labels.iter().map(|l| text_width(l, style.text_scale)).max().map_or(0, |w| w + 2 * style.gap);
    let header_h = if col_labels.is_empty() { 0 } else { line + 2 * style.gap };
    let width = label_w + style.gap + cols * (cw + style.gap);
    let height = header_h + style.gap + rows.len() as u32 * (ch + style.gap);
    let mut out = RgbaImage::from_pixel(width, height, style.background);
    for (c, label) in col_labels.iter().enumerate().take(cols as usize) {
        let x0 = label_w + style.gap + c as u32 * (cw + style.gap);
        let x = x0 + cw.saturating_sub(text_width(label, style.text_scale)) / 2;
        draw_text(&mut out, x, style.gap, label, style.text_scale, style.ink);
    }
    for (r, row) in rows.iter().enumerate() {
        let y0 = header_h + style.gap + r as u32 * (ch + style.gap);
        if let Some(label) = row_labels.get(r) {
            draw_text(&mut out, style.gap, y0 + ch.saturating_sub(line) / 2, label, style.text_scale, style.ink);
        }
        for (c, cell) in row.iter().enumerate() {
            let x0 = label_w + style.gap + c as u32 * (cw + style.gap);
            blit(&mut out, cell, x0, y0, cw, ch);
        }
    }
    out
}

/// Stacks images vertically (left-aligned) on `background`.
pub fn stack_vertical(parts: &[RgbaImage], background: Rgba<u8>) -> RgbaImage {
    let width = parts.iter().map(|p| p.width()).max().unwrap_or(1).max(1);
    let height = parts.iter().map(|p| p.height()).sum::<u32>().max(1);
    let mut out = RgbaImage::from_pixel(width, height, background);
    let mut y = 0;
    for p in parts {
        blit(&mut out, p, 0, y, p.width(), p.height());
        y += p.height();
    }
    out
}

/// Alpha-composites `src` (clipped to `w × h`) onto `dst` at `(x0, y0)`.
fn blit(dst: &mut RgbaImage, src: &RgbaImage, x0: u32, y0: u32, w: u32, h: u32) {
    for y in 0..h.min(src.height()) {
        for x in 0..w.min(src.width()) {
            let (dx, dy) = (x0 + x, y0 + y);
            if dx >= dst.width() || dy >= dst.height() {
                continue;
            }
            let s = *src.get_pixel(x, y);
            let a = u32::from(s[3]);
            if a == 255 {
                dst.put_pixel(dx, dy, s);
            } else if a > 0 {
                let d = dst.get_pixel_mut(dx, dy);
                for (dc, sc) in d.0.iter_mut().zip(s.0).take(3) {
                    *dc = ((u32::from(sc) * a + u32::from(*dc) * (255 - a) + 127) / 255) as u8;
                }
                d[3] = d[3].max(s[3]);
            }
        }
    }
}

/// Writes a PNG with maximal compression (figures kept in the repository): RGB when every pixel
/// is opaque, RGBA otherwise.
pub fn save_png(image: &RgbaImage, path: &Path) -> Result<(), image::ImageError> {
    save_png_with(image, path, image::codecs::png::CompressionType::Best)
}

/// [`save_png`] with fast compression, for the pictures every fit writes (a third of the time of
/// `gpmm fit` went into compressing them at the best level).
pub fn save_png_fast(image: &RgbaImage, path: &Path) -> Result<(), image::ImageError> {
    save_png_with(image, path, image::codecs::png::CompressionType::Fast)
}

fn save_png_with(image: &RgbaImage, path: &Path, compression: image::codecs::png::CompressionType) -> Result<(), image::ImageError> {
    let file = std::fs::File::create(path).map_err(image::ImageError::IoError)?;
    let writer = std::io::BufWriter::new(file);
    let enc = image::codecs::png::PngEncoder::new_with_quality(writer, compression, image::codecs::png::FilterType::Adaptive);
    if image.pixels().all(|p| p[3] == 255) {
        let rgb = image::DynamicImage::ImageRgba8(image.clone()).to_rgb8();
        enc.write_image(rgb.as_raw(), rgb.width(), rgb.height(), image::ExtendedColorType::Rgb8)
    } else {
        enc.write_image(image.as_raw(), image.width(), image.height(), image::ExtendedColorType::Rgba8)
    }
}

/// Light that shows shape: ambient 0.55 plus 0.45 diffuse from the upper left front.
pub fn shape_light() -> ShLight {
    ShLight::from_ambient_diffuse([0.55; 3], [0.45; 3], [-0.45, 0.45, 0.77])
}

/// Renders each mesh (all of `model`'s topology; the mean first, typically) from each view: one grid row per view.
///
/// Every cell shares one [`Framing`], fitted to the model's mean shape in all views.
pub fn sample_grid(
    model: &GpModel,
    meshes: &[Mesh],
    labels: &[String],
    views: &[View],
    settings: &RenderSettings,
) -> Result<RgbaImage, RenderError> {
    let framing = Framing::fit(&model.shape.mean, views, settings)?;
    let instances: Vec<Instance> = meshes.iter().map(Instance::of_mesh).collect();
    let mut renderer = Renderer::new();
    let mut rows = Vec::with_capacity(views.len());
    for view in views {
        let mut row = Vec::with_capacity(instances.len());
        for inst in &instances {
            row.push(renderer.render(inst, &model.triangles, &framing.pose(*view), settings)?.0);
        }
        rows.push(row);
    }
    let row_labels: Vec<String> = views.iter().map(|v| format!("yaw {}", v.yaw)).collect();
    Ok(compose_grid(&rows, &row_labels, labels, &GridStyle::default()))
}

/// Settings of the kernel figure.
#[derive(Debug, Clone, PartialEq)]
pub struct KernelFigureOptions {
    /// Kernels to show, one block each.
    pub kernels: Vec<ModelKernel>,
    /// Shape rank of each model.
    pub rank_shape: usize,
    /// Colour rank of each model.
    pub rank_color: usize,
    /// Nyström points per model.
    pub nystrom_points: usize,
    /// Samples per model part.
    pub samples: usize,
    /// Seed of the sample coefficients (the same coefficients for every kernel).
    pub seed: u64,
    /// Side of one square cell (pixels).
    pub cell: u32,
    /// Blocks per figure row.
    pub columns: usize,
    /// View of the shape samples (a turned view shows depth in the silhouette).
    pub shape_view: View,
    /// Shape coefficients are drawn from N(0, shape_scale²): GP samples of the paper's kernels move a face by
    /// a few millimetres, which a 1.0 makes hard to see at thumbnail size; the figure labels the factor.
    pub shape_scale: f32,
}

impl Default for KernelFigureOptions {
    fn default() -> Self {
        Self {
            kernels: ModelKernel::ALL.to_vec(),
            rank_shape: 50,
            rank_color: 50,
            nystrom_points: 500,
            samples: 3,
            seed: 0,
            cell: 96,
            columns: 3,
            shape_view: View::FRONTAL,
            shape_scale: 2.0,
        }
    }
}

/// One kernel's block: a row of shape samples (mean colour, [`shape_light`], `opts.shape_view`) over a row of
/// albedo samples (mean shape, ambient white light, frontal), with the kernel name above.
pub fn kernel_block(model: &GpModel, name: &str, opts: &KernelFigureOptions) -> Result<RgbaImage, RenderError> {
    let base = RenderSettings {
        width: opts.cell,
        height: opts.cell,
        background: Background::Color([1.0; 3]),
        margin: 0.04,
        ..RenderSettings::default()
    };
    let framing = Framing::fit(&model.shape.mean, &[View::FRONTAL, opts.shape_view], &base)?;
    let pose = framing.pose(View::FRONTAL);
    let shape_pose = framing.pose(opts.shape_view);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(opts.seed);
    let mut renderer = Renderer::new();
    let mut shape_row = Vec::new();
    let mut color_row = Vec::new();
    let shape_settings = RenderSettings { light: shape_light(), ..base };
    let color_settings = RenderSettings { light: ShLight::ambient_white(), ..base };
    for _ in 0..opts.samples {
        let a: Vec<f32> = (0..model.shape.rank()).map(|_| opts.shape_scale * rng.sample::<f32, _>(StandardNormal)).collect();
        let inst = Instance::of_model(model, &a, &[])?;
        shape_row.push(renderer.render(&inst, &model.triangles, &shape_pose, &shape_settings)?.0);
    }
    for _ in 0..opts.samples {
        let b: Vec<f32> = (0..model.color.rank()).map(|_| rng.sample(StandardNormal)).collect();
        let inst = Instance::of_model(model, &[], &b)?;
        color_row.push(renderer.render(&inst, &model.triangles, &pose, &color_settings)?.0);
    }
    let style = GridStyle { gap: 2, ..GridStyle::default() };
    let grid = compose_grid(&[shape_row, color_row], &[], &[], &style);
    let mut title = RgbaImage::from_pixel(grid.width(), GLYPH * style.text_scale + 6, style.background);
    let x = grid.width().saturating_sub(text_width(name, style.text_scale)) / 2;
    draw_text(&mut title, x, 4, name, style.text_scale, style.ink);
    Ok(stack_vertical(&[title, grid], style.background))
}

/// Row label of the shape samples: `shape`, or `shape xS` when the coefficients are scaled.
pub fn shape_label(scale: f32) -> String {
    if scale == 1.0 {
        "shape".into()
    } else {
        format!("shape x{scale}")
    }
}

/// The paper's kernel figure: for each kernel, a model built from `template` and its [`kernel_block`];
/// blocks on a grid of `opts.columns`, rows labelled "shape" / "albedo" on the left.
///
/// `progress(done, total, next)` is called before each model build and once at the end (`next` = "").
pub fn kernel_figure(
    template: &Template,
    opts: &KernelFigureOptions,
    mut progress: impl FnMut(usize, usize, &str),
) -> Result<RgbaImage, RenderError> {
    let total = opts.kernels.len();
    let mut blocks = Vec::with_capacity(total);
    for (i, kernel) in opts.kernels.iter().enumerate() {
        progress(i, total, kernel.name());
        let build = BuildOptions {
            kernel: *kernel,
            hyperparameters: Default::default(),
            rank_shape: RankSpec::Count(opts.rank_shape),
            rank_color: RankSpec::Count(opts.rank_color),
            nystrom: NystromOptions { points: opts.nystrom_points.max(1), ..Default::default() },
        };
        let model = build_model(template, &build, |_, _, _| {});
        blocks.push(kernel_block(&model, kernel.name(), opts)?);
    }
    progress(total, total, "");
    let style = GridStyle::default();
    let columns = opts.columns.max(1);
    let rows: Vec<Vec<RgbaImage>> = blocks.chunks(columns).map(<[RgbaImage]>::to_vec).collect();
    let grid = compose_grid(&rows, &[], &[], &GridStyle { gap: 10, ..style.clone() });
    // Left margin with the row kinds, repeated for every block row.
    let Some(block) = blocks.first() else { return Ok(grid) };
    let shape_label = shape_label(opts.shape_scale);
    let label_w = text_width(&shape_label, style.text_scale).max(text_width("albedo", style.text_scale)) + 2 * style.gap;
    let mut out = RgbaImage::from_pixel(grid.width() + label_w, grid.height(), style.background);
    blit(&mut out, &grid, label_w, 0, grid.width(), grid.height());
    let title_h = GLYPH * style.text_scale + 6;
    let cell = opts.cell;
    for r in 0..rows.len() as u32 {
        let y0 = 10 + r * (block.height() + 10) + title_h + 2;
        for (k, label) in [shape_label.as_str(), "albedo"].iter().enumerate() {
            let y = y0 + k as u32 * (cell + 2) + cell.saturating_sub(GLYPH * style.text_scale) / 2;
            draw_text(&mut out, style.gap, y, label, style.text_scale, style.ink);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_and_grid_layout() {
        let mut img = RgbaImage::from_pixel(40, 10, Rgba([255; 4]));
        draw_text(&mut img, 0, 0, "Ab", 1, Rgba([0, 0, 0, 255]));
        assert!(img.pixels().any(|p| p[0] == 0));
        let cell = RgbaImage::from_pixel(10, 10, Rgba([9, 9, 9, 255]));
        let g = compose_grid(&[vec![cell.clone(), cell.clone()], vec![cell]], &["a".into()], &["x".into()], &GridStyle::default());
        assert_eq!(g.width(), 16 + 8 + 4 + 2 * 14);
        assert_eq!(g.height(), 16 + 8 + 4 + 2 * 14);
    }
}
