//! Limits on what an untrusted scan file may make the readers hold in memory.

/// The most texels a texture may have (8192 x 4096). Held as 32-bit floats such a texture
/// takes 384 MiB; with the decoded image beside it while it is converted, loading one stays
/// well under a gigabyte, whatever a small compressed file states (docs/ingest.md, "Untrusted
/// files").
pub const MAX_TEXTURE_TEXELS: u64 = 1 << 25;

/// How many bytes of vertices and triangles the primitives may take as read, per byte of the
/// buffers (plus [`READ_BYTES_SLACK`]): each accessor read once takes about as much as it
/// stores (more for 8- and 16-bit indices, widened to 32 bits), so only accessors reused many
/// times pass it.
pub const READ_BYTES_PER_BUFFER_BYTE: u64 = 8;
/// Bytes of geometry allowed beyond [`READ_BYTES_PER_BUFFER_BYTE`] times the buffers' bytes.
pub(crate) const READ_BYTES_SLACK: u64 = 16 << 20;
