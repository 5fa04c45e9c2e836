//! Accessors: vertex attributes and indices copied out of their buffer
//! views with bounds checks, sparse substitution and normalized integers.

use glam::{Vec2, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions};

use super::Ctx;
use super::container::view_bytes;

/// Most elements of a sparse accessor without a base buffer view (its
/// size is not bounded by the file's size).
const MAX_SPARSE_ELEMENTS: usize = 1 << 27;

/// Copies an accessor's elements into a tightly packed byte vector,
/// applying sparse substitution. Returns the bytes and the element size.
fn accessor_bytes(ctx: &Ctx, accessor: &gltf::Accessor) -> Result<(Vec<u8>, usize), String> {
    let dims = accessor.dimensions();
    if matches!(dims, Dimensions::Mat2 | Dimensions::Mat3 | Dimensions::Mat4) {
        return Err("matrix accessors are not supported here".into());
    }
    let elem = accessor.data_type().size() * dims.multiplicity();
    let count = accessor.count();
    let total = count
        .checked_mul(elem)
        .ok_or_else(|| format!("accessor count {count} is too large"))?;
    let mut out = match accessor.view() {
        Some(view) => {
            let data = view_bytes(ctx, &view)?;
            let stride = view.stride().unwrap_or(elem);
            if stride < elem {
                return Err(format!(
                    "byteStride {stride} is smaller than the element size {elem}"
                ));
            }
            let start = accessor.offset();
            let end = match count.checked_sub(1) {
                None => start,
                Some(last) => last
                    .checked_mul(stride)
                    .and_then(|x| x.checked_add(start))
                    .and_then(|x| x.checked_add(elem))
                    .ok_or_else(|| format!("accessor count {count} is too large"))?,
            };
            if end > data.len() {
                return Err(format!(
                    "accessor needs bytes {start}..{end} of buffer view {} which has {} bytes",
                    view.index(),
                    data.len()
                ));
            }
            let mut out = Vec::with_capacity(total);
            for i in 0..count {
                let s = start + i * stride;
                let chunk = data
                    .get(s..s + elem)
                    .ok_or("accessor element out of bounds")?;
                out.extend_from_slice(chunk);
            }
            out
        }
        None => {
            if accessor.sparse().is_none() {
                return Err("accessor has neither a buffer view nor sparse data".into());
            }
            if count > MAX_SPARSE_ELEMENTS {
                return Err(format!("sparse accessor count {count} is too large"));
            }
            vec![0; total]
        }
    };
    if let Some(sparse) = accessor.sparse() {
        let n = sparse.count();
        if n > count {
            return Err(format!(
                "sparse accessor substitutes {n} elements of {count}"
            ));
        }
        let indices = sparse.indices();
        let isize = indices.index_type().size();
        let idata = view_bytes(ctx, &indices.view())?;
        let ibytes = n
            .checked_mul(isize)
            .and_then(|len| idata.get(indices.offset()..)?.get(..len))
            .ok_or("sparse indices exceed their buffer view")?;
        let values = sparse.values();
        let vdata = view_bytes(ctx, &values.view())?;
        let vbytes = n
            .checked_mul(elem)
            .and_then(|len| vdata.get(values.offset()..)?.get(..len))
            .ok_or("sparse values exceed their buffer view")?;
        for (ib, value) in ibytes.chunks_exact(isize).zip(vbytes.chunks_exact(elem)) {
            let target = match *ib {
                [a] => a as usize,
                [a, b] => u16::from_le_bytes([a, b]) as usize,
                [a, b, c, d] => u32::from_le_bytes([a, b, c, d]) as usize,
                _ => return Err("invalid sparse index size".into()),
            };
            let slot = target
                .checked_mul(elem)
                .and_then(|s| out.get_mut(s..s + elem))
                .ok_or_else(|| {
                    format!("sparse index {target} is out of range (accessor count {count})")
                })?;
            slot.copy_from_slice(value);
        }
    }
    Ok((out, elem))
}

/// Reads a float vector attribute with `n` components per element
/// (normalized integer types are mapped to `[0, 1]` / `[-1, 1]`).
fn read_floats(ctx: &Ctx, accessor: &gltf::Accessor, n: usize) -> Result<Vec<f32>, String> {
    let dims = accessor.dimensions();
    if dims.multiplicity() != n || matches!(dims, Dimensions::Mat2) {
        return Err(format!(
            "expected {n} components per element, found type {dims:?}"
        ));
    }
    let (bytes, _) = accessor_bytes(ctx, accessor)?;
    let norm = accessor.normalized();
    let values: Vec<f32> = match accessor.data_type() {
        DataType::F32 => bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
        DataType::U8 => bytes
            .iter()
            .map(|&b| if norm { b as f32 / 255.0 } else { b as f32 })
            .collect(),
        DataType::I8 => bytes
            .iter()
            .map(|&b| {
                let v = b as i8 as f32;
                if norm { (v / 127.0).max(-1.0) } else { v }
            })
            .collect(),
        DataType::U16 => bytes
            .chunks_exact(2)
            .map(|c| {
                let v = u16::from_le_bytes([c[0], c[1]]) as f32;
                if norm { v / 65535.0 } else { v }
            })
            .collect(),
        DataType::I16 => bytes
            .chunks_exact(2)
            .map(|c| {
                let v = i16::from_le_bytes([c[0], c[1]]) as f32;
                if norm { (v / 32767.0).max(-1.0) } else { v }
            })
            .collect(),
        DataType::U32 => bytes
            .chunks_exact(4)
            .map(|c| {
                let v = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                if norm {
                    (v as f64 / u32::MAX as f64) as f32
                } else {
                    v as f32
                }
            })
            .collect(),
    };
    Ok(values)
}

pub(super) fn read_vec3(ctx: &Ctx, accessor: &gltf::Accessor) -> Result<Vec<Vec3>, String> {
    Ok(read_floats(ctx, accessor, 3)?
        .chunks_exact(3)
        .map(|c| Vec3::new(c[0], c[1], c[2]))
        .collect())
}

pub(super) fn read_vec2(ctx: &Ctx, accessor: &gltf::Accessor) -> Result<Vec<Vec2>, String> {
    Ok(read_floats(ctx, accessor, 2)?
        .chunks_exact(2)
        .map(|c| Vec2::new(c[0], c[1]))
        .collect())
}

pub(super) fn read_vec4(ctx: &Ctx, accessor: &gltf::Accessor) -> Result<Vec<Vec4>, String> {
    Ok(read_floats(ctx, accessor, 4)?
        .chunks_exact(4)
        .map(|c| Vec4::new(c[0], c[1], c[2], c[3]))
        .collect())
}

/// Reads an index accessor (unsigned scalar integers).
pub(super) fn read_indices(ctx: &Ctx, accessor: &gltf::Accessor) -> Result<Vec<u32>, String> {
    if accessor.dimensions() != Dimensions::Scalar {
        return Err(format!(
            "index accessor must be SCALAR, found {:?}",
            accessor.dimensions()
        ));
    }
    let (bytes, _) = accessor_bytes(ctx, accessor)?;
    match accessor.data_type() {
        DataType::U8 => Ok(bytes.iter().map(|&b| u32::from(b)).collect()),
        DataType::U16 => Ok(bytes
            .chunks_exact(2)
            .map(|c| u32::from(u16::from_le_bytes([c[0], c[1]])))
            .collect()),
        DataType::U32 => Ok(bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()),
        t => Err(format!(
            "index accessor must use unsigned integers, found {t:?}"
        )),
    }
}
