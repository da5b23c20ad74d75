//! The posterior's terms: the [`prior`], the [`landmarks`] likelihood with the jaw [`contour`]
//! as a silhouette, the target [`image`] with its background model, and the image likelihood
//! composed from [`pixel`] and background terms, with the [`occlusion`] labels of what the
//! face does not explain and their [`labeller`].

pub mod contour;
pub mod image;
pub mod labeller;
pub mod landmarks;
pub mod occlusion;
pub mod pixel;
pub mod prior;
