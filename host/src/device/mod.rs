//! The device side: quantizing a model into its flash image ([`quantize`], its error: [`accuracy`]), the interim device
//! mesh ([`mesh`]), the fit on the simulated device ([`fit`]), its landmark-free start ([`detect`]) and the
//! landmark-free fit from a camera frame ([`frame_fit`]).

pub mod accuracy;
pub mod detect;
pub mod fit;
pub mod frame_fit;
pub mod mesh;
pub mod quantize;
