#!/usr/bin/env bash
# Builds the Python package (python/) into a fresh virtual environment, target/python-venv, and
# runs its tests. The README's test command runs it after `cargo test --workspace`, whose `rgm`
# binary (target/debug/rgm) the tests compare the package against. Needs python3 with venv and
# pip, and PyPI for maturin, numpy and the `test` extra (pytest; dask and distributed for the
# Dask example's test).
set -euo pipefail
cd "$(dirname "$0")/.."
start=$SECONDS
venv=target/python-venv
rm -rf "$venv"
python3 -m venv "$venv"
echo "test-python: building the rgm package (release build of python/, cached in python/target)"
"$venv/bin/pip" install --quiet --disable-pip-version-check "./python[test]"
echo "test-python: built and installed in $((SECONDS - start)) s"
if [ -x target/debug/rgm ]; then
  export RGM_BIN="$PWD/target/debug/rgm"
fi
# pytest itself (not `python -m pytest`, which would put the working folder on the path): the
# tests import the installed package, never the source folder python/rgm.
# pytest's summary stays the last line CI prints.
"$venv/bin/pytest" python/tests -q
