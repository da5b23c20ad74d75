//! The posterior's terms: the [`prior`], the [`landmarks`] likelihood with the jaw [`contour`]
//! as a silhouette, the target [`image`] with its background model, and the image likelihood
//! composed from [`pixel`] and background terms.

pub mod contour;
pub mod image;
pub mod landmarks;
pub mod pixel;
pub mod prior;
