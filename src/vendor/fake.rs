//! A vendor no GPU has, registered only in unit tests: it shows that a vendor is this one file
//! and one line in the registry — its rows reach `isa`'s tables with nothing else touched
//! (`report::isa`'s test).

use super::{model, Input, Neutral, Occupancy, Shim, Stats, Vendor, GPU_DEFAULT};

pub static FAKE: Vendor = Vendor {
    name: "Fakevendor",
    driver_ids: &[],
    driver_names: &["fakedrv"],
    shim: Some(Shim { kernel: "fake", icd: "fake.json", driver: "fakedrv", summary_env: &[] }),
    models: &[model("fk1", "Fake GPU One", "Fake 1", &[("FAKE_GPU_ID", "1")])],
    stats: Stats::Own,
    sources: ["Fake regs", "–", "Fake spills", "Fake lanes (lanes/unit)", "Fake ops", "–"],
    neutral,
    disassembly: None,
    occupancy: Some(Occupancy { unit: "lanes/unit", words: "lanes per unit", note: "Fakevendor" }),
    cycles: "no cycle estimate from this driver",
    quirks: GPU_DEFAULT,
};

fn neutral(s: &Input) -> Neutral {
    Neutral {
        registers: s.get("Fake regs"),
        spills: s.get("Fake spills"),
        occupancy: s.get("Fake lanes"),
        instructions: s.get("Fake ops"),
        ..Neutral::default()
    }
}
