#!/usr/bin/env bash
# Regenerates crates/rgm-cli/tests/golden/register_transforms.json, the transforms that
# crates/rgm-cli/tests/behaviour_pin.rs pins, from the code as it is now (the file records the
# commit). Run it only for a change that is meant to change results, and say why in the commit.
# Needs the ModelNet40 data (../shared/data/modelnet40_npy1024 beside the repository, or
# $RGM_DATA); extra arguments go to cargo (e.g. -j1).
set -euo pipefail
cd "$(dirname "$0")/.."
RGM_PIN_BLESS=1 cargo test -p rgm-cli --test behaviour_pin "$@" -- --nocapture \
    register_transforms_match_the_pinned_values
git diff --stat -- crates/rgm-cli/tests/golden/register_transforms.json
