//! Where a training starts when it fine-tunes: the two networks of an init file, dequantized
//! ([`crate::encode::decode_network`]), after a check that they are the networks this training
//! builds (sizes, layer shapes, landmark and light counts).

use crate::data::Geometry;
use crate::encode::decode_network;
use crate::nets::{check_architecture, finder_specs, initializer_specs, ArchitectureMismatch, Net};
use candle_core::Device;
use gpmm_core::format::init_file::InitFile;
use gpmm_core::net::{NetError, Shape};

/// Why an init file cannot be the start of a training.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// The bytes are not a valid init file.
    #[error("not a valid init file: {error}")]
    Unreadable {
        /// What the reader refused.
        error: NetError,
    },
    /// Its initializer reads another number of landmarks than the models have.
    #[error("its initializer reads {found} landmarks; the models have {expected}")]
    Landmarks {
        /// The file's.
        found: usize,
        /// The models'.
        expected: usize,
    },
    /// Its initializer reads another number of light values.
    #[error("its initializer reads {found} light values; this training labels {expected}")]
    Light {
        /// The file's.
        found: usize,
        /// The training's.
        expected: usize,
    },
    /// Its crops have another margin.
    #[error("its crops are {found} face sizes wide; this training's {expected}")]
    CropMargin {
        /// The file's.
        found: f32,
        /// The training's.
        expected: f32,
    },
    /// One of its networks has another architecture.
    #[error("its {network} does not have this training's architecture: {error}")]
    Architecture {
        /// `finder` or `initializer`.
        network: &'static str,
        /// How it differs.
        error: ArchitectureMismatch,
    },
    /// A tensor could not be made.
    #[error("{error}")]
    Tensor {
        /// The tensor library's error.
        error: candle_core::Error,
    },
}

/// The finder and the initializer of the init file `bytes` as networks to train further, with the
/// file's metadata; an error unless they are the networks a training of geometry `geo` builds.
pub fn networks_of_init(bytes: &[u8], geo: &Geometry, device: &Device) -> Result<(Net, Net, String), StartError> {
    let file = InitFile::parse(bytes).map_err(|error| StartError::Unreadable { error })?;
    if file.landmarks != geo.landmarks {
        return Err(StartError::Landmarks { found: file.landmarks, expected: geo.landmarks });
    }
    if file.light != geo.light {
        return Err(StartError::Light { found: file.light, expected: geo.light });
    }
    if file.crop_margin != geo.crop_margin {
        return Err(StartError::CropMargin { found: file.crop_margin, expected: geo.crop_margin });
    }
    let finder = decode_network(&file.finder);
    let initializer = decode_network(&file.initializer);
    check_architecture(&finder, Shape { h: geo.frame_side, w: geo.frame_side, c: 3 }, &finder_specs())
        .map_err(|error| StartError::Architecture { network: "finder", error })?;
    check_architecture(&initializer, Shape { h: geo.crop_side, w: geo.crop_side, c: 3 }, &initializer_specs(geo.initializer_outputs()))
        .map_err(|error| StartError::Architecture { network: "initializer", error })?;
    let tensor = |error| StartError::Tensor { error };
    Ok((
        Net::from_float(&finder, device).map_err(tensor)?,
        Net::from_float(&initializer, device).map_err(tensor)?,
        file.metadata.to_string(),
    ))
}
