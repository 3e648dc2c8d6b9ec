//! glTF 2.0 scans: binary `.glb` and `.gltf` with external or data-URI buffers and images, read
//! with the `gltf` crate; and [`write_glb`], a minimal textured GLB writer for tests and the
//! synthetic studio.
//!
//! # What is read
//!
//! Every mesh primitive reachable from the default scene (else the first scene; a file with no
//! scene at all: every root node), each transformed by its node's world transform (parents'
//! matrices composed in `f64`; a transform that mirrors reverses the winding so front faces
//! stay front faces, as the specification says). Coordinates are kept as stored: glTF is Y-up
//! metres by specification, so [`crate::LengthUnit::Auto`] means metres here, not a guess, and
//! an explicit unit scales as for any other format (for an exporter that wrote millimetres).
//! Only triangle lists are read (`mode` 4, indexed or not); points, lines, strips and fans are
//! refused. Skins and morph targets are ignored (the base geometry is read).
//!
//! Per triangle, the colour comes from the first of:
//!
//! 1. the material's base-colour texture at the texture-coordinate set it names (`TEXCOORD_0`
//!    normally), the image embedded in the GLB's binary chunk, an external file or a data URI;
//! 2. the primitive's `COLOR_0` vertex colours;
//! 3. the material's `baseColorFactor` (a primitive with no material has no colour, as an OBJ
//!    face without `usemtl`).
//!
//! The factor multiplies the texture or the vertex colours (the specification's base colour);
//! `COLOR_0` is not multiplied into a texture (scanners write one or the other). Samplers (wrap
//! modes, filters) and `KHR_texture_transform` are ignored: lookups repeat and are bilinear, as
//! for OBJ.
//!
//! # Conventions
//!
//! * **Texture coordinates**: glTF puts `v = 0` at the top of the image, OBJ at the bottom. They
//!   are stored in the OBJ convention (`v_obj = 1 - v_gltf`) so that one lookup
//!   ([`crate::TextureImage::bilinear`]) serves both; [`write_glb`] does the reverse.
//! * **Colour space**: every appearance of the crate holds display (sRGB-encoded) values, as an
//!   OBJ's PNG texture and a PLY's vertex colours store them. A glTF base-colour texture is
//!   sRGB-encoded by specification and is kept as stored; `COLOR_0` and `baseColorFactor` are
//!   linear by specification and are encoded to sRGB (after the factor's multiplication, done
//!   in linear light) so that all formats give the same value for the same print.
//! * **Invalid data**: the specification forbids non-finite accessor values and out-of-range
//!   indices, so a NaN position or an index past the vertices is an error naming the mesh and
//!   primitive (not a defect for the repair to drop, as in an OBJ or PLY).

mod accessor;
mod colour;
mod data;
mod document;
mod material;
mod primitive;
mod read;
mod scene;
#[cfg(test)]
mod tests;
mod uri;
mod write;

pub use crate::error::GltfProblem;
pub use crate::limits::READ_BYTES_PER_BUFFER_BYTE;
pub use colour::{linear_to_srgb, srgb_to_linear};
pub(crate) use data::Detail;
pub(crate) use read::read_gltf;
pub use uri::gltf_external_files;
pub use write::{encode_glb, write_glb};
