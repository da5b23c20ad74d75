//! model_io (in progress)
