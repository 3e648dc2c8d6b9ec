//! A glTF material as the scan's [`Material`]: its base-colour factor and texture, the image
//! decoded once per image and the factor multiplied in.

use std::collections::HashMap;
use std::path::Path;

use super::colour::{linear_to_srgb, srgb_to_linear};
use super::uri::{read_uri, resolve_uri, UriTarget};
use crate::error::MeshError;
use crate::material::{Material, TextureImage};

/// One glTF material: its factor (encoded to sRGB) and its base-colour image (decoded once per
/// image, the factor multiplied in).
pub(super) fn material(
    path: &Path,
    dir: &Path,
    buffers: &[Vec<u8>],
    m: &::gltf::Material<'_>,
    images: &mut HashMap<usize, TextureImage>,
) -> Result<Material, MeshError> {
    let index = m.index().unwrap_or(0);
    let name = m
        .name()
        .map_or_else(|| format!("material {index}"), str::to_string);
    let pbr = m.pbr_metallic_roughness();
    let f = pbr.base_color_factor();
    let diffuse = [f[0], f[1], f[2]].map(linear_to_srgb);
    let Some(info) = pbr.base_color_texture() else {
        return Ok(Material {
            name,
            diffuse,
            texture: None,
            texture_path: None,
        });
    };
    let image = info.texture().source();
    let img_index = image.index();
    let (bytes, where_, file) = match image.source() {
        ::gltf::image::Source::View { view, .. } => {
            let data = buffers
                .get(view.buffer().index())
                .and_then(|b| b.get(view.offset()..view.offset().checked_add(view.length())?));
            let Some(data) = data else {
                return Err(MeshError::Texture {
                    path: path.to_path_buf(),
                    reason: format!(
                        "image {img_index} (material `{name}`): its buffer view {} reaches past \
                         its buffer",
                        view.index()
                    ),
                });
            };
            (data.to_vec(), "embedded".to_string(), None)
        }
        ::gltf::image::Source::Uri { uri, .. } => match resolve_uri(dir, uri) {
            UriTarget::Refused(skinbrdf_core::untrusted::ConfineError::Missing {
                path: p, ..
            }) => {
                return Err(MeshError::MissingTexture {
                    path: path.to_path_buf(),
                    material: name,
                    texture: p,
                })
            }
            UriTarget::Refused(reason) => {
                return Err(MeshError::Refused {
                    path: path.to_path_buf(),
                    key: format!("image {img_index} uri (material `{name}`)"),
                    reason: Box::new(reason),
                })
            }
            UriTarget::File(p) => {
                let b = skinbrdf_core::untrusted::read_bounded(
                    &p,
                    skinbrdf_core::untrusted::TEXTURE_FILE,
                )?;
                (b, format!("{}", p.display()), Some(p))
            }
            _ => {
                let b = read_uri(dir, uri).map_err(|(_, reason)| MeshError::Texture {
                    path: path.to_path_buf(),
                    reason: format!("image {img_index} (material `{name}`): {reason}"),
                })?;
                (b, "data URI".to_string(), None)
            }
        },
    };
    let tex = match images.get(&img_index) {
        Some(t) => t.clone(),
        None => {
            let t = TextureImage::decode(&bytes).map_err(|reason| MeshError::Texture {
                path: file.clone().unwrap_or_else(|| path.to_path_buf()),
                reason: format!("image {img_index} ({where_}, material `{name}`): {reason}"),
            })?;
            images.insert(img_index, t.clone());
            t
        }
    };
    let tex = if f[..3] == [1.0, 1.0, 1.0] {
        tex
    } else {
        TextureImage {
            rgb: tex
                .rgb
                .iter()
                .map(|c| std::array::from_fn(|k| linear_to_srgb(srgb_to_linear(c[k]) * f[k])))
                .collect(),
            ..tex
        }
    };
    Ok(Material {
        name,
        diffuse,
        texture: Some(tex),
        texture_path: file,
    })
}
