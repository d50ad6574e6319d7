//! Rendering: the orbit camera, the MIP ray caster with its picks, the slice panes and the
//! status bar's texel probe. Reads the volume textures of `crate::gpu::volume_texture`; never
//! `crate::compute`.

pub mod camera;
pub mod probe;
pub mod raycast;
pub mod slice;
