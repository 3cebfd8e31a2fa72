//! Where rendered pixels go: image files written atomically ([`output`]:
//! PNG, EXR, npy AOVs), the farm's tiles of an image ([`tiling`]: which rows
//! a task renders; [`tile_file`]: the EXR a task writes) and their merge
//! into the whole image ([`merge`]).

pub mod merge;
pub mod output;
pub mod tile_file;
pub mod tiling;
