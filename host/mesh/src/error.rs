//! The crate's error type, [`MeshError`], and the glTF reader's problems ([`GltfProblem`]).

use std::path::{Path, PathBuf};

use crate::limits::{MAX_TEXTURE_TEXELS, READ_BYTES_PER_BUFFER_BYTE};
use crate::report::MeshReport;

/// Errors of the mesh crate. Each names the file (where there is one) and the problem.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The mesh breaks a hard invariant (see [`skinbrdf_core::TriMesh::validate`]).
    #[error("invalid mesh: {} problem(s), first: {}", problems.len(), problems.first().map(|p| p.to_string()).unwrap_or_default())]
    Invalid {
        /// Every problem found.
        problems: Vec<skinbrdf_core::MeshError>,
    },
    /// No triangle is left (none in the file, or none survived the repair).
    #[error("{source_name}: the mesh has no usable triangle (of {triangles_in} read)")]
    Empty {
        /// File or mesh name.
        source_name: String,
        /// Triangles in the input.
        triangles_in: usize,
    },
    /// Reading or writing a file failed.
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The mesh has defects and the policy was strict.
    #[error("{source_name}: mesh defects: {}", report.summary())]
    Defects {
        /// File or mesh name.
        source_name: String,
        /// What was found.
        report: Box<MeshReport>,
    },
    /// Repairing the mesh would drop more triangles than the policy accepts.
    #[error("{source_name}: repairing the mesh loses {} of its {} triangles, more than the {:.1} % accepted ({})", report.lost_triangles(), report.triangles_in, max_fraction * 100.0, report.summary())]
    TooManyDropped {
        /// File or mesh name.
        source_name: String,
        /// The policy's limit (fraction of the triangles).
        max_fraction: f64,
        /// What was found (`lost_triangles()` of `triangles_in`).
        report: Box<MeshReport>,
    },
    /// A parameter is out of range.
    #[error("{field}: {reason}")]
    InvalidParameter {
        /// Which parameter.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// An OBJ's material names a texture file that does not exist.
    #[error("{path}: material `{material}` names the texture {texture}, which does not exist")]
    MissingTexture {
        /// The OBJ file.
        path: PathBuf,
        /// The material.
        material: String,
        /// The texture file looked for.
        texture: PathBuf,
    },
    /// An OBJ's `mtllib` file could not be read.
    #[error("{path}: cannot read its material library {}", libraries.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "))]
    MissingMaterialLibrary {
        /// The OBJ file.
        path: PathBuf,
        /// The MTL files that failed.
        libraries: Vec<PathBuf>,
    },
    /// A texture image could not be decoded.
    #[error("texture {path}: {reason}")]
    Texture {
        /// The image file.
        path: PathBuf,
        /// The decoder's complaint.
        reason: String,
    },
    /// Texture coordinates that do not fit the faces.
    #[error("{path}: bad texture coordinates: {reason}")]
    BadUv {
        /// The OBJ file.
        path: PathBuf,
        /// What is wrong, with the object and face.
        reason: String,
    },
    /// A glTF file is malformed or uses what the loader does not read.
    #[error("{path}: glTF: {problem}")]
    Gltf {
        /// The `.glb` or `.gltf` file.
        path: PathBuf,
        /// What is wrong.
        problem: GltfProblem,
    },
    /// A file could not be read within its limits (not a regular file, or too large).
    #[error(transparent)]
    Read(skinbrdf_core::untrusted::ReadError),
    /// A path a scan file names (an OBJ's `mtllib`, an MTL's `map_Kd`, a glTF's URI) leads
    /// outside the scan's folder or to something other than a regular file.
    #[error("{}: {key}: {reason}", path.display())]
    Refused {
        /// The file that names the path.
        path: PathBuf,
        /// Where in it (`line 3 mtllib`, `buffer 0 uri`).
        key: String,
        /// Why it is refused.
        reason: Box<skinbrdf_core::untrusted::ConfineError>,
    },
    /// A file is malformed.
    #[error("{path}: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the line or element where it was found.
        reason: String,
    },
}

impl From<skinbrdf_core::untrusted::ReadError> for MeshError {
    /// A plain I/O failure stays [`MeshError::Io`]; a refusal (not a regular file, too large)
    /// is [`MeshError::Read`].
    fn from(e: skinbrdf_core::untrusted::ReadError) -> Self {
        match e {
            skinbrdf_core::untrusted::ReadError::Io { path, source } => Self::Io { path, source },
            other => Self::Read(other),
        }
    }
}

/// What is wrong with a glTF file (the `problem` of [`MeshError::Gltf`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GltfProblem {
    /// The GLB container is cut short: its header or a chunk states more bytes than there are.
    #[error("truncated GLB: {what} states {stated} bytes, {available} are there")]
    Truncated {
        /// Which length (the header's, the JSON chunk's, the binary chunk's).
        what: &'static str,
        /// Bytes stated.
        stated: u64,
        /// Bytes present.
        available: u64,
    },
    /// The `gltf` crate refused the file: bad GLB header, malformed JSON, invalid references.
    #[error("{0}")]
    Document(String),
    /// A buffer's external file cannot be read.
    #[error("buffer {buffer}: cannot read {}: {reason}", file.display())]
    MissingBuffer {
        /// Buffer index.
        buffer: usize,
        /// The file looked for.
        file: PathBuf,
        /// The I/O error.
        reason: String,
    },
    /// A buffer's source is unusable (no binary chunk, a bad data URI, an unsupported scheme).
    #[error("buffer {buffer}: {reason}")]
    BadBuffer {
        /// Buffer index.
        buffer: usize,
        /// What is wrong.
        reason: String,
    },
    /// A buffer holds fewer bytes than its `byteLength`.
    #[error("buffer {buffer} holds {actual} bytes, its byteLength is {stated}")]
    ShortBuffer {
        /// Buffer index.
        buffer: usize,
        /// `byteLength`.
        stated: usize,
        /// Bytes read.
        actual: usize,
    },
    /// A primitive is not a triangle list.
    #[error("{at}: primitive mode {mode} is not read (triangle lists only)")]
    UnsupportedMode {
        /// Mesh and primitive.
        at: String,
        /// The mode.
        mode: String,
    },
    /// A position is NaN or infinite (the specification forbids it).
    #[error("{at}: POSITION {vertex} is not finite ({}, {}, {})", value[0], value[1], value[2])]
    NonFinitePosition {
        /// Mesh and primitive.
        at: String,
        /// Vertex index in the primitive.
        vertex: usize,
        /// The stored value.
        value: [f32; 3],
    },
    /// An attribute or the indices cannot be read as a scan needs them.
    #[error("{at}: {attribute}: {reason}")]
    BadAccessor {
        /// Mesh and primitive.
        at: String,
        /// `POSITION`, `TEXCOORD_0`, `COLOR_0`, `indices`.
        attribute: String,
        /// What is wrong.
        reason: String,
    },
    /// The primitives read more vertices and triangles than the buffers can hold without
    /// reusing accessors many times (a small file drawing one mesh a million times).
    #[error(
        "{at}: the primitives read so far take {bytes} bytes of vertices and triangles, more than \
         {max} ({READ_BYTES_PER_BUFFER_BYTE} times the buffers' bytes): accessors reused many times"
    )]
    TooMuchGeometry {
        /// Mesh and primitive where the limit was passed.
        at: String,
        /// Bytes the primitives take as read.
        bytes: u64,
        /// The limit.
        max: u64,
    },
    /// The materials' textures hold more texels together than one texture may have.
    #[error(
        "material {material}: the materials' textures hold {texels} texels together, more than \
         the {max} one texture may have (one image used by many materials?)",
        max = MAX_TEXTURE_TEXELS
    )]
    TooManyTexels {
        /// The material where the limit was passed.
        material: usize,
        /// Texels so far.
        texels: u64,
    },
    /// A node is reached twice from the scene: the hierarchy has a cycle, or a node has two
    /// parents or is listed twice (glTF's nodes form trees; a node drawn many times would
    /// multiply the mesh held in memory).
    #[error("node {node} is reached twice: a cycle, or a node with two parents (glTF's nodes form trees)")]
    NodeCycle {
        /// The node reached twice.
        node: usize,
    },
}

/// The error for a file whose extension names no format the crate reads.
pub(crate) fn unknown_format(path: &Path) -> MeshError {
    MeshError::Parse {
        path: path.to_path_buf(),
        reason: "unknown mesh format (expected .ply, .obj, .glb or .gltf)".into(),
    }
}
