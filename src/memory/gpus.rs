//! Each modelled GPU's memory (`docs/gpu-memory.md` gives every figure's source and marks
//! what is assumed): compute units, the lanes of a wave, the resident waves per unit the model
//! assumes, each cache level's size, line and associativity, DRAM bandwidth and energy.

/// One GPU's memory as the model sees it.
#[derive(Clone, Debug, PartialEq)]
pub struct Gpu {
    pub id: &'static str,
    pub name: &'static str,
    /// Compute units (CUs, SMs, Xe-cores, shader cores: `unit`), each with its own L1.
    pub units: u32,
    pub unit: &'static str,
    pub clock_mhz: u32,
    /// Lanes in lockstep (the wave, warp or SIMD width the compiler uses for compute).
    pub wave: usize,
    /// Waves resident per unit, interleaved step by step (an assumption of the model: the
    /// kernels' occupancy differs per kernel and compiler; `isa` reports it, and `memory
    /// --compilers` takes it from there where [`Gpu::compiler`] names a build).
    pub resident: usize,
    /// The `isa` family or model whose compiler builds this GPU's kernels (`memory
    /// --compilers`: its occupancy, in waves per unit — AMD's waves per SIMD × [`Gpu::simds`],
    /// Adreno's waves per core, NVIDIA's warps per SM — sets each kernel's resident waves).
    /// Mali's thread class (full or half of [`VALHALL_WARPS_PER_CORE`]). Hopper borrows GA102's
    /// build (no Mesa shim builds for Hopper): its registers per thread give the warps per SM by
    /// CUDA's rule with Hopper's 64-warp limit, the register file (64 K per SM) being GA102's.
    /// `None` where no compiler here reports one: Intel's driver gives no occupancy.
    pub compiler: Option<&'static str>,
    pub l1_kib: u64,
    pub l1_line: u64,
    pub l1_ways: usize,
    /// Whether the L1 keeps a store's line dirty (write-back) — else stores pass through it
    /// into the L2 (write-through). Only the stacks' pushes write (`docs/gpu-memory.md`).
    pub l1_write_back: bool,
    pub l2_kib: u64,
    pub l2_line: u64,
    pub l2_ways: usize,
    /// Last-level cache (AMD's Infinity Cache, a system-level cache), 0 where none.
    pub llc_kib: u64,
    pub llc_line: u64,
    pub llc_ways: usize,
    pub dram: &'static str,
    pub dram_gbs: f64,
    /// L2 read bandwidth, GB/s: measured, derived or assumed per GPU (`docs/gpu-memory.md`, "L2
    /// bandwidth"); the roofline's L2 bound.
    pub l2_gbs: f64,
    /// DRAM access energy, pJ per bit, for the memory type.
    pub pj_per_bit: f64,
    /// Load-to-use latency (ns) of a read served by the L1, the L2, the last-level cache (0
    /// where none) and DRAM: pointer-chasing measurements where published, else assumed
    /// (`docs/gpu-memory.md`, "Latency"); the roofline's latency bound.
    pub latency_ns: [f64; 4],
    /// SIMDs per unit that `estimate`'s rays per 1000 clocks per SIMD scale by (AMD: 2 SIMD32
    /// per RDNA CU, 4 SIMD16 per GCN CU); 0 where no cycle model exists.
    pub simds: u32,
}

/// Warps resident per Mali Valhall shader core at full occupancy (at most 32 registers a
/// thread; more than 32 halve it: Mesa's shaderdb `threads` 2 or 1). The Arm driver's
/// `shaderWarpsPerCore` on Mali-G610 and G710 (`docs/gpu-memory.md`, "What the model adds").
pub const VALHALL_WARPS_PER_CORE: usize = 64;

/// Every modelled GPU.
pub static GPUS: &[Gpu] = &[
    Gpu {
        id: "navi31",
        name: "AMD Radeon RX 7900 XTX (RDNA3)",
        units: 96,
        unit: "CU",
        clock_mhz: 2500,
        wave: 32,
        resident: 8,
        compiler: Some("navi31"),
        l1_kib: 32,
        l1_line: 128,
        l1_ways: 32,
        l1_write_back: false,
        l2_kib: 6144,
        l2_line: 128,
        l2_ways: 16,
        llc_kib: 98304,
        llc_line: 64,
        llc_ways: 16,
        dram: "GDDR6",
        dram_gbs: 960.0,
        l2_gbs: 7680.0,
        pj_per_bit: 7.5,
        latency_ns: [28.5, 87.0, 150.3, 234.55],
        simds: 2,
    },
    Gpu {
        id: "navi21",
        name: "AMD Radeon RX 6900 XT (RDNA2)",
        units: 80,
        unit: "CU",
        clock_mhz: 2250,
        wave: 32,
        resident: 8,
        compiler: Some("navi21"),
        l1_kib: 16,
        l1_line: 128,
        l1_ways: 32,
        l1_write_back: false,
        l2_kib: 4096,
        l2_line: 128,
        l2_ways: 16,
        llc_kib: 131072,
        llc_line: 64,
        llc_ways: 16,
        dram: "GDDR6",
        dram_gbs: 512.0,
        l2_gbs: 4608.0,
        pj_per_bit: 7.5,
        latency_ns: [28.5, 87.0, 165.0, 283.89],
        simds: 2,
    },
    Gpu {
        id: "vega10",
        name: "AMD Radeon RX Vega 64 (GCN5)",
        units: 64,
        unit: "CU",
        clock_mhz: 1546,
        wave: 64,
        resident: 8,
        compiler: Some("vega10"),
        l1_kib: 16,
        l1_line: 64,
        l1_ways: 4,
        l1_write_back: false,
        l2_kib: 4096,
        l2_line: 64,
        l2_ways: 16,
        llc_kib: 0,
        llc_line: 64,
        llc_ways: 1,
        dram: "HBM2",
        dram_gbs: 483.8,
        l2_gbs: 1583.0,
        pj_per_bit: 3.9,
        latency_ns: [90.6, 187.6, 0.0, 404.3],
        simds: 4,
    },
    Gpu {
        id: "g610",
        name: "Arm Mali-G610 MC4 (Valhall, RK3588)",
        units: 4,
        unit: "shader core",
        clock_mhz: 1000,
        wave: 16,
        resident: 32,
        compiler: Some("g610"),
        l1_kib: 16,
        l1_line: 64,
        l1_ways: 4,
        l1_write_back: true,
        l2_kib: 1024,
        l2_line: 64,
        l2_ways: 8,
        llc_kib: 0,
        llc_line: 64,
        llc_ways: 1,
        dram: "LPDDR4X",
        dram_gbs: 33.8,
        l2_gbs: 256.0,
        pj_per_bit: 4.5,
        latency_ns: [62.3, 150.0, 0.0, 350.0],
        simds: 0,
    },
    Gpu {
        id: "a740",
        name: "Qualcomm Adreno 740 (Snapdragon 8 Gen 2)",
        units: 6,
        unit: "SP",
        clock_mhz: 680,
        wave: 64,
        resident: 8,
        compiler: Some("a740"),
        l1_kib: 16,
        l1_line: 64,
        l1_ways: 4,
        l1_write_back: true,
        l2_kib: 512,
        l2_line: 64,
        l2_ways: 16,
        llc_kib: 6144,
        llc_line: 64,
        llc_ways: 16,
        dram: "LPDDR5X",
        dram_gbs: 67.2,
        l2_gbs: 261.0,
        pj_per_bit: 4.0,
        latency_ns: [62.3, 150.0, 243.0, 350.0],
        simds: 0,
    },
    Gpu {
        id: "lnl",
        name: "Intel Arc 140V (Xe2, Lunar Lake)",
        units: 8,
        unit: "Xe-core",
        clock_mhz: 2050,
        wave: 16,
        resident: 32,
        compiler: None,
        l1_kib: 192,
        l1_line: 64,
        l1_ways: 8,
        l1_write_back: true,
        l2_kib: 8192,
        l2_line: 64,
        l2_ways: 16,
        llc_kib: 8192,
        llc_line: 64,
        llc_ways: 16,
        dram: "LPDDR5X",
        dram_gbs: 136.5,
        l2_gbs: 1050.0,
        pj_per_bit: 4.0,
        latency_ns: [40.0, 120.0, 200.0, 350.0],
        simds: 0,
    },
    Gpu {
        id: "ga102",
        name: "NVIDIA GeForce RTX 3090 (Ampere)",
        units: 82,
        unit: "SM",
        clock_mhz: 1695,
        wave: 32,
        resident: 16,
        compiler: Some("ga102"),
        l1_kib: 128,
        l1_line: 128,
        l1_ways: 256,
        l1_write_back: true,
        l2_kib: 6144,
        l2_line: 128,
        l2_ways: 16,
        llc_kib: 0,
        llc_line: 128,
        llc_ways: 1,
        dram: "GDDR6X",
        dram_gbs: 936.0,
        l2_gbs: 2604.0,
        pj_per_bit: 7.25,
        latency_ns: [19.0, 140.0, 0.0, 314.2],
        simds: 0,
    },
    Gpu {
        id: "h100",
        name: "NVIDIA H100 SXM5 80GB (Hopper)",
        units: 132,
        unit: "SM",
        clock_mhz: 1980,
        wave: 32,
        resident: 16,
        compiler: Some("ga102"),
        l1_kib: 256,
        l1_line: 128,
        l1_ways: 512,
        l1_write_back: true,
        l2_kib: 51200,
        l2_line: 128,
        l2_ways: 20,
        llc_kib: 0,
        llc_line: 128,
        llc_ways: 1,
        dram: "HBM3",
        dram_gbs: 3350.0,
        l2_gbs: 9800.0,
        pj_per_bit: 3.5,
        latency_ns: [16.2, 141.6, 0.0, 347.5],
        simds: 0,
    },
    Gpu {
        id: "h200",
        name: "NVIDIA H200 SXM 141GB (Hopper)",
        units: 132,
        unit: "SM",
        clock_mhz: 1980,
        wave: 32,
        resident: 16,
        compiler: Some("ga102"),
        l1_kib: 256,
        l1_line: 128,
        l1_ways: 512,
        l1_write_back: true,
        l2_kib: 51200,
        l2_line: 128,
        l2_ways: 20,
        llc_kib: 0,
        llc_line: 128,
        llc_ways: 1,
        dram: "HBM3e",
        dram_gbs: 4800.0,
        l2_gbs: 9800.0,
        pj_per_bit: 3.5,
        latency_ns: [16.2, 141.6, 0.0, 347.5],
        simds: 0,
    },
];

/// The GPU model called `id`.
pub fn gpu(id: &str) -> Option<&'static Gpu> {
    GPUS.iter().find(|g| g.id == id)
}

/// The table of the models' figures (Markdown), for the report. `release(g)`: the compilers
/// release whose occupancy set `g`'s resident waves (`memory --compilers`), where one did.
pub fn table(gpus: &[&Gpu], release: impl Fn(&Gpu) -> Option<String>) -> String {
    let mut md = String::from(
        "## The GPU models (sources and assumptions: `docs/gpu-memory.md`)\n\n| GPU | units | wave | resident waves/unit | L1/unit KiB, line, ways, stores | L2 KiB, line, ways | LLC KiB, line, ways | L2 GB/s | DRAM | GB/s | pJ/bit | latency ns L1, L2, LLC, DRAM |\n|---|---:|---:|---:|---|---|---|---:|---|---:|---:|---|\n",
    );
    for g in gpus {
        md += &format!(
            "| {} ({}) | {} {} | {} | {} | {}, {} B, {}, {} | {}, {} B, {} | {} | {:.0} | {} | {:.0} | {} | {} |\n",
            g.id,
            g.name,
            g.units,
            g.unit,
            g.wave,
            match (release(g), g.compiler) {
                (Some(c), Some(t)) if t == g.id => format!("per kernel: {t}'s occupancy on {c}"),
                (Some(c), Some(t)) => format!("per kernel: from {t}'s registers on {c}"),
                _ => format!("{} (assumed)", g.resident),
            },
            g.l1_kib,
            g.l1_line,
            g.l1_ways,
            if g.l1_write_back { "write-back" } else { "write-through" },
            g.l2_kib,
            g.l2_line,
            g.l2_ways,
            if g.llc_kib > 0 { format!("{}, {} B, {}", g.llc_kib, g.llc_line, g.llc_ways) } else { "none".into() },
            g.l2_gbs,
            g.dram,
            g.dram_gbs,
            g.pj_per_bit,
            g.latency_ns
                .iter()
                .map(|&l| if l > 0.0 { format!("{l}") } else { "–".into() })
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    md + "\n"
}
