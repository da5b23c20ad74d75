//! The device side: quantizing a model into its flash image ([`quantize`], its error: [`accuracy`]), the interim device
//! mesh ([`mesh`]), the fit on the simulated device ([`fit`]) and its landmark-free start ([`detect`]).

pub mod accuracy;
pub mod detect;
pub mod fit;
pub mod mesh;
pub mod quantize;
