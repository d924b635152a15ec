//! glTF 2.0 (`.gltf` with its buffers, `.glb`): the default scene (else scene 0, else every
//! mesh once, untransformed), nodes depth first in the order the file lists them, each mesh
//! primitive through its node's world transform (matrix or TRS, composed from the root);
//! triangle lists, strips and fans (points and lines are skipped, with a warning). Positions
//! are read straight from the accessors (float VEC3, byte stride honoured; indices u8/u16/u32),
//! every range checked: nothing in a file can make the loader panic or read outside its
//! buffers.

use super::{bad, fan_tri, strip_tri, SceneError};
use glam::{Mat4, Vec3};
use std::borrow::Cow;
use std::path::{Path, PathBuf};

/// Triangles of a glTF (`.gltf` JSON or `.glb` binary) file; `warnings` gets what was skipped.
pub fn load(path: &Path, bytes: &[u8], warnings: &mut Vec<String>) -> Result<Vec<[Vec3; 3]>, SceneError> {
    let glb = bytes.starts_with(b"glTF");
    if path.to_string_lossy().to_ascii_lowercase().trim_end_matches(".gz").ends_with(".glb") && !glb {
        return Err(bad(path, "not a GLB file: it does not start with the magic 'glTF'".into()));
    }
    if !glb && bytes.iter().find(|b| !b.is_ascii_whitespace()) != Some(&b'{') {
        return Err(bad(path, "not a glTF JSON file: its root is not a JSON object ('{' expected first)".into()));
    }
    let g = gltf::Gltf::from_slice(bytes).map_err(|e| bad(path, format!("not a valid glTF 2.0 file: {e}")))?;
    let json = g.document.as_json();
    let version = &json.asset.version;
    if version.split('.').next() != Some("2") {
        return Err(bad(path, format!("asset.version is {version}; this reads glTF 2.x")));
    }
    check_transforms(path, json)?;
    check_unique(path, json)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    // The GLB binary chunk is borrowed, not copied (often the biggest array of a big scene).
    let mut buffers: Vec<Cow<[u8]>> = Vec::new();
    for b in g.document.buffers() {
        let what = format!("buffer {}", b.index());
        let data =
            match b.source() {
                gltf::buffer::Source::Bin => Cow::Borrowed(g.blob.as_deref().ok_or_else(|| {
                    bad(path, format!("{what} is the GLB binary chunk, which the file does not have"))
                })?),
                gltf::buffer::Source::Uri(uri) => Cow::Owned(read_uri(path, &dir, uri, &what)?),
            };
        if data.len() < b.length() {
            return Err(bad(path, format!("{what}: {} bytes, the file declares {}", data.len(), b.length())));
        }
        // Its declared byteLength is the buffer (a GLB chunk is padded to 4 bytes; a file or
        // data URI holds exactly it): nothing past it is read.
        let pad = if matches!(b.source(), gltf::buffer::Source::Bin) { 3 } else { 0 };
        if data.len() > b.length() + pad {
            return Err(bad(
                path,
                format!("{what}: byteLength {} is smaller than its {} bytes of data", b.length(), data.len()),
            ));
        }
        let data = match data {
            Cow::Borrowed(d) => Cow::Borrowed(&d[..b.length()]),
            Cow::Owned(mut d) => {
                d.truncate(b.length());
                Cow::Owned(d)
            }
        };
        buffers.push(data);
    }
    let doc = &g.document;
    let mut tris = Vec::new();
    let roots: Vec<(gltf::Node, Mat4)> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().map(|n| (n, Mat4::IDENTITY)).collect(),
        None => {
            for m in doc.meshes() {
                mesh_triangles(path, &buffers, &m, Mat4::IDENTITY, &mut tris, warnings)?;
            }
            return Ok(tris);
        }
    };
    // Depth first, children in file order; a node reached twice on one path is a cycle.
    let mut stack: Vec<(gltf::Node, Mat4, Vec<usize>)> =
        roots.into_iter().rev().map(|(n, m)| (n, m, Vec::new())).collect();
    while let Some((node, parent, mut path_nodes)) = stack.pop() {
        if path_nodes.contains(&node.index()) {
            return Err(bad(
                path,
                format!("node {} is its own ancestor (a cycle in the node hierarchy)", node.index()),
            ));
        }
        if path_nodes.len() > 1024 {
            return Err(bad(path, format!("node {}: the hierarchy is deeper than 1024 levels", node.index())));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if !world.is_finite() {
            return Err(bad(path, format!("node {}: its world transform is not finite", node.index())));
        }
        if let Some(m) = node.mesh() {
            mesh_triangles(path, &buffers, &m, world, &mut tris, warnings)?;
        }
        path_nodes.push(node.index());
        let children: Vec<gltf::Node> = node.children().collect();
        for c in children.into_iter().rev() {
            stack.push((c, world, path_nodes.clone()));
        }
    }
    Ok(tris)
}

/// Node transforms as glTF 2.0 allows them: a matrix or TRS, not both; a matrix affine
/// (last row 0 0 0 1); a rotation a unit quaternion (within 10⁻³).
fn check_transforms(path: &Path, json: &gltf::json::Root) -> Result<(), SceneError> {
    for (i, n) in json.nodes.iter().enumerate() {
        let trs = n.translation.is_some() || n.rotation.is_some() || n.scale.is_some();
        if let Some(m) = n.matrix {
            if trs {
                return Err(bad(
                    path,
                    format!("node {i}: both a matrix and translation/rotation/scale (one or the other)"),
                ));
            }
            if m[3] != 0.0 || m[7] != 0.0 || m[11] != 0.0 || m[15] != 1.0 {
                return Err(bad(
                    path,
                    format!(
                        "node {i}: the matrix is not affine (last row {} {} {} {}, expected 0 0 0 1)",
                        m[3], m[7], m[11], m[15]
                    ),
                ));
            }
        }
        if let Some(q) = &n.rotation {
            let len = q.0.iter().map(|x| x * x).sum::<f32>().sqrt();
            if !len.is_finite() || (len - 1.0).abs() > 1e-3 {
                return Err(bad(path, format!("node {i}: rotation {:?} is not a unit quaternion (length {len})", q.0)));
            }
        }
    }
    Ok(())
}

/// Scenes' `nodes` and nodes' `children` list each node once (glTF 2.0's schema says
/// `uniqueItems`): a node listed twice would have its meshes' triangles loaded twice, two
/// copies in one place whose hits tie.
fn check_unique(path: &Path, json: &gltf::json::Root) -> Result<(), SceneError> {
    let twice = |list: &[gltf::json::Index<gltf::json::Node>]| {
        list.iter().enumerate().find(|(i, n)| list[..*i].contains(n)).map(|(_, n)| n.value())
    };
    for (i, s) in json.scenes.iter().enumerate() {
        if let Some(n) = twice(&s.nodes) {
            return Err(bad(path, format!("scene {i} lists node {n} twice (a scene's nodes are unique in glTF 2.0)")));
        }
    }
    let mut parent: Vec<Option<usize>> = vec![None; json.nodes.len()];
    for (i, node) in json.nodes.iter().enumerate() {
        if let Some(n) = node.children.as_deref().and_then(twice) {
            return Err(bad(
                path,
                format!("node {i} lists child {n} twice (a node's children are unique in glTF 2.0)"),
            ));
        }
        // One parent per node (glTF 2.0): a node under two parents would load twice.
        for c in node.children.iter().flatten().map(|c| c.value()) {
            match parent.get(c).copied().flatten() {
                Some(p) => {
                    return Err(bad(
                        path,
                        format!(
                            "node {c} is a child of both node {p} and node {i} (a node has one parent in glTF 2.0)"
                        ),
                    ))
                }
                None if c < parent.len() => parent[c] = Some(i),
                None => {}
            }
        }
    }
    Ok(())
}

/// The bytes of a buffer URI: a `data:` URI (base64) or a file beside the glTF.
fn read_uri(path: &Path, dir: &Path, uri: &str, what: &str) -> Result<Vec<u8>, SceneError> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, b64) =
            rest.split_once(";base64,").ok_or_else(|| bad(path, format!("{what}: a data URI that is not base64")))?;
        use base64::Engine;
        return base64::engine::general_purpose::STANDARD
            .decode(b64.trim())
            .map_err(|e| bad(path, format!("{what}: invalid base64 data URI: {e}")));
    }
    if uri.contains("://") {
        return Err(bad(
            path,
            format!("{what}: URI '{uri}' is not a file beside the glTF (halftrace reads no network)"),
        ));
    }
    let f: PathBuf = dir.join(percent_decode(uri));
    let meta = std::fs::metadata(&f).map_err(|e| bad(path, format!("{what}: {}: {e}", f.display())))?;
    if !meta.is_file() {
        return Err(bad(path, format!("{what}: {} is not a regular file", f.display())));
    }
    // Files beside the glTF (its folder and below) only, unless HALFTRACE_GLTF_ANY_URI=1: an
    // absolute URI or one that climbs with `..` (or a link out) would read anything.
    if std::env::var_os("HALFTRACE_GLTF_ANY_URI").is_none_or(|v| v != "1") {
        let base = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
        let inside = match (f.canonicalize(), base.canonicalize()) {
            (Ok(f), Ok(d)) => f.starts_with(&d),
            _ => false,
        };
        if !inside {
            return Err(bad(
                path,
                format!(
                    "{what}: URI '{uri}' is outside the glTF's folder ({}); buffers are read from files beside it \
                     (HALFTRACE_GLTF_ANY_URI=1 allows others)",
                    base.display()
                ),
            ));
        }
    }
    std::fs::read(&f).map_err(|e| bad(path, format!("{what}: {}: {e}", f.display())))
}

/// `%XX` escapes of a relative URI decoded (anything else kept as is).
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let hex = |c: u8| (c as char).to_digit(16).map(|d| d as u8);
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 3 <= b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push(h * 16 + l);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The bytes of element `i` of an accessor (every range checked).
struct View<'b> {
    data: &'b [u8],
    start: usize,
    stride: usize,
    count: usize,
    size: usize,
}

impl View<'_> {
    fn elem(&self, i: usize) -> &[u8] {
        let o = self.start + i * self.stride;
        &self.data[o..o + self.size]
    }
}

fn view<'b>(path: &Path, buffers: &'b [Cow<[u8]>], a: &gltf::Accessor, what: &str) -> Result<View<'b>, SceneError> {
    if a.sparse().is_some() {
        return Err(bad(path, format!("{what}: sparse accessors are not supported")));
    }
    let v = a.view().ok_or_else(|| bad(path, format!("{what}: accessor {} has no buffer view", a.index())))?;
    let data = &buffers[v.buffer().index()];
    let size = a.size();
    let stride = v.stride().unwrap_or(size).max(size);
    let start = v.offset().checked_add(a.offset()).ok_or_else(|| bad(path, format!("{what}: offset overflows")))?;
    let count = a.count();
    let view_end = v.offset().checked_add(v.length()).filter(|&e| e <= data.len()).ok_or_else(|| {
        bad(path, format!("{what}: buffer view {} runs past its buffer ({} bytes)", v.index(), data.len()))
    })?;
    if count > 0 {
        let last = (count - 1).checked_mul(stride).and_then(|x| x.checked_add(start)).and_then(|x| x.checked_add(size));
        match last {
            Some(end) if end <= view_end => {}
            _ => {
                return Err(bad(
                    path,
                    format!(
                    "{what}: accessor {} ({count} elements of {size} bytes, stride {stride}) runs past buffer view {}",
                    a.index(),
                    v.index()
                ),
                ))
            }
        }
    }
    Ok(View { data, start, stride, count, size })
}

fn mesh_triangles(
    path: &Path,
    buffers: &[Cow<[u8]>],
    m: &gltf::Mesh,
    world: Mat4,
    tris: &mut Vec<[Vec3; 3]>,
    warnings: &mut Vec<String>,
) -> Result<(), SceneError> {
    use gltf::accessor::{DataType, Dimensions};
    use gltf::mesh::{Mode, Semantic};
    for p in m.primitives() {
        let what = format!("mesh {} ('{}') primitive {}", m.index(), m.name().unwrap_or(""), p.index());
        let mode = p.mode();
        if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
            warnings.push(format!("{}: {what}: {mode:?} skipped (triangles only)", path.display()));
            continue;
        }
        let pa = p.get(&Semantic::Positions).ok_or_else(|| bad(path, format!("{what}: no POSITION attribute")))?;
        if pa.data_type() != DataType::F32 || pa.dimensions() != Dimensions::Vec3 {
            return Err(bad(
                path,
                format!("{what}: POSITION is {:?} {:?}, expected float VEC3", pa.data_type(), pa.dimensions()),
            ));
        }
        let pv = view(path, buffers, &pa, &format!("{what} POSITION"))?;
        let mut pos = Vec::with_capacity(pv.count);
        for i in 0..pv.count {
            let e = pv.elem(i);
            let f = |k: usize| f32::from_le_bytes([e[4 * k], e[4 * k + 1], e[4 * k + 2], e[4 * k + 3]]);
            let v = Vec3::new(f(0), f(1), f(2));
            if !v.is_finite() {
                return Err(bad(path, format!("{what}: vertex {i} is not finite ({v:?})")));
            }
            pos.push(world.transform_point3(v));
        }
        let idx: Vec<u32> = match p.indices() {
            None => (0..pos.len() as u32).collect(),
            Some(ia) => {
                if ia.dimensions() != Dimensions::Scalar {
                    return Err(bad(path, format!("{what}: indices are {:?}, expected SCALAR", ia.dimensions())));
                }
                let iv = view(path, buffers, &ia, &format!("{what} indices"))?;
                let mut out = Vec::with_capacity(iv.count);
                for i in 0..iv.count {
                    let e = iv.elem(i);
                    out.push(match ia.data_type() {
                        DataType::U8 => e[0] as u32,
                        DataType::U16 => u16::from_le_bytes([e[0], e[1]]) as u32,
                        DataType::U32 => u32::from_le_bytes([e[0], e[1], e[2], e[3]]),
                        t => return Err(bad(path, format!("{what}: indices of type {t:?} (u8, u16 or u32 expected)"))),
                    });
                }
                out
            }
        };
        if let Some((k, &i)) = idx.iter().enumerate().find(|(_, &i)| i as usize >= pos.len()) {
            return Err(bad(path, format!("{what}: index {k} is {i}, but there are {} vertices", pos.len())));
        }
        let v = |i: u32| pos[i as usize];
        match mode {
            Mode::Triangles => {
                if !idx.len().is_multiple_of(3) {
                    warnings.push(format!(
                        "{}: {what}: {} indices is not a multiple of 3; the last {} ignored",
                        path.display(),
                        idx.len(),
                        idx.len() % 3
                    ));
                }
                tris.extend(idx.chunks_exact(3).map(|t| [v(t[0]), v(t[1]), v(t[2])]));
            }
            Mode::TriangleStrip => tris.extend((2..idx.len()).map(|i| strip_tri(i).map(|k| v(idx[k])))),
            _ => tris.extend((2..idx.len()).map(|i| fan_tri(i).map(|k| v(idx[k])))),
        }
    }
    Ok(())
}
