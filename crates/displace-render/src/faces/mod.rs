//! The displaced faces a ray is traced through: a flat quad or triangle
//! carried into its map space and sphere traced there ([`displaced`], the
//! ray-tracer paper's section 2.4 shell), a triangle of a curved mesh
//! traced through its shell along the vertex normals ([`curved_face`]), and
//! a displaced mesh tessellated finely ([`displaced_surface`]): the curved
//! surface's ground truth and `export-mesh --scene`'s output.

pub mod curved_face;
pub mod displaced;
pub mod displaced_surface;
