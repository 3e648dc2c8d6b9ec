//! Head-scan meshes: PLY/OBJ loading with validation, normals by local planar fit, and an obvhs BVH for ray casting.
