#!/usr/bin/env bash
# One hash of every kernel's SPIR-V in spirv/ (names and bytes), as docs/sample-report records it.
set -euo pipefail
cd "$(dirname "$0")/.."
find spirv -type f -name '*.spv' | LC_ALL=C sort | xargs sha256sum | sha256sum | cut -d' ' -f1
