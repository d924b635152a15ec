//! Scenes: Wavefront OBJ (triangulated, all models concatenated in file order), glTF 2.0
//! (`.gltf`, `.glb`) and PLY ([`crate::formats`]), each plain or gzip-compressed (`.gz`). A
//! triangle's index in the loader's order is its public `prim` id.

use crate::geom::Aabb;
use glam::Vec3;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum SceneError {
    #[error("{path}: cannot read scene: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: not a valid gzip stream: {source}")]
    Gzip { path: PathBuf, source: std::io::Error },
    #[error("{path}: file is empty")]
    EmptyFile { path: PathBuf },
    #[error("{path}:{line}: {msg}")]
    Malformed { path: PathBuf, line: usize, msg: String },
    #[error("{path}:{line}: vertex coordinate is not finite ({text})")]
    NonFinite { path: PathBuf, line: usize, text: String },
    #[error("{path}: OBJ parse error: {msg}")]
    Parse { path: PathBuf, msg: String },
    /// A glTF or PLY file that does not describe triangles we can read (the message names the
    /// element).
    #[error("{path}: {msg}")]
    Invalid { path: PathBuf, msg: String },
    #[error("{path}: scene has no triangles")]
    NoTriangles { path: PathBuf },
    #[error("{path}: scene has {count} triangles; at most {max} are supported")]
    TooLarge { path: PathBuf, count: usize, max: usize },
}

/// Most triangles a scene may have: leaf references keep 27 bits of triangle index.
pub const MAX_TRIANGLES: usize = 1 << 27;

/// A triangle soup in fp32 world space.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Short name (file name without `.obj`/`.obj.gz`).
    pub name: String,
    pub path: PathBuf,
    /// Triangles as vertex positions, in `prim` order.
    pub tris: Vec<[Vec3; 3]>,
    pub bounds: Aabb,
    /// Number of zero-area triangles (loaded, never hit).
    pub degenerate: usize,
    /// Non-fatal problems found while loading (e.g. a missing `.mtl`).
    pub warnings: Vec<String>,
}

impl Scene {
    /// Builds a scene from triangles (tests, instancing). Fails on non-finite coordinates or an
    /// empty list.
    pub fn from_triangles(name: &str, tris: Vec<[Vec3; 3]>) -> Result<Scene, SceneError> {
        let path = PathBuf::from(name);
        if tris.is_empty() {
            return Err(SceneError::NoTriangles { path });
        }
        if tris.len() > MAX_TRIANGLES {
            return Err(SceneError::TooLarge { path, count: tris.len(), max: MAX_TRIANGLES });
        }
        let mut bounds = Aabb::EMPTY;
        let mut degenerate = 0;
        for (i, t) in tris.iter().enumerate() {
            for v in t {
                if !v.is_finite() {
                    return Err(SceneError::NonFinite { path, line: 0, text: format!("triangle {i}: {v:?}") });
                }
                bounds.grow(*v);
            }
            if (t[1] - t[0]).cross(t[2] - t[0]) == Vec3::ZERO {
                degenerate += 1;
            }
        }
        Ok(Scene { name: name.to_string(), path, tris, bounds, degenerate, warnings: Vec::new() })
    }

    pub fn len(&self) -> usize {
        self.tris.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Geometric (unnormalised) normal of triangle `prim`.
    pub fn normal(&self, prim: usize) -> Vec3 {
        let t = &self.tris[prim];
        (t[1] - t[0]).cross(t[2] - t[0])
    }
}

/// The short name a scene file gets (file name without `.gz` and its format's extension).
pub fn scene_name(path: &Path) -> String {
    name_and_format(path).0
}

/// A scene file's name without `.gz` and its format's extension, and the format that
/// extension names (`None`: no known one).
fn name_and_format(path: &Path) -> (String, Option<Format>) {
    let f = path.file_name().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
    let f = f.strip_suffix(".gz").unwrap_or(&f);
    match f.rsplit_once('.').and_then(|(stem, ext)| Some((stem, Format::of_ext(ext)?))) {
        Some((stem, format)) => (stem.to_string(), Some(format)),
        None => (f.to_string(), None),
    }
}

/// A scene file's format, from its extension (after any `.gz`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Obj,
    Gltf,
    Ply,
}

impl Format {
    fn of_ext(ext: &str) -> Option<Format> {
        match ext.to_ascii_lowercase().as_str() {
            "obj" => Some(Format::Obj),
            "gltf" | "glb" => Some(Format::Gltf),
            "ply" => Some(Format::Ply),
            _ => None,
        }
    }

    /// The format of `path` (OBJ for an unknown extension, as before other formats existed).
    pub fn of(path: &Path) -> Format {
        name_and_format(path).1.unwrap_or(Format::Obj)
    }
}

/// Loads an OBJ, glTF (`.gltf`, `.glb`) or PLY file, plain or gzip-compressed (`.gz`) (a
/// progress line when it takes over a second).
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    crate::progress::step(&format!("loading {}", path.display()), || load_quiet(path))
}

fn load_quiet(path: &Path) -> Result<Scene, SceneError> {
    // Only regular files: a FIFO would block and a device such as /dev/zero never ends.
    let meta = std::fs::metadata(path).map_err(|source| SceneError::Io { path: path.into(), source })?;
    if !meta.is_file() {
        return Err(SceneError::Io {
            path: path.into(),
            source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a regular file"),
        });
    }
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io { path: path.into(), source })?;
    let bytes = if path.extension().is_some_and(|e| e == "gz") {
        let mut out = Vec::new();
        flate2::read::GzDecoder::new(&bytes[..])
            .read_to_end(&mut out)
            .map_err(|source| SceneError::Gzip { path: path.into(), source })?;
        out
    } else {
        bytes
    };
    if bytes.iter().all(|b| b.is_ascii_whitespace()) {
        return Err(SceneError::EmptyFile { path: path.into() });
    }
    let format = Format::of(path);
    if format != Format::Obj {
        let mut warnings = Vec::new();
        let tris = match format {
            Format::Gltf => crate::formats::load_gltf(path, &bytes, &mut warnings)?,
            _ => crate::formats::load_ply(path, &bytes)?,
        };
        drop(bytes);
        return finish(path, tris, warnings);
    }
    prescan(path, &bytes)?;

    let opts = tobj::LoadOptions { triangulate: true, single_index: false, ignore_points: true, ignore_lines: true };
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    // Non-UTF-8 bytes (in a comment, say) become U+FFFD instead of failing the whole read; in a
    // statement, prescan has already named the line.
    let text = String::from_utf8_lossy(&bytes);
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
    finish(path, tris, warnings)
}

/// The scene of a loaded triangle list, with the file's name on every error and warning.
fn finish(path: &Path, tris: Vec<[Vec3; 3]>, warnings: Vec<String>) -> Result<Scene, SceneError> {
    let mut scene = Scene::from_triangles(&scene_name(path), tris).map_err(|e| match e {
        SceneError::NoTriangles { .. } => SceneError::NoTriangles { path: path.into() },
        SceneError::TooLarge { count, max, .. } => SceneError::TooLarge { path: path.into(), count, max },
        SceneError::NonFinite { line, text, .. } => SceneError::NonFinite { path: path.into(), line, text },
        other => other,
    })?;
    scene.path = path.into();
    scene.warnings = warnings;
    if scene.degenerate > 0 {
        scene.warnings.push(format!(
            "{}: {} zero-area triangles (kept; they are never hit)",
            path.display(),
            scene.degenerate
        ));
    }
    Ok(scene)
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
