#!/usr/bin/env bash
# Checks that the simulation files aortagen writes (VTP, legacy VTK, multi-solid STL,
# grouped OBJ, per-face GLB; capped and open; with and without flow extensions) read with
# VTK 9 / PyVista and meshio with the right counts, face ids and normals.
# Makes (once) a venv with pinned packages under ~/.cache/aortagen-sim-venv.
set -euo pipefail
cd "$(dirname "$0")/../.."
venv="${AORTAGEN_SIM_VENV:-$HOME/.cache/aortagen-sim-venv}"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/pip" install --quiet --disable-pip-version-check \
    vtk==9.7.2 pyvista==0.49.2 meshio==5.3.5 numpy==2.4.6
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/aortagen-target}"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
run() { cargo run --quiet --example simulation -- --out "$out" "$@" > /dev/null; }
run --stem root
run --stem root_extended --extension 2
run --stem root_remeshed --remesh 1.0
"$venv/bin/python" -W ignore tests/simulation/check_readers.py "$out"
