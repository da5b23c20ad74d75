//! Meshes: the coloured triangle mesh ([`Mesh`]), reading and writing mesh and landmark files ([`io`]), the template scan and its
//! normalization ([`template`]), small vector geometry ([`geometry`]) and simplification to a vertex budget ([`simplify`]).

pub mod align;
pub mod closest;
pub mod geometry;
pub mod io;
pub mod simplify;
pub mod template;

/// A coloured triangle mesh in f64 (positions in the mesh's units, colours linear RGB in \[0, 1\]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<[f64; 3]>,
    /// Per-vertex colours, same length as `positions`.
    pub colors: Vec<[f64; 3]>,
    /// Triangles as vertex indices (counter-clockwise seen from outside).
    pub triangles: Vec<[u32; 3]>,
}
