//! Minimal NumPy `.npy` (format 1.0–3.0) reading and writing for the two arrays halftrace
//! exchanges: rays (float32, shape (N, 8)) and hits (structured `t, prim, u, v`).
//! Written by hand because the hit file needs a structured dtype and every error must name
//! the file and what is wrong with it.

use crate::base::Hit;
use crate::base::Ray;
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

const MAGIC: &[u8] = b"\x93NUMPY";

struct Header {
    descr: String,
    fortran: bool,
    shape: Vec<usize>,
    data_offset: usize,
}

fn parse_header(path: &Path, b: &[u8]) -> Result<Header, NpyError> {
    let fmt = |msg: &str| NpyError::Format { path: path.into(), msg: msg.into() };
    if b.len() < 10 || &b[..6] != MAGIC {
        return Err(fmt("missing \\x93NUMPY magic"));
    }
    let major = b[6];
    let (hlen, start) = match major {
        1 => (u16::from_le_bytes([b[8], b[9]]) as usize, 10),
        2 | 3 => {
            if b.len() < 12 {
                return Err(fmt("truncated header"));
            }
            (u32::from_le_bytes([b[8], b[9], b[10], b[11]]) as usize, 12)
        }
        v => return Err(fmt(&format!("unsupported format version {v}"))),
    };
    if b.len() < start + hlen {
        return Err(fmt("truncated header"));
    }
    let h = std::str::from_utf8(&b[start..start + hlen]).map_err(|_| fmt("header is not text"))?;
    let value_of = |key: &str| -> Result<&str, NpyError> {
        let k = format!("'{key}'");
        let i = h.find(&k).ok_or_else(|| fmt(&format!("header has no {k}")))?;
        let rest = h[i + k.len()..].trim_start();
        let rest = rest.strip_prefix(':').ok_or_else(|| fmt("malformed header"))?;
        Ok(rest.trim_start())
    };
    let d = value_of("descr")?;
    let descr = if let Some(s) = d.strip_prefix('\'') {
        s.split('\'').next().unwrap_or("").to_string()
    } else {
        // Structured dtype: keep the list text for the error message.
        d.split("),").next().unwrap_or("").to_string()
    };
    let f = value_of("fortran_order")?;
    let fortran = if f.starts_with("True") {
        true
    } else if f.starts_with("False") {
        false
    } else {
        return Err(fmt("fortran_order is neither True nor False"));
    };
    let s = value_of("shape")?;
    let s = s.strip_prefix('(').ok_or_else(|| fmt("shape is not a tuple"))?;
    let s = s.split(')').next().ok_or_else(|| fmt("shape is not a tuple"))?;
    let mut shape = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        shape.push(part.trim_end_matches('L').parse::<usize>().map_err(|_| fmt(&format!("bad shape entry '{part}'")))?);
    }
    Ok(Header { descr, fortran, shape, data_offset: start + hlen })
}

fn write_npy(path: &Path, descr: &str, shape: &str, data: &[u8]) -> Result<(), NpyError> {
    let mut header = format!("{{'descr': {descr}, 'fortran_order': False, 'shape': {shape}, }}");
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut bytes = Vec::with_capacity(MAGIC.len() + 4 + header.len() + data.len());
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&[1, 0]);
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    bytes.extend_from_slice(data);
    // Through a temporary file and a rename: a failed write never leaves a truncated file.
    crate::fsx::write_atomic(path, &bytes)
        .map_err(|e| NpyError::Io { path: path.into(), source: std::io::Error::other(format!("{e:#}")) })
}

/// Reads rays from a float32 array of shape (N, 8): `ox oy oz tmin dx dy dz tmax`.
/// The rays are not validated here; see [`crate::base::validate`].
pub fn read_rays(path: &Path) -> Result<Vec<Ray>, NpyError> {
    let b = crate::fsx::read_regular(path).map_err(|source| NpyError::Io { path: path.into(), source })?;
    let h = parse_header(path, &b)?;
    if h.descr != "<f4" && h.descr != "=f4" {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: "dtype float32 ('<f4')".into(),
            found: format!("dtype '{}'", h.descr),
        });
    }
    if h.fortran {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: "C order".into(),
            found: "fortran_order True".into(),
        });
    }
    if h.shape.len() != 2 || h.shape[1] != 8 {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: "shape (N, 8)".into(),
            found: format!("shape {:?}", h.shape),
        });
    }
    let n = h.shape[0];
    if n == 0 {
        // Nothing to trace: a speed or a SIMD utilisation of no rays means nothing.
        return Err(NpyError::Shape {
            path: path.into(),
            expected: "at least one ray".into(),
            found: "shape (0, 8)".into(),
        });
    }
    let data = &b[h.data_offset..];
    let Some(need) = n.checked_mul(32) else {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: "a ray count whose data fits in memory".into(),
            found: format!("shape ({n}, 8)"),
        });
    };
    if data.len() != need {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: format!("{need} data bytes for {n} rays"),
            found: format!("{} bytes", data.len()),
        });
    }
    Ok(data
        .chunks_exact(32)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes([c[4 * i], c[4 * i + 1], c[4 * i + 2], c[4 * i + 3]]);
            Ray { origin: [f(0), f(1), f(2)], tmin: f(3), dir: [f(4), f(5), f(6)], tmax: f(7) }
        })
        .collect())
}

/// Writes rays as float32 (N, 8).
pub fn write_rays(path: &Path, rays: &[Ray]) -> Result<(), NpyError> {
    write_npy(path, "'<f4'", &format!("({}, 8)", rays.len()), bytemuck::cast_slice(rays))
}

/// Writes hits as a structured array with fields `t` (f32), `prim` (i32), `u`, `v` (f32).
pub fn write_hits(path: &Path, hits: &[Hit]) -> Result<(), NpyError> {
    write_npy(
        path,
        "[('t', '<f4'), ('prim', '<i4'), ('u', '<f4'), ('v', '<f4')]",
        &format!("({},)", hits.len()),
        bytemuck::cast_slice(hits),
    )
}

/// Reads a hit file written by [`write_hits`] (used by tests and `report`).
pub fn read_hits(path: &Path) -> Result<Vec<Hit>, NpyError> {
    let b = std::fs::read(path).map_err(|source| NpyError::Io { path: path.into(), source })?;
    let h = parse_header(path, &b)?;
    if !h.descr.contains("'t'") || h.shape.len() != 1 {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: "structured hits (t, prim, u, v), shape (N,)".into(),
            found: format!("{} {:?}", h.descr, h.shape),
        });
    }
    let data = &b[h.data_offset..];
    if h.shape[0].checked_mul(16) != Some(data.len()) {
        return Err(NpyError::Shape {
            path: path.into(),
            expected: format!("{} hits × 16 bytes", h.shape[0]),
            found: format!("{} bytes", data.len()),
        });
    }
    Ok(data.chunks_exact(16).map(bytemuck::pod_read_unaligned).collect())
}
