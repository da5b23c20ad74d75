//! Meshes: reading and writing mesh and landmark files ([`io`]), the template scan and its
//! normalization ([`template`]), small vector geometry ([`geometry`]) and simplification to a vertex budget ([`simplify`]).

pub mod align;
pub mod closest;
pub mod geometry;
pub mod io;
pub mod simplify;
pub mod template;
