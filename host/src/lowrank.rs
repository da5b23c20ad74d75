//! lowrank (in progress)
