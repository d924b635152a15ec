//! Scene formats: PLY (ascii, binary both endians) and glTF (`.gltf` with external or data-URI
//! buffers, `.glb`) load the triangles they describe — through node transforms, strips and
//! fans — and trace to the hits of the same triangles from OBJ; bad files are errors naming
//! the file and the element, never a panic.

mod common;
use common::*;
use glam::{Mat4, Quat, Vec3};
use halftrace::layout::LayoutId;
use halftrace::scene::{self, Scene};
use std::path::PathBuf;

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("halftrace-formats-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The scene's triangle soup as PLY: 3 vertices per triangle, one face each.
fn ply(s: &Scene, format: &str) -> Vec<u8> {
    let mut out = format!("ply\nformat {format} 1.0\ncomment from halftrace tests\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n", 3 * s.len(), s.len()).into_bytes();
    let be = format == "binary_big_endian";
    let f = |x: f32, o: &mut Vec<u8>| o.extend_from_slice(&if be { x.to_be_bytes() } else { x.to_le_bytes() });
    let i = |x: i32, o: &mut Vec<u8>| o.extend_from_slice(&if be { x.to_be_bytes() } else { x.to_le_bytes() });
    for t in &s.tris {
        for v in t {
            if format == "ascii" {
                out.extend_from_slice(format!("{} {} {}\n", v.x, v.y, v.z).as_bytes());
            } else {
                f(v.x, &mut out);
                f(v.y, &mut out);
                f(v.z, &mut out);
            }
        }
    }
    for k in 0..s.len() as i32 {
        if format == "ascii" {
            out.extend_from_slice(format!("3 {} {} {}\n", 3 * k, 3 * k + 1, 3 * k + 2).as_bytes());
        } else {
            out.push(3);
            for j in 0..3 {
                i(3 * k + j, &mut out);
            }
        }
    }
    out
}

fn same_hits(a: &Scene, b: &Scene) {
    let of = |s: &Scene| Prepared { scene: s.clone(), bin: halftrace::bvh::build_binary(s) };
    let (pa, pb) = (of(a), of(b));
    let mut hits = 0;
    for (kind, rays) in ray_sets(&pa, 64, 500) {
        let ha = encode(&pa, LayoutId::f32(), 4).reference_default(&rays).0;
        let hb = encode(&pb, LayoutId::f32(), 4).reference_default(&rays).0;
        hits += ha.iter().filter(|h| h.is_hit()).count();
        assert_same_hits(&format!("{} vs {} {kind}", a.path.display(), b.path.display()), &rays, &ha, &hb);
    }
    assert!(hits > 1000, "only {hits} hits; the test would be vacuous");
}

#[test]
fn ply_copies_trace_to_the_obj_hits_exactly() {
    let obj = load("fandisk.obj");
    for format in ["ascii", "binary_little_endian", "binary_big_endian"] {
        let p = dir().join(format!("fandisk_{format}.ply"));
        std::fs::write(&p, ply(&obj, format)).unwrap();
        let s = scene::load(&p).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.name, format!("fandisk_{format}"));
        assert_eq!(s.tris, obj.tris, "{format}: other triangles");
        same_hits(&obj, &s);
    }
}

#[test]
fn ply_strips_and_polygons() {
    let d = dir();
    // A quad as one polygon (fanned), and the same quad as a strip of two triangles.
    let quad = "ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
    let p = d.join("quad.ply");
    std::fs::write(&p, quad).unwrap();
    let s = scene::load(&p).unwrap();
    let v = |x: f32, y: f32| Vec3::new(x, y, 0.0);
    assert_eq!(s.tris, vec![[v(0., 0.), v(1., 0.), v(1., 1.)], [v(0., 0.), v(1., 1.), v(0., 1.)]]);
    let strip = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement tristrips 1\nproperty list int int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n5 0 1 2 3 -1\n";
    let p = d.join("strip.ply");
    std::fs::write(&p, strip).unwrap();
    let s = scene::load(&p).unwrap();
    assert_eq!(s.tris, vec![[v(0., 0.), v(1., 0.), v(0., 1.)], [v(0., 1.), v(1., 0.), v(1., 1.)]]);
}

/// A .gltf with two buffers (an external .bin and a data URI), a node hierarchy (matrix and
/// TRS), an indexed triangle list, a strip, a fan and a line primitive (skipped).
#[test]
fn gltf_node_transforms_strips_and_fans() {
    use base64::Engine;
    let d = dir();
    let pts: [[f32; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let mut pos = Vec::new();
    for p in pts {
        for c in p {
            pos.extend_from_slice(&c.to_le_bytes());
        }
    }
    std::fs::write(d.join("quad pos.bin"), &pos).unwrap();
    let idx: Vec<u8> = [0u16, 1, 2, 0, 2, 3].iter().flat_map(|i| i.to_le_bytes()).collect();
    let idx_uri =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&idx));
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
        "nodes":[{{"children":[1],"matrix":[2,0,0,0, 0,2,0,0, 0,0,2,0, 10,0,0,1]}},
                 {{"mesh":0,"translation":[0,0,5],"rotation":[0,0,0.70710677,0.70710677],"scale":[1,1,3]}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}},
                                  {{"attributes":{{"POSITION":0}},"mode":5}},
                                  {{"attributes":{{"POSITION":0}},"mode":6}},
                                  {{"attributes":{{"POSITION":0}},"mode":1}}]}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
                     {{"bufferView":1,"componentType":5123,"count":6,"type":"SCALAR"}}],
        "bufferViews":[{{"buffer":0,"byteLength":48}},{{"buffer":1,"byteLength":12}}],
        "buffers":[{{"byteLength":48,"uri":"quad%20pos.bin"}},{{"byteLength":12,"uri":"{idx_uri}"}}]}}"#
    );
    let p = d.join("quad.gltf");
    std::fs::write(&p, json).unwrap();
    let s = scene::load(&p).unwrap_or_else(|e| panic!("{e}"));
    assert!(s.warnings.iter().any(|w| w.contains("Lines skipped")), "{:?}", s.warnings);
    let world = Mat4::from_cols_array(&[2., 0., 0., 0., 0., 2., 0., 0., 0., 0., 2., 0., 10., 0., 0., 1.])
        * Mat4::from_scale_rotation_translation(
            Vec3::new(1., 1., 3.),
            Quat::from_xyzw(0., 0., 0.70710677, 0.70710677),
            Vec3::new(0., 0., 5.),
        );
    let w = |i: usize| world.transform_point3(Vec3::from(pts[i]));
    let want = [
        [w(0), w(1), w(2)],
        [w(0), w(2), w(3)], // list
        [w(0), w(1), w(2)],
        [w(2), w(1), w(3)], // strip (winding kept)
        [w(0), w(1), w(2)],
        [w(0), w(2), w(3)], // fan
    ];
    assert_eq!(s.tris.len(), want.len());
    for (k, (a, b)) in s.tris.iter().zip(want.iter()).enumerate() {
        for j in 0..3 {
            assert!(
                (a[j] - b[j]).length() <= 1e-5 * (1.0 + b[j].length()),
                "triangle {k} vertex {j}: {:?} vs {:?}",
                a[j],
                b[j]
            );
        }
    }
}

/// `halftrace instance` writes a GLB of N transformed copies; it loads back with every copy
/// where its node puts it.
#[test]
fn instanced_glb_loads_every_copy() {
    let src = load("teapot.obj");
    let bytes = halftrace::scene::instance::instanced_glb(&src, 5, 3);
    let p = dir().join("teapots.glb");
    std::fs::write(&p, &bytes).unwrap();
    let s = scene::load(&p).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.len(), 5 * src.len());
    assert_eq!(s.name, "teapots");
    let g = gltf::Gltf::from_slice(&bytes).unwrap();
    let nodes: Vec<_> = g.document.nodes().collect();
    for (k, n) in nodes.iter().enumerate() {
        let (t, r, sc) = n.transform().decomposed();
        let m = Mat4::from_scale_rotation_translation(Vec3::from(sc), Quat::from_array(r), Vec3::from(t));
        for (i, tri) in src.tris.iter().enumerate().step_by(97) {
            for (j, &v) in tri.iter().enumerate() {
                let want = m.transform_point3(v);
                let got = s.tris[k * src.len() + i][j];
                assert!(
                    (got - want).length() <= 1e-5 * (1.0 + want.length()),
                    "copy {k} triangle {i}: {got:?} vs {want:?}"
                );
            }
        }
    }
}

/// A glTF with one triangle in node 0 (its mesh), node 1 (children `children`, no mesh), and
/// scene 0 listing `nodes`; it loads with each list free of repeats.
fn gltf_listing(nodes: &str, children: &str) -> String {
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":{nodes}}}],
        "nodes":[{{"mesh":0}},{{"children":{children}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}}]}}"#
    )
}

#[test]
fn gltf_lists_without_repeats_load() {
    for (nodes, children, tris) in [("[0]", "[]", 1), ("[1]", "[0]", 1), ("[0, 1]", "[]", 1)] {
        let p = dir().join("listing.gltf");
        std::fs::write(&p, gltf_listing(nodes, children)).unwrap();
        let s = scene::load(&p).unwrap_or_else(|e| panic!("{nodes} {children}: {e}"));
        assert_eq!(s.len(), tris, "{nodes} {children}");
    }
}

#[test]
fn bad_files_name_the_file_and_element() {
    let d = dir();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n3 0 1 7\n".to_vec(), "face 0: vertex index 1 is out of range"),
        ("trunc.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x00\x00".to_vec(), "element 'vertex' (3 declared): "),
        ("nan.ply", [&b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"[..], &f32::NAN.to_le_bytes(), &[0u8; 8]].concat(), "vertex 0 is not finite"),
        ("word.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 zero\n".to_vec(), "element 'vertex' (1 declared, from line 8): "),
        ("noface.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n".to_vec(), "no 'face' or 'tristrips' element"),
        ("notjson.gltf", b"{ this is not json".to_vec(), "not a valid glTF 2.0 file"),
        ("missing.gltf", br#"{"asset":{"version":"2.0"},"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}],"bufferViews":[{"buffer":0,"byteLength":36}],"buffers":[{"byteLength":36,"uri":"nowhere.bin"}]}"#.to_vec(), "buffer 0: "),
        ("short.gltf", br#"{"asset":{"version":"2.0"},"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"accessors":[{"bufferView":0,"componentType":5126,"count":30,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}],"bufferViews":[{"buffer":0,"byteLength":36}],"buffers":[{"byteLength":36,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]}"#.to_vec(), "runs past buffer view 0"),
        ("empty.glb", b"glTF\x02\x00\x00\x00\x0c\x00\x00\x00".to_vec(), "not a valid glTF 2.0 file"),
        ("v2.ply", b"ply\nformat ascii 2.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n".to_vec(), "format version 2.0: this reads PLY 1.0"),
        ("v1_1.ply", b"ply\nformat binary_little_endian 1.1\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec(), "format version 1.1"),
        ("twice.gltf", gltf_listing("[0, 0]", "[]").into_bytes(), "scene 0 lists node 0 twice"),
        ("child_twice.gltf", gltf_listing("[1]", "[0, 0]").into_bytes(), "node 1 lists child 0 twice"),
        ("lines.gltf", br#"{"asset":{"version":"2.0"},"meshes":[{"primitives":[{"attributes":{"POSITION":0},"mode":1}]}],"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}],"bufferViews":[{"buffer":0,"byteLength":36}],"buffers":[{"byteLength":36,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]}"#.to_vec(), "scene has no triangles — mesh 0 ('') primitive 0: Lines skipped"),
    ];
    for (name, bytes, want) in cases {
        let p = d.join(name);
        std::fs::write(&p, bytes).unwrap();
        let e = match scene::load(&p) {
            Ok(s) => panic!("{name}: loaded {} triangles, expected an error", s.len()),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(&p.display().to_string()) && e.contains(want), "{name}: {e}");
    }
}

/// An OBJ that starts with a UTF-8 byte-order mark loads the same triangles as without it (the
/// mark once hid the first vertex line).
#[test]
fn an_obj_with_a_byte_order_mark_loads_every_vertex() {
    let d = dir();
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n";
    let (plain, bom) = (d.join("plain.obj"), d.join("bom.obj"));
    std::fs::write(&plain, text).unwrap();
    std::fs::write(&bom, [&b"\xEF\xBB\xBF"[..], text.as_bytes()].concat()).unwrap();
    let (a, b) = (scene::load(&plain).unwrap(), scene::load(&bom).unwrap());
    assert_eq!(b.len(), 2);
    assert_eq!(a.tris, b.tris);
}

/// A node that is the child of two nodes (glTF 2.0 allows one parent) is refused, naming both,
/// instead of loading twice.
#[test]
fn a_gltf_node_with_two_parents_is_refused() {
    let p = dir().join("two-parents.gltf");
    let text = gltf_listing("[1, 2]", "[0]").replace(r#"{"children":[0]}],"#, r#"{"children":[0]},{"children":[0]}],"#);
    assert!(text.contains(r#"{"children":[0]},{"children":[0]}"#), "{text}");
    std::fs::write(&p, text).unwrap();
    let e = scene::load(&p).unwrap_err().to_string();
    assert!(e.contains("node 0 is a child of both node 1 and node 2"), "{e}");
}
