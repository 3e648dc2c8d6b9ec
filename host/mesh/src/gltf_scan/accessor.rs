//! Accessors checked before the `gltf` crate reads them (types, bounds inside their buffer
//! views and buffers), with the specification's names for errors.

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::mesh::Mode;

/// A component type's name in the glTF specification.
fn data_type_name(t: DataType) -> &'static str {
    match t {
        DataType::I8 => "BYTE",
        DataType::U8 => "UNSIGNED_BYTE",
        DataType::I16 => "SHORT",
        DataType::U16 => "UNSIGNED_SHORT",
        DataType::U32 => "UNSIGNED_INT",
        DataType::F32 => "FLOAT",
    }
}

/// An accessor type's name in the glTF specification.
fn dimensions_name(d: Dimensions) -> &'static str {
    match d {
        Dimensions::Scalar => "SCALAR",
        Dimensions::Vec2 => "VEC2",
        Dimensions::Vec3 => "VEC3",
        Dimensions::Vec4 => "VEC4",
        Dimensions::Mat2 => "MAT2",
        Dimensions::Mat3 => "MAT3",
        Dimensions::Mat4 => "MAT4",
    }
}

/// A primitive mode's name in the glTF specification.
pub(super) fn mode_name(m: Mode) -> &'static str {
    match m {
        Mode::Points => "POINTS",
        Mode::Lines => "LINES",
        Mode::LineLoop => "LINE_LOOP",
        Mode::LineStrip => "LINE_STRIP",
        Mode::Triangles => "TRIANGLES",
        Mode::TriangleStrip => "TRIANGLE_STRIP",
        Mode::TriangleFan => "TRIANGLE_FAN",
    }
}

/// Checks an accessor's type and that its bytes lie inside its buffer view and buffer (the
/// `gltf` crate's readers assume a valid file and panic or stop short otherwise).
pub(super) fn check_accessor(
    acc: &::gltf::Accessor<'_>,
    buffers: &[Vec<u8>],
    types: &[DataType],
    dims: &[Dimensions],
    count: Option<usize>,
) -> Result<(), String> {
    if !types.contains(&acc.data_type()) || !dims.contains(&acc.dimensions()) {
        let names = |v: Vec<&str>| v.join(" or ");
        return Err(format!(
            "accessor {} is {} {}, expected {} and {}",
            acc.index(),
            data_type_name(acc.data_type()),
            dimensions_name(acc.dimensions()),
            names(types.iter().map(|&t| data_type_name(t)).collect()),
            names(dims.iter().map(|&d| dimensions_name(d)).collect()),
        ));
    }
    if let Some(n) = count {
        if acc.count() != n {
            return Err(format!(
                "accessor {} has {} elements for {n} vertices",
                acc.index(),
                acc.count()
            ));
        }
    }
    if acc.count() == 0 {
        return Err(format!("accessor {} is empty", acc.index()));
    }
    let elem = acc.size();
    let within = |view: &::gltf::buffer::View<'_>, offset: usize, count: usize, elem: usize| {
        let stride = view.stride().unwrap_or(elem).max(elem);
        let end = stride
            .checked_mul(count - 1)
            .and_then(|s| s.checked_add(offset))
            .and_then(|s| s.checked_add(elem));
        let buf_len = buffers.get(view.buffer().index()).map_or(0, Vec::len);
        matches!(end, Some(e) if e <= view.length())
            && view
                .offset()
                .checked_add(view.length())
                .is_some_and(|e| e <= buf_len)
    };
    match acc.view() {
        Some(view) if !within(&view, acc.offset(), acc.count(), elem) => {
            return Err(format!(
                "accessor {} ({} elements) reaches past its buffer view {} or buffer",
                acc.index(),
                acc.count(),
                view.index()
            ))
        }
        None if acc.sparse().is_none() => {
            return Err(format!("accessor {} has no data", acc.index()));
        }
        _ => {}
    }
    if let Some(sp) = acc.sparse() {
        let n = sp.count();
        let ok = n > 0
            && within(
                &sp.indices().view(),
                sp.indices().offset(),
                n,
                sp.indices().index_type().size(),
            )
            && within(&sp.values().view(), sp.values().offset(), n, elem);
        if !ok {
            return Err(format!(
                "accessor {}: its sparse substitution is empty or reaches past its buffer",
                acc.index()
            ));
        }
    }
    Ok(())
}
