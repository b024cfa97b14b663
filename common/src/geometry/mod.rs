//! Rays, affine transforms and surface interactions.

pub mod interaction;
pub mod ray;
pub mod transform;

pub use interaction::{SurfaceInteraction, SurfaceRef};
pub use ray::{Ray, offset_ray_origin};
pub use transform::Transform;
