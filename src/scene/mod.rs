//! Scenes: a triangle soup in fp32 world space ([`Scene`]) read from a Wavefront OBJ
//! ([`obj`]), glTF 2.0 (`.gltf`, `.glb`: [`gltf`]) or PLY ([`ply`]) file, each plain or
//! gzip-compressed (`.gz`), or made by instancing ([`instance`]). A triangle's index in the
//! loader's order is its public `prim` id. Every error names the file and the line or element.

pub mod gltf;
pub mod instance;
pub mod obj;
pub mod ply;

use crate::base::{Aabb, ClosestBox, ClosestTrue, Hit, Ray, RayPre};
use glam::Vec3;
use std::io::Read;
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
    /// `skipped`: what the file held that is not triangles (" (…)" or empty).
    #[error("{path}: scene has no triangles{skipped}")]
    NoTriangles { path: PathBuf, skipped: String },
    #[error("{path}: scene has {count} triangles; at most {max} are supported")]
    TooLarge { path: PathBuf, count: usize, max: usize },
    /// The path is quoted and escaped: it holds the character the message is about.
    #[error(
        "{path:?}: the scene's name {name:?} (its file name) cannot name rows and table cells: it is blank or has a \
         control character or '|' — rename the file"
    )]
    Name { path: PathBuf, name: String },
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
    /// Number of zero-area triangles: three vertices exactly on one line (loaded; the
    /// closest-hit rule never hits them, `base::exact::collinear`).
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
            return Err(SceneError::NoTriangles { path, skipped: String::new() });
        }
        if tris.len() > MAX_TRIANGLES {
            return Err(SceneError::TooLarge { path, count: tris.len(), max: MAX_TRIANGLES });
        }
        let mut bounds = Aabb::EMPTY;
        for (i, t) in tris.iter().enumerate() {
            for v in t {
                if !v.is_finite() {
                    return Err(SceneError::NonFinite { path, line: 0, text: format!("triangle {i}: {v:?}") });
                }
                bounds.grow(*v);
            }
        }
        let mut scene = Scene { name: name.to_string(), path, tris, bounds, degenerate: 0, warnings: Vec::new() };
        scene.degenerate = (0..scene.len()).filter(|&i| crate::base::exact::collinear(&scene.verts(i))).count();
        Ok(scene)
    }

    pub fn len(&self) -> usize {
        self.tris.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// The closest hit of `ray` among every triangle, tested one by one under the closest-hit
    /// rule ([`ClosestTrue`], exact mode): the oracle of every conservative traversal.
    pub fn brute_force(&self, ray: &Ray) -> Hit {
        self.brute_force_counted(ray).0
    }

    /// [`Self::brute_force`], and how many of its tests took the exact path.
    pub fn brute_force_counted(&self, ray: &Ray) -> (Hit, u32) {
        let best = ClosestTrue::brute_force(ray, (0..self.tris.len()).map(|i| (self.verts(i), i as i32)));
        (best.hit(), best.rare)
    }

    /// The closest hit under the box rule that the true rule replaced ([`ClosestBox`]), for
    /// showing what it loses.
    pub fn brute_force_box(&self, ray: &Ray) -> Hit {
        let r = RayPre::new(ray);
        let mut best = ClosestBox::new(ray.tmax, self.hit_pad());
        for i in 0..self.tris.len() {
            best.test(&r, &self.verts(i), i as i32);
        }
        best.hit()
    }

    /// Re-traces the rays that a traversal flagged (`Hit::is_flagged`: fp32 could not decide
    /// one of their triangles) with the exact rule, in place, on every core; returns how many
    /// there were. The brute force gives the hit every conservative traversal's exact mode
    /// would (the rule's hit is the brute-force minimum).
    pub fn resolve(&self, rays: &[Ray], hits: &mut [Hit]) -> usize {
        crate::base::resolve_flagged(rays, hits, |r| self.brute_force(r))
    }

    /// The padding of every triangle's box in the box rule (`base::hit_pad` of the scene's
    /// bounds), which the BVH is still refitted with (`bvh::build`).
    pub fn hit_pad(&self) -> f32 {
        crate::base::hit_pad(&self.bounds)
    }

    /// Triangle `prim`'s vertices as the triangle tests take them (x, y, z of each in turn).
    pub fn verts(&self, prim: usize) -> [f32; 9] {
        let t = &self.tris[prim];
        [t[0].x, t[0].y, t[0].z, t[1].x, t[1].y, t[1].z, t[2].x, t[2].y, t[2].z]
    }

    /// Geometric (unnormalised) normal of triangle `prim`.
    pub fn normal(&self, prim: usize) -> Vec3 {
        let t = &self.tris[prim];
        (t[1] - t[0]).cross(t[2] - t[0])
    }
}

/// Where the extra scenes are when no `--scenes-dir` is given: the repository's test scenes
/// (`tests/scenes`, run from the repository root), else the project's shared set
/// (`../shared/scenes`), else none.
pub fn default_scenes_dir() -> Option<PathBuf> {
    ["tests/scenes", "../shared/scenes"].into_iter().map(PathBuf::from).find(|d| d.is_dir())
}

/// The `.obj` and `.obj.gz` scenes in a folder, sorted by path (`--scenes-dir`).
pub fn obj_files_in(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.to_string_lossy().ends_with(".obj") || p.to_string_lossy().ends_with(".obj.gz"))
        .collect();
    found.sort();
    Ok(found)
}

/// The short name a scene file gets (file name without `.gz` and its format's extension).
pub fn scene_name(path: &Path) -> String {
    name_and_format(path).0
}

/// A scene file's short name ([`scene_name`]), refused where it cannot stand in a report: rows,
/// Markdown cells and file names of the outputs carry it, so it must be non-blank and printable
/// without '|' (a newline would split a table), as a user kernel's name must be.
pub fn checked_name(path: &Path) -> Result<String, SceneError> {
    let name = scene_name(path);
    if name.trim().is_empty() || name.chars().any(|c| c.is_control() || c == '|') {
        return Err(SceneError::Name { path: path.into(), name });
    }
    Ok(name)
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
    checked_name(path)?;
    // Only regular files: a FIFO would block and a device such as /dev/zero never ends.
    let meta = std::fs::metadata(path).map_err(|source| SceneError::Io { path: path.into(), source })?;
    if !meta.is_file() {
        return Err(SceneError::Io {
            path: path.into(),
            source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a regular file"),
        });
    }
    // A scene is held in memory several times over while it loads (text, parsed vertices,
    // triangles, then the BVH): its text may take at most an eighth of the memory this process
    // can have, checked before reading and while decompressing (a gzip bomb is refused, not
    // an abort on allocation).
    let limit = scene_byte_limit();
    let too_big = |what: &str| SceneError::Invalid {
        path: path.into(),
        msg: format!(
            "{what} more than {} MB, the most a scene may take here (an eighth of the {} MB this process may use)",
            limit >> 20,
            (limit * 8) >> 20
        ),
    };
    if meta.len() > limit {
        return Err(too_big("the file holds"));
    }
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io { path: path.into(), source })?;
    // gzip by its magic, whatever the name; every member of a multi-member file.
    let gz = bytes.starts_with(&[0x1f, 0x8b]);
    if path.extension().is_some_and(|e| e == "gz") && !gz {
        let source = std::io::Error::new(std::io::ErrorKind::InvalidData, "no gzip header (magic 1f 8b)");
        return Err(SceneError::Gzip { path: path.into(), source });
    }
    let bytes = if gz {
        let mut out = Vec::new();
        flate2::read::MultiGzDecoder::new(&bytes[..])
            .take(limit + 1)
            .read_to_end(&mut out)
            .map_err(|source| SceneError::Gzip { path: path.into(), source })?;
        if out.len() as u64 > limit {
            return Err(too_big("it decompresses to"));
        }
        out
    } else {
        bytes
    };
    if bytes.iter().all(|b| b.is_ascii_whitespace()) {
        return Err(SceneError::EmptyFile { path: path.into() });
    }
    let mut warnings = Vec::new();
    let tris = match Format::of(path) {
        Format::Obj => {
            let (tris, w) = obj::load(path, &bytes)?;
            warnings = w;
            tris
        }
        Format::Gltf => gltf::load(path, &bytes, &mut warnings)?,
        Format::Ply => ply::load(path, &bytes)?,
    };
    drop(bytes);
    finish(path, tris, warnings)
}

/// The most bytes of scene text (decompressed) a load accepts: an eighth of the memory this
/// process may use — the smaller of the machine's available memory and the address-space
/// limit (`ulimit -v`) — and at least 64 MiB.
pub fn scene_byte_limit() -> u64 {
    let kib = |text: &str, key: &str| {
        text.lines().find(|l| l.starts_with(key)).and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
    };
    let mut mem = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| kib(&m, "MemAvailable:"))
        .map(|k| k * 1024)
        .unwrap_or(16 << 30);
    if let Some(limit) = std::fs::read_to_string("/proc/self/limits").ok().and_then(|t| {
        let l = t.lines().find(|l| l.starts_with("Max address space"))?;
        l.split_whitespace().nth(3)?.parse::<u64>().ok()
    }) {
        mem = mem.min(limit);
    }
    (mem / 8).max(64 << 20)
}

/// The scene of a loaded triangle list, with the file's name on every error and warning.
fn finish(path: &Path, tris: Vec<[Vec3; 3]>, warnings: Vec<String>) -> Result<Scene, SceneError> {
    let mut scene = Scene::from_triangles(&scene_name(path), tris).map_err(|e| match e {
        SceneError::NoTriangles { .. } => {
            // What was skipped is why there is nothing (a glTF of lines or points).
            let prefix = format!("{}: ", path.display());
            let what: Vec<&str> = warnings.iter().map(|w| w.strip_prefix(&prefix).unwrap_or(w)).collect();
            let skipped = if what.is_empty() { String::new() } else { format!(" — {}", what.join("; ")) };
            SceneError::NoTriangles { path: path.into(), skipped }
        }
        SceneError::TooLarge { count, max, .. } => SceneError::TooLarge { path: path.into(), count, max },
        SceneError::NonFinite { line, text, .. } => SceneError::NonFinite { path: path.into(), line, text },
        other => other,
    })?;
    scene.path = path.into();
    scene.warnings = warnings;
    if scene.degenerate > 0 {
        scene.warnings.push(format!(
            "{}: {} zero-area triangles (all three vertices on one line; kept, and never hit: the closest-hit rule \
             takes only crossings of a triangle with area)",
            path.display(),
            scene.degenerate
        ));
    }
    Ok(scene)
}

fn bad(path: &Path, msg: String) -> SceneError {
    SceneError::Invalid { path: path.into(), msg }
}

/// Triangle `i` (≥ 2) of a strip, as positions in the strip: every other one swaps its first
/// two vertices, keeping the winding (glTF and PLY strips alike).
fn strip_tri(i: usize) -> [usize; 3] {
    if i.is_multiple_of(2) {
        [i - 2, i - 1, i]
    } else {
        [i - 1, i - 2, i]
    }
}

/// Triangle `i` (≥ 2) of a fan (a glTF fan, a PLY polygon), as positions in it.
fn fan_tri(i: usize) -> [usize; 3] {
    [0, i - 1, i]
}
