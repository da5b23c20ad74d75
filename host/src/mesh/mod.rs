//! Meshes: reading and writing mesh and landmark files ([`io`]), the template scan and its
//! normalization ([`template`]), and small vector geometry ([`geometry`]).

pub mod geometry;
pub mod io;
pub mod template;
