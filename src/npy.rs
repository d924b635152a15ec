//! NumPy `.npy` files for the two arrays halftrace exchanges: rays (float32, shape (N, 8)) and
//! hits (structured `t, prim, u, v`), through the `npyz` crate, which reads the header as the
//! Python literal NumPy writes (any key order or quoting, versions 1.0 to 3.0). This wrapper
//! checks the shape, dtype and data size of each array and names the file in every error.

use crate::base::Hit;
use crate::base::Ray;
use npyz::WriterBuilder;
use std::path::{Path, PathBuf};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum NpyError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: not a .npy file: {msg}")]
    Format { path: PathBuf, msg: String },
    #[error("{path}: expected {expected}, found {found}")]
    Shape { path: PathBuf, expected: String, found: String },
}

/// One element of a hit file: the structured dtype `[('t', '<f4'), ('prim', '<i4'), ('u',
/// '<f4'), ('v', '<f4')]`, 16 bytes.
#[derive(npyz::Serialize, npyz::Deserialize, npyz::AutoSerialize)]
struct HitRecord {
    t: f32,
    prim: i32,
    u: f32,
    v: f32,
}

/// A file's header and the bytes after it.
fn open<'b>(path: &Path, bytes: &'b [u8]) -> Result<(npyz::NpyHeader, &'b [u8]), NpyError> {
    let f = npyz::NpyFile::new(bytes).map_err(|e| NpyError::Format { path: path.into(), msg: e.to_string() })?;
    Ok((f.header().clone(), f.into_inner()))
}

/// `shape` as text, as NumPy prints it.
fn shape_text(shape: &[u64]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(u64::to_string).collect::<Vec<_>>().join(", ")),
    }
}

/// Refuses data that is not exactly `count` elements of `size` bytes (`what`: "rays", "hits").
fn check_size(path: &Path, data: &[u8], count: u64, size: u64, what: &str) -> Result<(), NpyError> {
    let Some(need) = count.checked_mul(size).filter(|&n| usize::try_from(n).is_ok()) else {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: format!("a count of {what} whose data fits in memory"),
            found: format!("{count} {what}"),
        });
    };
    if data.len() as u64 != need {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: format!("{need} data bytes for {count} {what}"),
            found: format!("{} bytes", data.len()),
        });
    }
    Ok(())
}

/// Reads rays from a float32 array of shape (N, 8): `ox oy oz tmin dx dy dz tmax`, either byte
/// order. The rays are not validated here; see [`crate::base::validate`].
pub fn read_rays(path: &Path) -> Result<Vec<Ray>, NpyError> {
    let b = crate::fsx::read_regular(path).map_err(|source| NpyError::Io { path: path.into(), source })?;
    let (h, data) = open(path, &b)?;
    let shape = h.shape().to_vec();
    let float32 = matches!(h.dtype(), npyz::DType::Plain(t)
        if t.type_char() == npyz::TypeChar::Float && t.size_field() == 4);
    if !float32 {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: "dtype float32 ('<f4')".into(),
            found: format!("dtype {}", h.dtype().descr()),
        });
    }
    if h.order() == npyz::Order::Fortran {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: "C order".into(),
            found: "fortran_order True".into(),
        });
    }
    if shape.len() != 2 || shape[1] != 8 {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: "shape (N, 8)".into(),
            found: format!("shape {}", shape_text(&shape)),
        });
    }
    if shape[0] == 0 {
        // Nothing to trace: a speed or a SIMD utilisation of no rays means nothing.
        return Err(NpyError::Shape {
            path: path.into(),
            expected: "at least one ray".into(),
            found: "shape (0, 8)".into(),
        });
    }
    check_size(path, data, shape[0], 32, "rays")?;
    let floats = npyz::NpyFile::with_header(h, data)
        .into_vec::<f32>()
        .map_err(|e| NpyError::Format { path: path.into(), msg: e.to_string() })?;
    Ok(floats
        .chunks_exact(8)
        .map(|f| Ray { origin: [f[0], f[1], f[2]], tmin: f[3], dir: [f[4], f[5], f[6]], tmax: f[7] })
        .collect())
}

/// Writes an array through a temporary file and a rename: a failed write never leaves a
/// truncated file.
fn write_array<T: npyz::AutoSerialize>(
    path: &Path,
    shape: &[u64],
    items: impl IntoIterator<Item = T>,
) -> Result<(), NpyError> {
    let io = |source| NpyError::Io { path: path.into(), source };
    let mut bytes = Vec::new();
    let mut w =
        npyz::WriteOptions::<T>::new().default_dtype().shape(shape).writer(&mut bytes).begin_nd().map_err(io)?;
    w.extend(items).map_err(io)?;
    w.finish().map_err(io)?;
    crate::fsx::write_atomic(path, &bytes).map_err(|e| io(std::io::Error::other(format!("{e:#}"))))
}

/// Writes rays as float32 (N, 8).
pub fn write_rays(path: &Path, rays: &[Ray]) -> Result<(), NpyError> {
    let floats =
        rays.iter().flat_map(|r| [r.origin[0], r.origin[1], r.origin[2], r.tmin, r.dir[0], r.dir[1], r.dir[2], r.tmax]);
    write_array(path, &[rays.len() as u64, 8], floats)
}

/// Writes hits as a structured array with fields `t` (f32), `prim` (i32), `u`, `v` (f32).
pub fn write_hits(path: &Path, hits: &[Hit]) -> Result<(), NpyError> {
    let records = hits.iter().map(|h| HitRecord { t: h.t, prim: h.prim, u: h.u, v: h.v });
    write_array(path, &[hits.len() as u64], records)
}

/// Reads a hit file written by [`write_hits`] (used by tests and `report`).
pub fn read_hits(path: &Path) -> Result<Vec<Hit>, NpyError> {
    let b = crate::fsx::read_regular(path).map_err(|source| NpyError::Io { path: path.into(), source })?;
    let (h, data) = open(path, &b)?;
    let shape = h.shape().to_vec();
    let wrong = || NpyError::Shape {
        path: path.into(),
        expected: "structured hits (t, prim, u, v), shape (N,)".into(),
        found: format!("{} {}", h.dtype().descr(), shape_text(&shape)),
    };
    if shape.len() != 1 {
        return Err(wrong());
    }
    check_size(path, data, shape[0], 16, "hits")?;
    let records = npyz::NpyFile::with_header(h.clone(), data).data::<HitRecord>().map_err(|_| wrong())?;
    records
        .map(|r| r.map(|r| Hit { t: r.t, prim: r.prim, u: r.u, v: r.v }))
        .collect::<std::io::Result<Vec<Hit>>>()
        .map_err(|e| NpyError::Format { path: path.into(), msg: e.to_string() })
}
