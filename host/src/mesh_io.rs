//! Mesh and landmark file input/output. (Implementation in progress.)
