//! `halftrace isa` on RADV's null device for RDNA3 (AMD's compiler, no GPU): every kernel of
//! the default matrix builds and reports the driver's statistics and its disassembly's mix,
//! under the validation layer; `report` renders the folder; and null devices are refused by
//! every command that would run on them, naming `isa`.

use super::*;
use halftrace::isa::{plan, Matrix};
use halftrace::report::isa::IsaRow;

const RADV_ICD: &str = "/usr/share/vulkan/icd.d/radeon_icd.json";

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("halftrace-isa-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn isa_builds_every_kernel_on_a_null_device() {
    assert!(
        std::path::Path::new(RADV_ICD).exists(),
        "{RADV_ICD} is missing: RADV (mesa-vulkan-drivers, scripts/install-deps.sh) provides the null devices"
    );
    let out = tmp("navi31");
    let bin = env!("CARGO_BIN_EXE_halftrace");
    let o = Command::new(bin)
        .args(["isa", "--family", "navi31", "--validation", "--quiet", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "isa failed:\n{stdout}\n{stderr}");
    let rows: Vec<IsaRow> = serde_json::from_str(&std::fs::read_to_string(out.join("isa.json")).unwrap()).unwrap();
    assert_eq!(rows.len(), plan(Matrix::Default, &[]).len(), "one row per kernel of the default matrix");
    for r in &rows {
        assert!(r.status.is_ok(), "{} on {}: {}", r.kernel, r.device, r.status);
        assert_eq!(r.family, "navi31");
        assert_eq!(r.generation, "RDNA3");
        for (what, v) in
            [("VGPRs", r.vgprs), ("scratch", r.scratch_bytes), ("waves", r.waves_per_simd), ("instr", r.instructions)]
        {
            assert!(v.is_some_and(|v| v > 0.0), "{}: no {what} statistic ({:?})", r.kernel, r.stats);
        }
        let a = r.asm.unwrap_or_else(|| panic!("{}: no disassembly counts", r.kernel));
        assert!(a.valu > 0 && a.scratch_loads.is_some() && a.scratch_stores.is_some(), "{}: {a:?}", r.kernel);
        // The disassembly's vector ALU count is the driver's, but for what it could not decode.
        let driver = r.valu.unwrap() as u64;
        assert!(a.valu <= driver && driver <= a.valu + a.undecoded, "{}: {a:?} against VALU {driver}", r.kernel);
        let q = r.vs_f32.unwrap_or_else(|| panic!("{}: no ratio to f32", r.kernel));
        if r.layout == "f32" {
            assert_eq!((q.vgprs, q.scratch), (Some(1.0), Some(1.0)));
        }
    }
    // f16h's stack (P = 1, every math): one group per visit (trav.comp, DEFER_ENTRIES). At
    // B = 2 as many groups as there were entries, larger than f32's, so more scratch; at B = 4
    // and 8 at most 2× f32's scratch and VGPRs (it was 5× and 2.4× with an entry per child;
    // f16h at B = 8 needs 84 VGPRs, f32 48 since it keeps no ChildHits beside their keys).
    for r in rows.iter().filter(|r| r.layout == "f16h" && r.packet == 1) {
        let f = rows.iter().find(|f| f.layout == "f32" && f.packet == 1 && f.branching == r.branching).unwrap();
        let (s, fs) = (r.scratch_bytes.unwrap(), f.scratch_bytes.unwrap());
        let (v, fv) = (r.vgprs.unwrap(), f.vgprs.unwrap());
        match r.branching {
            2 => assert!(s > fs, "{}: scratch {s} not above f32's {fs}", r.kernel),
            4 | 8 => assert!(
                s <= 2.0 * fs && v <= 2.0 * fv,
                "{}: scratch {s} and VGPRs {v} against f32's {fs} and {fv}",
                r.kernel
            ),
            _ => assert!(s < fs, "{}: scratch {s} not below f32's {fs}", r.kernel),
        }
    }
    // The fp16-math kernels compute in fp16, their box tests packed two children to a
    // register (v_pk_*_f16: glsl/half.glsl, slab16x2).
    for r in rows.iter().filter(|r| r.math == "f16" || r.math == "mixed") {
        let a = r.asm.unwrap();
        assert!(a.packed_f16 + a.scalar_f16 > 50, "{}: {a:?}", r.kernel);
        assert!(a.packed_f16 >= 30, "{}: only {} packed fp16 instructions ({a:?})", r.kernel, a.packed_f16);
        assert!(a.packed_f16 >= a.scalar_f16, "{}: under half of the fp16 instructions packed ({a:?})", r.kernel);
    }
    let md = std::fs::read_to_string(out.join("isa.md")).unwrap();
    assert!(md.contains("## Compiler view") && md.contains("navi31 (RDNA3)"), "{md}");
    for f in ["isa.csv", "isa_vgprs.png", "isa_scratch.svg"] {
        assert!(out.join(f).exists(), "{f} not written");
    }
    // A second run into the folder is refused without --force, and leaves it as it was.
    let again = Command::new(bin).args(["isa", "--family", "navi31", "--quick", "--out"]).arg(&out).output().unwrap();
    assert!(!again.status.success() && String::from_utf8_lossy(&again.stderr).contains("--force"));
    assert_eq!(std::fs::read_to_string(out.join("isa.md")).unwrap(), md);
    // `report` renders an isa folder (alone here; beside sweep folders in the same way).
    let merged = tmp("merged");
    let o = Command::new(bin).arg("report").arg(&out).arg("--out").arg(&merged).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = std::fs::read_to_string(merged.join("report.md")).unwrap();
    assert!(report.contains("## Compiler view") && report.contains("| f16h f16 | 4 |"), "{report}");
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&merged);
}

/// ACO's `Latency` rebuilt from its own printouts (`halftrace::isa::aco`): for every kernel
/// of the default matrix on RDNA3 (navi31) and GCN5 (vega10), the final program's block
/// cycles weighted by the depths that replaying instruction selection gives them equal the
/// `latency` ACO printed (to its six decimals) and, rounded, the row's `Latency` statistic;
/// so does the sum over loops of cycles per pass × ACO's passes, and every kernel's traversal
/// and triangle loops are found.
#[test]
fn aco_latency_is_rebuilt_from_its_blocks_on_every_kernel() {
    assert!(std::path::Path::new(RADV_ICD).exists(), "{RADV_ICD} is missing: RADV provides the null devices");
    let bin = std::path::Path::new(env!("CARGO_BIN_EXE_halftrace"));
    for family in ["navi31", "vega10"] {
        let run = halftrace::estimate::programs(bin, family, Matrix::Default, &[], None)
            .unwrap_or_else(|e| panic!("{family}: {e:#}"));
        assert_eq!(run.len(), plan(Matrix::Default, &[]).len(), "{family}: one row per kernel");
        for (row, p, sides) in run {
            let p = p.unwrap_or_else(|e| panic!("{family} {}: {e}", row.kernel));
            // The sides the replay tracks weigh as ACO's depths do, block by block.
            for b in &p.blocks {
                let w: f64 = b.sides.iter().map(|s| s.weight).product();
                assert_eq!(w, b.depth.if_factor(), "{family} {} BB{}: {:?}", row.kernel, b.index, b.sides);
            }
            // The marked build names the triangle test's sides in the real program, each inside
            // its triangle loop; the undecided pair's update is made selects (left out, said).
            let sides = sides.unwrap_or_else(|e| panic!("{family} {}: {e}", row.kernel));
            let r = halftrace::estimate::roles(&p).unwrap_or_else(|e| panic!("{family} {}: {e}", row.kernel));
            use halftrace::base::tri::Branch;
            // On this release the loop the edges side names is the one the shape names.
            let at = halftrace::estimate::roles_at(&p, sides.sides.get(&Branch::Edges).copied()).unwrap();
            assert_eq!(at, r, "{family} {}", row.kernel);
            for k in [Branch::Edges, Branch::Cross, Branch::Divide, Branch::Flat, Branch::Candidate, Branch::Best] {
                let s =
                    sides.sides.get(&k).unwrap_or_else(|| panic!("{family} {}: no {k:?} side: {sides:?}", row.kernel));
                assert!(r.triangles.contains(*s), "{family} {}: {k:?} at BB{s}, outside {:?}", row.kernel, r.triangles);
            }
            let mine = p.aco_latency();
            assert!(
                (mine - p.printed_latency).abs() <= 1e-6,
                "{family} {}: rebuilt {mine} against ACO's {}",
                row.kernel,
                p.printed_latency
            );
            assert_eq!(Some(&mine.round()), row.stats.get("Latency"), "{family} {}: the Latency statistic", row.kernel);
            // The same from the loops' parts: cycles per pass × ACO's passes.
            let parts = p.cycles(|l| p.aco_passes(l));
            assert!(
                (parts - mine).abs() <= 1e-9 * mine,
                "{family} {}: {parts} from the loops, {mine} from the blocks",
                row.kernel
            );
            assert_eq!(r.traversal.depth, 1, "{family} {}", row.kernel);
            assert!(r.triangles.depth > 1, "{family} {}: {r:?}", row.kernel);
        }
    }
}

/// `halftrace estimate` end to end on navi31 (f32 and f16a, B = 4, the teapot's primary and ao
/// rays): every kernel rebuilt exactly and estimated, its named branches found by the marked
/// build and weighed by the rays; f32's ratio is 1; a wave in lockstep
/// costs at least its average lane and, on incoherent ao rays, more; the triangle tests and
/// the traversal step carry cycles; `report` renders the section and the plot; bad arguments
/// are refused by name.
#[test]
fn estimate_weighs_acos_model_with_the_rays() {
    assert!(std::path::Path::new(RADV_ICD).exists(), "{RADV_ICD} is missing: RADV provides the null devices");
    let out = tmp("estimate");
    let o = out.to_str().unwrap();
    let scene = format!("{}/scenes/teapot.obj", env!("CARGO_MANIFEST_DIR"));
    let (ok, _, err) = cli(&["isa", "--quick", "--family", "navi31", "--layouts", "f16a", "--out", o]);
    assert!(ok, "{err}");
    let (ok, stdout, err) =
        cli(&["estimate", "--matrix", "layouts", "--layouts", "f16a", "--scene", &scene, "--res", "48", "--out", o]);
    assert!(ok, "{err}");
    assert!(
        stdout.contains("3 kernels on 1 family taken apart (3 rebuilt exactly), 6 estimated on 2 ray set(s)"),
        "{stdout}"
    );
    let rows = halftrace::report::estimate::read(&out).unwrap().expect("estimate-rays.json");
    assert_eq!(rows.len(), 6);
    for r in &rows {
        let what = format!("{} {}", r.kernel, r.rays);
        assert!(r.status.is_ok(), "{what}: {}", r.status);
        assert_eq!(r.wave, 64, "{what}: RADV compiles compute in wave64");
        assert!(r.cycles_per_ray >= r.lane_average && r.lane_average > 0.0, "{what}: {r:?}");
        assert!((r.split.total() - r.cycles_per_ray).abs() < 1e-6 * r.cycles_per_ray, "{what}: the split adds up");
        assert!(r.split.triangles > 0.0 && r.split.step > 0.0 && r.split.setup > 0.0, "{what}: {r:?}");
        if r.rays == "ao" {
            assert!(r.cycles_per_ray > 1.2 * r.lane_average, "{what}: lockstep on incoherent rays {r:?}");
        }
        if r.layout == "f32" {
            assert_eq!((r.vs_f32, r.aco_vs_f32), (Some(1.0), Some(1.0)), "{what}");
        }
        // The marked build names the triangle test's sides in ACO's program (the candidate's
        // update of the undecided pair is made selects, unmarked), and the rays' branch weights
        // move the triangle tests' part only.
        for k in ["edges", "cross", "flat", "divide", "candidate", "best", "huge 0.0%"] {
            assert!(r.branches.starts_with("rays: ") && r.branches.contains(k), "{what}: {k} in {}", r.branches);
        }
        assert!(r.aco_branches > 0.0 && r.aco_triangles > 0.0, "{what}: {r:?}");
        let moved = (r.aco_branches - r.aco_triangles) - (r.cycles_per_ray - r.split.triangles);
        assert!(moved.abs() < 1e-6 * r.cycles_per_ray, "{what}: only the triangle part moves: {r:?}");
        assert!(r.split.triangles != r.aco_triangles, "{what}: the rays weighed no branch: {r:?}");
    }
    let (ok, _, err) = cli(&["report", o]);
    assert!(ok, "{err}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("## Estimated cycles per ray") && md.contains("trav_f16a_m32_b4_p1"), "{md}");
    assert!(out.join("estimate.png").is_file());
    // Its own files are refused without --force; bad arguments name themselves.
    let (ok, _, err) = cli(&["estimate", "--matrix", "layouts", "--out", o]);
    assert!(!ok && err.contains("already holds estimate") && err.contains("--force"), "{err}");
    let (ok, _, err) = cli(&["estimate", "--family", "navi99", "--out", &format!("{o}-2")]);
    assert!(!ok && err.contains("--family 'navi99'"), "{err}");
    let (ok, _, err) = cli(&["estimate", "--rays", "sideways", "--out", &format!("{o}-3")]);
    assert!(!ok && err.contains("--rays sideways"), "{err}");
    let _ = std::fs::remove_dir_all(&out);
}

/// A null device runs nothing (a wait on it crashes inside RADV): every command that would run
/// refuses it by name and points to `isa`, exiting 1 rather than crashing.
#[test]
fn null_devices_are_refused_by_the_commands_that_run() {
    let scene = format!("{}/scenes/teapot.obj", env!("CARGO_MANIFEST_DIR"));
    let out = tmp("refused");
    let o = out.to_string_lossy().to_string();
    let runs: [&[&str]; 4] = [
        &["trace", "--scene", &scene, "--width", "8", "--height", "8"],
        &["sweep", "--scene", &scene, "--width", "8", "--height", "8", "--layouts", "f32", "--quiet", "--out", &o],
        &["bench", "--scene", &scene, "--width", "8", "--height", "8", "--rounds", "1", "--layouts", "f16h"],
        &["conformance", "--quick", "--scene", &scene, "--out", &o],
    ];
    for args in runs {
        let r = Command::new(env!("CARGO_BIN_EXE_halftrace"))
            .args(args)
            .env("VK_ICD_FILENAMES", RADV_ICD)
            .env("RADV_FORCE_FAMILY", "navi31")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(1), "{}: {err}", args[0]);
        assert!(err.contains("compile-only") && err.contains("halftrace isa"), "{}: {err}", args[0]);
    }
    assert!(!out.join("results.csv").exists(), "a refused sweep wrote rows");
    let _ = std::fs::remove_dir_all(&out);
}

/// Every other vendor's production compiler through its drm-shim (scripts/install-compilers.sh
/// builds them): one model per vendor, f32, f16h and f16w in each math mode the device admits
/// at B = 4. Each model's vendor-neutral columns are filled from its driver's own statistics,
/// and f16h compiles to more instructions than f32.
/// On Adreno a740, f16h keeps its group stack in memory (private loads, registers); on Mali-G610
/// f32 and f16w build without spills.
/// CI installs the compilers and sets HALFTRACE_REQUIRE_COMPILERS=1, so there a missing
/// install fails; elsewhere the test says it did not run and how to make it run.
#[test]
fn isa_builds_on_every_vendors_compiler() {
    if let Err(why) = halftrace::isa::shim::compilers() {
        assert!(std::env::var("HALFTRACE_REQUIRE_COMPILERS").is_err(), "{why}");
        eprintln!("isa_builds_on_every_vendors_compiler DID NOT RUN: {why}");
        return;
    }
    let out = tmp("vendors");
    let (ok, stdout, stderr) = cli(&[
        "isa",
        "--family",
        "a740,g610,lnl,ga102,v3d-71",
        "--quick",
        "--layouts",
        "f16h,f16w",
        "--validation",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "isa on the vendors failed:\n{stdout}\n{stderr}");
    let rows: Vec<IsaRow> = serde_json::from_str(&std::fs::read_to_string(out.join("isa.json")).unwrap()).unwrap();
    for (model, vendor) in
        [("a740", "Qualcomm"), ("g610", "Arm"), ("lnl", "Intel"), ("ga102", "NVIDIA"), ("v3d-71", "Broadcom")]
    {
        let here: Vec<&IsaRow> = rows.iter().filter(|r| r.family == model).collect();
        assert_eq!(here.len(), 6, "{model}: one row per kernel (f32, f16h in three maths, f16w in two)");
        assert!(
            here.iter().all(|r| !r.status.is_failed()),
            "{model}: {:?}",
            here.iter().map(|r| &r.status).collect::<Vec<_>>()
        );
        let ok: Vec<&&IsaRow> = here.iter().filter(|r| r.status.is_ok()).collect();
        assert!(ok.len() >= 2, "{model}: f32 and at least f16h with fp32 math build");
        for r in &ok {
            assert_eq!(r.vendor, vendor, "{}", r.kernel);
            assert!(
                r.instructions.is_some_and(|v| v > 100.0),
                "{model} {}: no instruction count {:?}",
                r.kernel,
                r.stats
            );
            assert!(r.occupancy.is_some() || vendor == "Intel", "{model} {}: no occupancy {:?}", r.kernel, r.stats);
            assert!(
                r.registers.is_some() || r.private_bytes.is_some() || r.spills.is_some(),
                "{model} {}: neither registers nor private memory {:?}",
                r.kernel,
                r.stats
            );
            assert!(r.asm.is_some() || vendor == "Broadcom", "{model} {}: no disassembly counts", r.kernel);
        }
        let f32 = ok.iter().find(|r| r.layout == "f32").unwrap_or_else(|| panic!("{model}: f32 did not build"));
        for h in ok.iter().filter(|r| r.layout == "f16h") {
            // f16h's kernel holds more code than f32's (frames, fp16 conversions, the group
            // stack); its registers need not be more (v3d-71: 62 against f32's 64, both capped
            // near 64 and spilling the rest).
            let (a, b) = (h.instructions.unwrap(), f32.instructions.unwrap());
            assert!(a > b, "{model} {}: {a} instructions, not above f32's {b}", h.kernel);
            // turnip would keep f16h's group stack in registers but for GROUPS_ALLOC: then it
            // needed 192 registers and over a thousand private loads. The bounds hold:
            // private loads at most f32's + 10, and with fp16 or mixed math registers at most
            // f32's + 8 vec4 registers (+ 32 in the column's 32-bit registers; fp32 math needs
            // 128 against f32's 76).
            if model == "a740" {
                let ldp = |r: &IsaRow| {
                    *r.stats.get("LDP Count").unwrap_or_else(|| panic!("a740 {}: no LDP Count {:?}", r.kernel, r.stats))
                };
                assert!(ldp(h) <= ldp(f32) + 10.0, "a740 {}: {} private loads, f32 {}", h.kernel, ldp(h), ldp(f32));
                let (rh, rf) = (h.registers.expect("a740 f16h registers"), f32.registers.expect("a740 f32 registers"));
                if h.math != "f32" {
                    assert!(rh <= rf + 32.0, "a740 {}: {rh} registers against f32's {rf}", h.kernel);
                }
            }
        }
        // The target on Mali-G610: f32 and a reduced layout (f16w, fp32 math) at B = 4
        // fit its 64 registers (no value of a previous traversal step is held across the
        // loop, no ChildHit beside its key, a box decoded axis by axis: docs/vendors.md).
        if model == "g610" {
            for r in ok.iter().filter(|r| r.layout == "f32" || r.layout == "f16w") {
                assert_eq!(r.spills, Some(0.0), "g610 {}: spills and fills {:?}", r.kernel, r.stats);
            }
            assert!(ok.iter().any(|r| r.layout == "f16w"), "g610: f16w did not build");
        }
        // Where the device has no fp16 arithmetic, the fp16-math kernels are skipped by name.
        for r in here.iter().filter(|r| r.status.is_skipped()) {
            assert!(r.status.to_string().contains("shaderFloat16"), "{model} {}: {}", r.kernel, r.status);
        }
    }
    let md = std::fs::read_to_string(out.join("isa.md")).unwrap();
    assert!(md.contains("Across vendors"), "isa.md has no table across vendors");
    // `estimate` shows Intel's and Mali's whole-shader estimates beside, saying what each assumes.
    let est = tmp("vendors-estimate");
    let (ok, stdout, stderr) = cli(&[
        "estimate",
        "--family",
        "lnl,g610",
        "--matrix",
        "layouts",
        "--layouts",
        "f16h",
        "--out",
        est.to_str().unwrap(),
    ]);
    assert!(ok, "estimate on the vendors failed:\n{stdout}\n{stderr}");
    let md = std::fs::read_to_string(est.join("estimate.md")).unwrap();
    assert!(md.contains("## lnl (Xe2): `Cycle Count`") && md.contains("×10 per nesting level"), "{md}");
    assert!(md.contains("## g610 (Valhall (v10)): normalized cycles"), "{md}");
    assert!(md.contains("| trav_f32_b4_p1 | f32 | f32 | 4 | ") && md.contains("| 1.00 |"), "{md}");
    let _ = std::fs::remove_dir_all(&est);
}

/// The newest Mesa beside the pinned one (`scripts/install-newest-compilers.sh`: Debian sid's
/// binaries, their own glibc): `isa --compilers newest` builds on turnip and NVK there through
/// a patched copy of the binary, each row's driver naming the release; NVK 26's own occupancy
/// (`Max warps/SM`), renamed `SLM size` and `Static cycle count` fill the columns; TU102 has
/// fp16 there; Apple's M1 (Honeykrisp, the seventh vendor) builds every kernel in its columns;
/// AMD's navi31 builds under the amdgpu shim, in `isa` and `estimate`; both releases side by
/// side in one run. A model whose shim the release lacks (panvk) is refused before any work. CI
/// installs both; elsewhere the test says it did not run and how to make it run.
#[test]
fn isa_builds_on_the_newest_compilers() {
    let dir = match halftrace::isa::shim::compilers_for(Some("newest")) {
        Ok(d) => d,
        Err(why) => {
            assert!(std::env::var("HALFTRACE_REQUIRE_COMPILERS").is_err(), "{why}");
            eprintln!("isa_builds_on_the_newest_compilers DID NOT RUN: {why}");
            return;
        }
    };
    let release = halftrace::isa::shim::release(&dir);
    let out = tmp("newest");
    let (ok, stdout, stderr) = cli(&[
        "isa",
        "--compilers",
        "newest",
        "--family",
        "a740,ga102,tu102,m1,navi31",
        "--quick",
        "--layouts",
        "f16h",
        "--validation",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "isa on the newest compilers failed:\n{stdout}\n{stderr}");
    let rows: Vec<IsaRow> = serde_json::from_str(&std::fs::read_to_string(out.join("isa.json")).unwrap()).unwrap();
    assert_eq!(rows.len(), 20, "f32 and f16h in three maths on four models and navi31");
    for r in &rows {
        assert!(r.status.is_ok(), "{} {}: {}", r.family, r.kernel, r.status);
        assert!(r.driver.contains(&release), "{} {}: driver {} is not Mesa {release}", r.family, r.kernel, r.driver);
        assert!(
            r.registers.is_some_and(|g| g > 0.0) && r.occupancy.is_some(),
            "{} {}: {:?}",
            r.family,
            r.kernel,
            r.stats
        );
        if r.family == "navi31" {
            // Mesa 26 has no RADV null device: navi31 is RADV under the amdgpu shim, its label the
            // family's, its columns ACO's.
            assert!(r.device.ends_with("(amdgpu shim)") && r.device_label() == "navi31 (RDNA3)", "{}", r.device);
            assert_eq!((r.vendor.name(), r.registers), ("AMD", r.vgprs), "navi31 {}", r.kernel);
            assert_eq!(r.occupancy, r.waves_per_simd, "navi31 {}", r.kernel);
            assert!(r.cycles.is_some_and(|c| c > 0.0), "navi31 {}: no Latency", r.kernel);
        } else if r.family == "m1" {
            // Apple's 16-bit registers, threads in flight and ALU cycles.
            assert_eq!(r.registers, r.stats.get("GPRs").map(|g| g / 2.0), "m1 {}", r.kernel);
            assert_eq!((r.vendor.name(), r.occupancy), ("Apple", r.stats.get("Threads").copied()), "m1 {}", r.kernel);
            assert!(r.cycles.is_some_and(|c| c > 0.0), "m1 {}: no ALU cycles", r.kernel);
            // Honeykrisp keeps private arrays of up to 256 bytes in registers: f16h's group
            // stack, allocated past that (GROUPS_ALLOC), no longer fills the register file
            // (255 16-bit registers, 384 threads, thousands of spills). The target:
            // f16h's threads at least half f32's.
            let f32 = rows.iter().find(|f| f.family == "m1" && f.layout == "f32").expect("m1 f32");
            let (t, tf) = (r.occupancy.unwrap(), f32.occupancy.unwrap());
            assert!(2.0 * t >= tf, "m1 {}: {t} threads against f32's {tf} {:?}", r.kernel, r.stats);
            assert!(r.spills.is_some_and(|s| s <= 40.0), "m1 {}: spills and fills {:?}", r.kernel, r.stats);
        } else if r.family != "a740" {
            assert_eq!(r.occupancy, r.stats.get("Max warps/SM").copied(), "{} {}", r.family, r.kernel);
            assert_eq!(r.private_bytes, r.stats.get("SLM size").copied(), "{} {}", r.family, r.kernel);
            assert!(r.cycles.is_some_and(|c| c > 0.0), "{} {}: no static cycle count", r.family, r.kernel);
        }
    }
    // turnip on Mesa 26.2 keeps private arrays of up to 768 bytes (its register file) in
    // registers while they fit: f32's entry stack, one 388-byte field array of it, took all 48
    // vec4 registers (192). Both stacks are allocated past that on turnip; the targets
    // on a740: f32 at most 96 registers, f16h's private loads at most f32's + 10.
    let a740 = |l: &'static str| rows.iter().filter(move |r| r.family == "a740" && r.layout == l);
    let f32 = a740("f32").next().expect("a740 f32");
    assert!(f32.registers.is_some_and(|g| g <= 96.0), "a740 f32 on Mesa {release}: {:?}", f32.stats);
    let ldp = |r: &IsaRow| r.stats.get("LDP Count").copied().unwrap_or(f64::NAN);
    for h in a740("f16h") {
        assert!(ldp(h) <= ldp(f32) + 10.0, "a740 {}: {} private loads, f32 {}", h.kernel, ldp(h), ldp(f32));
    }
    // Both releases in one run: every device once per release, the release in each table's
    // column, and the section of what the release changes with each release's own figures.
    let both = tmp("both-releases");
    let (ok, stdout, stderr) = cli(&[
        "isa",
        "--compilers",
        "pinned,newest",
        "--family",
        "navi31,a740",
        "--quick",
        "--layouts",
        "f16h",
        "--out",
        both.to_str().unwrap(),
    ]);
    assert!(ok, "isa on both releases failed:\n{stdout}\n{stderr}");
    let rows: Vec<IsaRow> = serde_json::from_str(&std::fs::read_to_string(both.join("isa.json")).unwrap()).unwrap();
    assert_eq!(rows.len(), 16, "f32 and f16h in three maths on two devices and two releases");
    let md = std::fs::read_to_string(both.join("isa.md")).unwrap();
    let newest = halftrace::report::isa::release(&format!("Mesa {release}"));
    assert!(md.contains(&format!("| device | kernel | B | Mesa 25.0.7 | {newest} | verdict |")), "{md}");
    for r in rows.iter().filter(|r| r.layout == "f32") {
        let rel = halftrace::report::isa::release(&r.driver);
        assert!(rel == "Mesa 25.0.7" || rel == newest, "{}: {}", r.kernel, r.driver);
        assert!(md.contains(&format!("### {} · {rel}", r.device_label())), "{rel}: {md}");
        let n = |x: Option<f64>| x.map(|v| format!("{v:.0}")).unwrap_or_else(|| "–".into());
        let cell = format!("{} / {} / {} / {}", n(r.registers), n(r.occupancy), n(r.spills), n(r.cycles));
        let line = md
            .lines()
            .find(|l| l.starts_with(&format!("| {} | f32 | 4 |", r.device_label())))
            .unwrap_or_else(|| panic!("{md}"));
        assert!(line.contains(&cell), "{rel} {}: {cell} not in {line}", r.family);
    }
    // estimate on the newest release: ACO 26 leaves an empty else side out of a divergent if;
    // every kernel is still rebuilt exactly from its blocks.
    let est = tmp("newest-estimate");
    let (ok, stdout, stderr) = cli(&[
        "estimate",
        "--compilers",
        "newest",
        "--family",
        "navi31",
        "--matrix",
        "layouts",
        "--layouts",
        "f16h",
        "--rays",
        "primary",
        "--res",
        "32",
        "--out",
        est.to_str().unwrap(),
    ]);
    assert!(ok && stdout.contains("(4 rebuilt exactly)"), "estimate on the newest release:\n{stdout}\n{stderr}");
    // Its rows and headings name the release they were built with.
    let md = std::fs::read_to_string(est.join("estimate.md")).unwrap();
    assert!(md.contains(&format!("## navi31 (RDNA3), {newest}\n")), "{md}");
    assert!(md.contains(&format!("## navi31 (RDNA3), {newest}, teapot, primary rays")), "{md}");
    // The memory model's resident waves from the compilers' occupancy (`memory --compilers`):
    // each kernel's waves per unit are what its compiler reported for it on that release (navi31:
    // waves per SIMD × 2 SIMDs per CU); a model the release has no compiler for (g610: Debian
    // builds no panvk) keeps its assumed figure, said. The estimate made on the same release joins.
    let mem = tmp("newest-memory");
    // `memory` at B = 4 on 16² primary rays, with `more` flags.
    let memory_with = |compilers: &str, gpus: &str, more: &[&str], out: &PathBuf| {
        let out = out.to_str().unwrap();
        let mut args =
            vec!["memory", "--compilers", compilers, "--gpu", gpus, "--branchings", "4", "--rays", "primary"];
        args.extend(["--res", "16", "--out", out]);
        args.extend_from_slice(more);
        cli(&args)
    };
    let est_dir = est.to_str().unwrap();
    let memory = |compilers: &str, gpus: &str, out: &PathBuf| {
        memory_with(compilers, gpus, &["--layouts", "f16h", "--estimate", est_dir], out)
    };
    let (ok, stdout, stderr) = memory("newest", "navi31,a740,g610", &mem);
    assert!(ok, "memory on the newest compilers failed:\n{stdout}\n{stderr}");
    // Only the B modelled are built: f32 and f16h's three maths at B = 4, on two models.
    assert!(stdout.contains("8 single-ray kernels built on navi31, a740 "), "{stdout}");
    let mrows = halftrace::report::memory::read(&mem).unwrap().expect("memory.json");
    assert_eq!(mrows.len(), 3 * 4, "f32 and f16h in three maths on three GPU models");
    for m in &mrows {
        if m.gpu == "g610" {
            let g = halftrace::memory::gpus::gpu("g610").unwrap();
            assert_eq!(m.resident, g.resident, "g610 {}", m.kernel);
            assert_eq!(m.resident_from, "assumed (g610: not built)", "g610 {}", m.kernel);
            continue;
        }
        let isa = rows
            .iter()
            .find(|r| r.family == m.gpu && r.kernel == m.kernel && halftrace::report::isa::release(&r.driver) == newest)
            .unwrap_or_else(|| panic!("{} {}: no isa row on {newest}", m.gpu, m.kernel));
        let per_unit = if m.gpu == "navi31" { 2.0 } else { 1.0 };
        assert_eq!(Some(m.resident as f64), isa.occupancy.map(|o| o * per_unit), "{} {}", m.gpu, m.kernel);
        assert!(m.resident_from.contains(&release), "{} {}: {}", m.gpu, m.kernel, m.resident_from);
    }
    let md = std::fs::read_to_string(mem.join("memory.md")).unwrap();
    assert!(md.contains("per kernel: a740's occupancy on ") && md.contains("| 32 (assumed) |"), "{md}");
    // Only models the release lacks: the run goes on with the assumed figure, said.
    let (ok, _, stderr) = memory_with("newest", "g610", &[], &tmp("newest-mali"));
    assert!(ok && stderr.contains("has no compiler for g610"), "{stderr}");
    // Mali on the pinned release (panfrost's shim): each kernel's thread class, 2 (at most 32
    // registers) all of a Valhall core's 64 warps, 1 half; its fp16-math kernels, which panvk
    // 25.0.7 cannot build, keep the assumed figure, said.
    let mali = tmp("pinned-mali");
    let (ok, stdout, stderr) = memory_with("pinned", "g610", &["--layouts", "q8"], &mali);
    assert!(ok && stdout.contains("built on g610 "), "memory on the pinned Mali compiler:\n{stdout}\n{stderr}");
    let mrows = halftrace::report::memory::read(&mali).unwrap().expect("memory.json");
    assert_eq!(mrows.len(), 3, "f32 and q8 in two maths");
    for m in &mrows {
        if m.math == "f16" {
            assert!(m.resident_from.contains("needs shaderFloat16") && m.resident == 32, "{}: {m:?}", m.kernel);
            continue;
        }
        // "panvk Mesa 25.0.7: 1 threads (of 2: …)": the class after the driver.
        let class: usize = m
            .resident_from
            .split(": ")
            .nth(1)
            .and_then(|x| x.split(' ').next()?.parse().ok())
            .unwrap_or_else(|| panic!("{}: {}", m.kernel, m.resident_from));
        assert!(
            m.resident_from.contains("Mesa 25.0.7") && m.resident_from.contains(" threads (of 2: 64 warps/core at 2)")
        );
        assert_eq!(m.resident, class * 32, "{}: {}", m.kernel, m.resident_from);
    }
    // An estimate made on another release is refused: its issue bound and the cache model's
    // waves would come from two compilers.
    let (ok, _, stderr) = memory("pinned", "navi31", &tmp("pinned-memory"));
    assert!(!ok && stderr.contains("Mesa 25.0.7") && stderr.contains(&newest), "{stderr}");
    let csv = std::fs::read_to_string(est.join("estimate-rays.csv")).unwrap();
    assert!(csv.starts_with("family,generation,driver,") && csv.contains(&format!("Mesa {release}")), "{csv}");
    let (ok, _, stderr) = cli(&[
        "isa",
        "--compilers",
        "newest",
        "--family",
        "g610",
        "--quick",
        "--out",
        tmp("newest-g610").to_str().unwrap(),
    ]);
    assert!(!ok && stderr.contains("g610 (panvk)") && stderr.contains(&release), "{stderr}");
}
