//! The device side: quantizing a model into its flash image ([`quantize`], its error: [`accuracy`]), the interim device
//! mesh ([`mesh`]) and the fit on the simulated device ([`fit`]).

pub mod accuracy;
pub mod fit;
pub mod mesh;
pub mod quantize;
