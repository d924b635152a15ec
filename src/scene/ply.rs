//! PLY 1.0 (ascii, binary little- and big-endian): element `vertex` (properties x, y, z of any
//! numeric type) and `face` (`vertex_indices` or `vertex_index`, polygons fanned from their
//! first vertex), or `tristrips` (`vertex_indices`, strips separated by -1), in file order.

use super::{bad, fan_tri, strip_tri, SceneError};
use glam::Vec3;
use std::path::Path;

/// Triangles of a PLY file (ascii or binary, either endian).
pub fn load(path: &Path, bytes: &[u8]) -> Result<Vec<[Vec3; 3]>, SceneError> {
    use ply_rs::ply::Property;
    let parser = ply_rs::parser::Parser::<ply_rs::ply::DefaultElement>::new();
    // Element by element, so that an error names the element, and the data checked to end
    // where the header's counts say it does.
    let mut r = bytes;
    let header = parser.read_header(&mut r).map_err(|e| bad(path, format!("not a valid PLY header: {e}")))?;
    // 1.0 is the only PLY version there is; another is a file this reader cannot know it reads
    // right (ply-rs parses any number).
    let v = &header.version;
    if (v.major, v.minor) != (1, 0) {
        return Err(bad(path, format!("format version {}.{}: this reads PLY 1.0", v.major, v.minor)));
    }
    let mut payload = std::collections::HashMap::new();
    let ascii = matches!(header.encoding, ply_rs::ply::Encoding::Ascii);
    // An ascii element's first line in the file (the parser counts lines per element).
    let mut line = bytes[..bytes.len() - r.len()].iter().filter(|&&b| b == b'\n').count() + 1;
    for (name, def) in &header.elements {
        let at = if ascii { format!(", from line {line}") } else { String::new() };
        let els = parser
            .read_payload_for_element(&mut r, def, &header)
            .map_err(|e| bad(path, format!("element '{name}' ({} declared{at}): {e}", def.count)))?;
        line += def.count;
        payload.insert(name.clone(), els);
    }
    let rest = if ascii { r.iter().filter(|b| !b.is_ascii_whitespace()).count() } else { r.len() };
    if rest > 0 {
        let counts: Vec<String> = header.elements.iter().map(|(n, d)| format!("{} {n}", d.count)).collect();
        return Err(bad(
            path,
            format!(
                "{} bytes of data follow the last element the header declares ({}): the header's counts do not \
                 match the data",
                r.len(),
                counts.join(", ")
            ),
        ));
    }
    let verts = payload.get("vertex").ok_or_else(|| bad(path, "no 'vertex' element".into()))?;
    let num = |p: Option<&Property>| -> Option<f64> {
        Some(match p? {
            Property::Float(x) => *x as f64,
            Property::Double(x) => *x,
            Property::Char(x) => *x as f64,
            Property::UChar(x) => *x as f64,
            Property::Short(x) => *x as f64,
            Property::UShort(x) => *x as f64,
            Property::Int(x) => *x as f64,
            Property::UInt(x) => *x as f64,
            _ => return None,
        })
    };
    let mut pos = Vec::with_capacity(verts.len());
    for (i, e) in verts.iter().enumerate() {
        let c = |k: &str| num(e.get(k)).ok_or_else(|| bad(path, format!("vertex {i}: no numeric property '{k}'")));
        let v = Vec3::new(c("x")? as f32, c("y")? as f32, c("z")? as f32);
        if !v.is_finite() {
            return Err(bad(path, format!("vertex {i} is not finite ({v:?})")));
        }
        pos.push(v);
    }
    let list = |e: &ply_rs::ply::DefaultElement, what: &str| -> Result<Vec<i64>, SceneError> {
        let p = e
            .get("vertex_indices")
            .or_else(|| e.get("vertex_index"))
            .ok_or_else(|| bad(path, format!("{what}: no 'vertex_indices' list")))?;
        Ok(match p {
            Property::ListChar(v) => v.iter().map(|&x| x as i64).collect(),
            Property::ListUChar(v) => v.iter().map(|&x| x as i64).collect(),
            Property::ListShort(v) => v.iter().map(|&x| x as i64).collect(),
            Property::ListUShort(v) => v.iter().map(|&x| x as i64).collect(),
            Property::ListInt(v) => v.iter().map(|&x| x as i64).collect(),
            Property::ListUInt(v) => v.iter().map(|&x| x as i64).collect(),
            _ => return Err(bad(path, format!("{what}: 'vertex_indices' is not an integer list"))),
        })
    };
    let get = |what: &str, i: i64| -> Result<Vec3, SceneError> {
        usize::try_from(i)
            .ok()
            .and_then(|i| pos.get(i).copied())
            .ok_or_else(|| bad(path, format!("{what}: vertex index {i} is out of range ({} vertices)", pos.len())))
    };
    let mut tris = Vec::new();
    if let Some(faces) = payload.get("face") {
        for (f, e) in faces.iter().enumerate() {
            let what = format!("face {f}");
            let ix = list(e, &what)?;
            if ix.len() < 3 {
                return Err(bad(path, format!("{what}: {} vertices (at least 3 needed)", ix.len())));
            }
            for k in 2..ix.len() {
                let [a, b, c] = fan_tri(k);
                tris.push([get(&what, ix[a])?, get(&what, ix[b])?, get(&what, ix[c])?]);
            }
        }
    } else if let Some(strips) = payload.get("tristrips") {
        for (s, e) in strips.iter().enumerate() {
            let what = format!("tristrips {s}");
            for strip in list(e, &what)?.split(|&i| i < 0) {
                for k in 2..strip.len() {
                    let [a, b, c] = strip_tri(k);
                    tris.push([get(&what, strip[a])?, get(&what, strip[b])?, get(&what, strip[c])?]);
                }
            }
        }
    } else {
        return Err(bad(path, "no 'face' or 'tristrips' element".into()));
    }
    Ok(tris)
}
