//! Silhouettes of fits and their overlap: the learning loop's first quality control compares where
//! the face was at the start of a fit with where the fit left it.

use image::RgbaImage;

use crate::fit::{morphable, FitBuffers, FitOptions, FitRunError, Params};
use crate::gp::model::GpModel;
use crate::render::{Background, HostRasterizer, ImageSink};
use gpmm_core::render::Cull;

/// The pixels a render covers (alpha above zero), row-major.
pub fn coverage(render: &RgbaImage) -> Vec<bool> {
    render.pixels().map(|p| p.0[3] > 0).collect()
}

/// Intersection over union of two masks of the same size (0 when both are empty).
pub fn iou(a: &[bool], b: &[bool]) -> f64 {
    let (mut both, mut either) = (0usize, 0usize);
    for (&x, &y) in a.iter().zip(b) {
        both += usize::from(x && y);
        either += usize::from(x || y);
    }
    if either == 0 {
        0.0
    } else {
        both as f64 / either as f64
    }
}

/// `params` of `model` rendered into the fit's working image (`settings.size` square, transparent
/// where the face does not cover).
pub fn render_params(model: &GpModel, params: &Params, settings: &FitOptions) -> Result<RgbaImage, FitRunError> {
    let mm = morphable(model)?;
    let (w, h) = (settings.size, settings.size);
    let core_error = |stage: &'static str| move |error| FitRunError::Core { stage, error };
    let mut buffers = FitBuffers::host(mm.vertices(), w, h);
    let mut inst = buffers.instance::<{ crate::fit::KS }, { crate::fit::KC }>().map_err(core_error("instance"))?;
    inst.update(&mm, params, w, h).map_err(core_error("silhouette"))?;
    let mut raster: Box<HostRasterizer> = Box::new(HostRasterizer::new());
    let mut sink = ImageSink::new(w, h, Background::Transparent);
    raster
        .render(inst.projected(), mm.triangles(), w, h, Cull::Clockwise, &mut sink)
        .map_err(|e| FitRunError::Core { stage: "silhouette", error: e.into() })?;
    Ok(sink.into_image())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overlap_of_masks() {
        let a = [true, true, false, false];
        let b = [true, false, true, false];
        assert!((iou(&a, &b) - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(iou(&a, &a), 1.0);
        assert_eq!(iou(&[false; 4], &[false; 4]), 0.0);
        let mut img = RgbaImage::new(2, 1);
        img.put_pixel(1, 0, image::Rgba([0, 0, 0, 7]));
        assert_eq!(coverage(&img), vec![false, true]);
    }
}
