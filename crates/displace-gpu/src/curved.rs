//! Curved meshes for the raster path: the prisms and boundary triangles of
//! [`displace_shaders::curved_prisms`], which displace-bevy builds its
//! curved material from too (`shaders/curved.wgsl` walks the prisms per
//! fragment).

pub use displace_shaders::curved_prisms::{CurvedShells, CurvedVertex, GpuPrism, ShellsError};
