//! The capacity of a host fit: how many shape and colour coefficients its parameter vector holds.

use gpmm_core::model::FitParams;

/// Shape coefficient capacity of a fit (a model of higher rank is fitted in its first `KS` components).
pub const KS: usize = 200;
/// Colour coefficient capacity of a fit.
pub const KC: usize = 200;
/// The parameter vector of a host fit.
pub type Params = FitParams<KS, KC>;
