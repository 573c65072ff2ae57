#!/usr/bin/env bash
# Installs what rgm needs on a fresh Debian/Ubuntu machine that has the Rust toolchain, gcc and
# Python: gfortran for the statically built OpenBLAS, Python's venv for the Python package's
# tests (scripts/test-python.sh), and Chromium for the viewer's browser test
# (scripts/test-browser.sh). Safe to run again.
set -euo pipefail

need_apt=()
command -v gfortran >/dev/null 2>&1 || need_apt+=(gfortran)
command -v make >/dev/null 2>&1 || need_apt+=(make)
python3 -c "import venv, ensurepip" >/dev/null 2>&1 || need_apt+=(python3-venv)
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
if [ ${#need_apt[@]} -gt 0 ]; then
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  echo "setup: installing ${need_apt[*]} with apt-get"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi
echo "setup: ready (gfortran $(gfortran -dumpversion))"
