//! The image chain's first steps at half the working resolution
//! ([`ImageSettings::coarse_steps`](crate::fit::settings::ImageSettings)): the same posterior's
//! terms on the target's 2 × 2 block means ([`TargetImage::half`]), with the landmarks, their σ,
//! the focal length and its prior halved with it, so that the landmark term is the same and a
//! step renders and compares a quarter of the pixels. The pose, shape, colour and light move as
//! they would at full resolution; only the image term is coarser (a quarter of the pixels, each
//! a block's mean), and the full-resolution steps that follow start from the best sample found.

use crate::error::FitError;
use crate::fit::chain::observer::ChainObserver;
use crate::fit::chain::proposal::{Mixture, StandardProposal};
use crate::fit::chain::{image_chain, FitResult, ImageProblem, Problem};
use crate::fit::likelihood::image::BackgroundModel;
use crate::fit::likelihood::pixel::GaussianPixel;
use crate::fit::settings::ProposalSettings;
use crate::geometry::TriIndex;
use crate::model::instance::Instance;
use crate::model::params::FitParams;
use crate::model::MAX_LANDMARKS;
use crate::render::TileRasterizer;
use rand_core::Rng;

/// Runs `steps` image-chain steps of `problem` and `image` (full resolution) at half resolution
/// from `from` (borrowed to halve its focal length, then restored), with the mixture of
/// `proposals` for the half-size image. The result's samples are full-resolution parameters
/// (their focal length doubled back); its log posteriors are the half-resolution chain's.
/// `BadConfig` for an image smaller than 2 × 2. (Inlined: its locals then share the caller's
/// stack with those of the full-resolution steps, which a device's landmark-free fit needs.)
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn half_resolution_chain<R, I, O, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize>(
    problem: &Problem<'_, I, StandardProposal>,
    image: &ImageProblem<'_, GaussianPixel, BackgroundModel>,
    proposals: &ProposalSettings,
    from: &mut FitParams<KS, KC>,
    steps: u32,
    instance: &mut Instance<'_, KS, KC>,
    raster: &mut TileRasterizer<TW, TH, BIN>,
    rng: &mut R,
    observer: O,
) -> Result<FitResult<KS, KC>, FitError>
where
    R: Rng + ?Sized,
    I: TriIndex,
    O: ChainObserver,
{
    let target = image.image.half()?;
    let (w, h) = (target.width(), target.height());
    let mut points = [[0.0f32; 2]; MAX_LANDMARKS];
    let landmarks = problem.landmarks.scaled(0.5, &mut points)?;
    let prior = crate::fit::likelihood::prior::Prior {
        focal_mean: 0.5 * problem.prior.focal_mean,
        focal_sigma: 0.5 * problem.prior.focal_sigma,
        ..*problem.prior
    };
    let mixture = Mixture::from_shares(&proposals.image, &proposals.drift, w.max(h) as f32)?;
    let half = Problem { landmarks, prior: &prior, mixture: &mixture, width: w, height: h, ..*problem };
    let ip = ImageProblem { image: target, ..*image };
    // `from` at half resolution for the chain, then as it was (halving and doubling are exact).
    from.focal *= 0.5;
    let fit = image_chain(&half, &ip, from, steps, instance, raster, rng, observer);
    from.focal *= 2.0;
    let mut fit = fit?;
    fit.best.focal *= 2.0;
    fit.last.focal *= 2.0;
    Ok(fit)
}
