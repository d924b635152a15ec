//! Wavefront OBJ through `tobj`: triangulated, every model concatenated in file order. Lines
//! `tobj` would not name (a vertex without three finite numbers, a face reference out of
//! range) are checked first, by line number ([`prescan`]); materials are never read.

use super::SceneError;
use glam::Vec3;
use std::io::BufReader;
use std::path::Path;

/// The triangles of an OBJ file's bytes, and the warnings about its material files.
pub fn load(path: &Path, bytes: &[u8]) -> Result<(Vec<[Vec3; 3]>, Vec<String>), SceneError> {
    // A UTF-8 byte-order mark (editors on Windows write one) is not part of the first line:
    // left there, the first statement is not recognised and its vertex is lost.
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    prescan(path, bytes)?;

    let opts = tobj::LoadOptions { triangulate: true, single_index: false, ignore_points: true, ignore_lines: true };
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    // Non-UTF-8 bytes (in a comment, say) become U+FFFD instead of failing the whole read; in a
    // statement, prescan has already named the line.
    let text = String::from_utf8_lossy(bytes);
    let mut reader = BufReader::new(text.as_bytes());
    // Materials do not affect geometry, so they are never read (an `mtllib /dev/zero` or a FIFO
    // cannot stall the load); a missing or irregular material file is only named in a warning.
    let mtl_warnings = std::cell::RefCell::new(Vec::new());
    let (models, _) = tobj::load_obj_buf(&mut reader, &opts, |p| {
        let f = dir.join(p);
        if !f.is_file() {
            let what = if f.exists() { "is not a regular file" } else { "was not found" };
            mtl_warnings.borrow_mut().push(format!(
                "{}: mtllib {} {what} (materials are not used; geometry is unaffected)",
                path.display(),
                f.display()
            ));
        }
        Err(tobj::LoadError::OpenFileFailed)
    })
    .map_err(|e| SceneError::Parse { path: path.into(), msg: e.to_string() })?;
    let warnings = mtl_warnings.into_inner();

    let mut tris = Vec::new();
    for m in &models {
        let p = &m.mesh.positions;
        let idx = &m.mesh.indices;
        let vert = |i: u32| -> Result<Vec3, SceneError> {
            let i = i as usize * 3;
            if i + 2 >= p.len() {
                return Err(SceneError::Parse {
                    path: path.into(),
                    msg: format!("model '{}': vertex index out of range", m.name),
                });
            }
            Ok(Vec3::new(p[i], p[i + 1], p[i + 2]))
        };
        for f in idx.chunks_exact(3) {
            tris.push([vert(f[0])?, vert(f[1])?, vert(f[2])?]);
        }
    }
    Ok((tris, warnings))
}

/// Line-level checks that tobj does not report with a line number: vertex lines need three
/// finite numbers, face lines need at least three vertex references that resolve.
fn prescan(path: &Path, bytes: &[u8]) -> Result<(), SceneError> {
    let text = String::from_utf8_lossy(bytes);
    let mut nverts: i64 = 0;
    let malformed = |line: usize, msg: String| SceneError::Malformed { path: path.into(), line, msg };
    for (ln, raw) in text.lines().enumerate() {
        let line = ln + 1;
        let l = raw.split('#').next().unwrap_or("").trim();
        // A line continued on the next (a trailing backslash, which some exporters write):
        // tobj reads the two lines apart, so the first would lose its last values.
        if l.ends_with('\\') {
            return Err(malformed(
                line,
                "ends with '\\' (a line continued on the next), which halftrace does not read: join the two lines"
                    .into(),
            ));
        }
        let mut it = l.split_whitespace();
        match it.next() {
            Some("v") => {
                let coords: Vec<&str> = it.collect();
                if coords.len() < 3 {
                    return Err(malformed(line, format!("vertex needs 3 coordinates, found {}", coords.len())));
                }
                for c in &coords[..3] {
                    match c.parse::<f32>() {
                        Ok(x) if x.is_finite() => {}
                        Ok(_) => {
                            return Err(SceneError::NonFinite { path: path.into(), line, text: raw.trim().to_string() })
                        }
                        Err(_) => return Err(malformed(line, format!("'{c}' is not a number"))),
                    }
                }
                nverts += 1;
            }
            Some("f") => {
                let refs: Vec<&str> = it.collect();
                if refs.len() < 3 {
                    return Err(malformed(line, format!("face needs at least 3 vertices, found {}", refs.len())));
                }
                for r in refs {
                    let first = r.split('/').next().unwrap_or("");
                    let i: i64 =
                        first.parse().map_err(|_| malformed(line, format!("'{r}' is not a vertex reference")))?;
                    let ok = if i > 0 { i <= nverts } else { i < 0 && -i <= nverts };
                    if !ok {
                        return Err(malformed(
                            line,
                            format!("vertex reference {i} is out of range ({nverts} vertices so far)"),
                        ));
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}
