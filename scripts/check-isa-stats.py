#!/usr/bin/env python3
"""Checks `halftrace isa` against RADV's own statistics dump.

Usage: RADV_DEBUG=shaderstats halftrace isa --family F ... --out DIR 2> STDERR
       python3 scripts/check-isa-stats.py DIR/isa.json STDERR

RADV_DEBUG=shaderstats makes RADV print a "*** SHADER STATS ***" block to stderr for every
shader it compiles. Each isa row (read through VK_KHR_pipeline_executable_properties) is matched
to the block with the same CRC32 "Hash" of its code, and every statistic both name is compared
(the 64-bit "Driver pipeline hash" is left out: isa.json keeps statistics as doubles). Exits 1
on any difference or on a row without a block."""
import json, sys

rows = [r for r in json.load(open(sys.argv[1])) if r["status"] == "ok"]
blocks, cur = [], None
for line in open(sys.argv[2], errors="replace"):
    line = line.strip()
    if line == "*** SHADER STATS ***":
        cur = {}
    elif line.startswith("****") and cur is not None:
        blocks.append(cur)
        cur = None
    elif cur is not None and ": " in line:
        k, v = line.split(": ", 1)
        try:
            cur[k] = float(v)
        except ValueError:
            pass
by_hash = {}
for b in blocks:
    by_hash.setdefault(b.get("Hash"), []).append(b)
bad = 0
compared = 0
for r in rows:
    s = r["stats"]
    cands = by_hash.get(s.get("Hash"), [])
    if not cands:
        print(f"{r['family']} {r['kernel']}: no RADV_DEBUG=shaderstats block with Hash {s.get('Hash')}")
        bad += 1
        continue
    b = cands[0]
    diff = {k: (s[k], b[k]) for k in s if k in b and k != "Driver pipeline hash" and s[k] != b[k]}
    compared += len([k for k in s if k in b and k != "Driver pipeline hash"])
    if diff:
        print(f"{r['family']} {r['kernel']}: differs {diff}")
        bad += 1
print(f"{len(rows)} rows, {len(blocks)} RADV blocks, {compared} statistics compared, {bad} rows differ or unmatched")
sys.exit(1 if bad else 0)
