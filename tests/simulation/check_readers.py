"""Reads every simulation file in a directory with VTK 9 / PyVista and meshio and checks it
against its sidecar JSON: point and triangle counts, the triangles of every face id and the
point normals. Exits non-zero on the first mismatch.

Usage: python check_readers.py DIR
"""

import json
import pathlib
import sys

import meshio
import numpy as np
import pyvista as pv
import vtk

# meshio reads legacy VTK, STL and OBJ; it has no VTP (PolyData XML) or glTF reader.
MESHIO_FORMATS = {".vtk", ".stl", ".obj"}


def fail(path, message):
    raise SystemExit(f"FAIL {path.name}: {message}")


def expected(path):
    side = json.loads(pathlib.Path(str(path) + ".json").read_text())
    faces = {f["id"]: f["triangles"] for f in side["faces"]}
    names = {f["name"]: f["triangles"] for f in side["faces"]}
    return side["quality"]["vertices"], side["quality"]["triangles"], faces, names


def check_patches(path, names):
    """One STL solid or OBJ group per face, named as the face, with its triangles."""
    found, current = {}, None
    for line in path.read_text().splitlines():
        words = line.split()
        if words[:1] in (["solid"], ["g"]):
            current = words[1]
            found[current] = 0
        elif current is not None and words[:1] in (["facet"], ["f"]):
            found[current] += 1
    if found != names:
        fail(path, f"patches {found} != {names}")


def check_face_ids(path, ids, faces):
    ids = np.asarray(ids).ravel()
    found = {int(k): int(v) for k, v in zip(*np.unique(ids, return_counts=True))}
    if found != faces:
        fail(path, f"face ids {found} != {faces}")


def check_normals(path, points, triangles, normals):
    normals = np.asarray(normals, dtype=float)
    lengths = np.linalg.norm(normals, axis=1)
    if np.abs(lengths - 1).max() > 1e-4:
        fail(path, f"point normals not unit (worst length {lengths.min():.6f})")
    a, b, c = (points[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)
    agree = np.einsum("ij,ij->i", normals[triangles].mean(axis=1), face) > 0
    if agree.mean() < 0.999:
        fail(path, f"point normals disagree with {100 * (1 - agree.mean()):.2f}% of triangles")


def check_pyvista(path, n_points, n_tris, faces):
    data = pv.read(path)
    if isinstance(data, pv.MultiBlock):
        leaves = [b for b in data.recursive_iterator() if b is not None and b.n_cells > 0]
        if len(leaves) != len(faces):
            fail(path, f"{len(leaves)} primitives for {len(faces)} faces")
        counts = sorted(b.n_cells for b in leaves)
        if counts != sorted(faces.values()):
            fail(path, f"primitive triangle counts {counts} != {sorted(faces.values())}")
        return
    if data.n_cells != n_tris:
        fail(path, f"{data.n_cells} cells, expected {n_tris}")
    grid = data.cast_to_unstructured_grid()
    if not (np.asarray(grid.celltypes) == vtk.VTK_TRIANGLE).all():
        fail(path, "not all cells are triangles")
    if path.suffix in {".vtp", ".vtk"}:
        if data.n_points != n_points:
            fail(path, f"{data.n_points} points, expected {n_points}")
        check_face_ids(path, data.cell_data["ModelFaceID"], faces)
        tris = grid.cells_dict[vtk.VTK_TRIANGLE]
        check_normals(path, np.asarray(data.points, dtype=float), tris, data.point_data["Normals"])


def check_meshio(path, n_points, n_tris, faces):
    mesh = meshio.read(path)
    tris = np.concatenate([c.data for c in mesh.cells if c.type == "triangle"])
    if len(tris) != n_tris:
        fail(path, f"meshio: {len(tris)} triangles, expected {n_tris}")
    if path.suffix == ".vtk":
        if len(mesh.points) != n_points:
            fail(path, f"meshio: {len(mesh.points)} points, expected {n_points}")
        check_face_ids(path, np.concatenate(mesh.cell_data["ModelFaceID"]), faces)
        check_normals(path, mesh.points, tris, mesh.point_data["Normals"])


def main():
    directory = pathlib.Path(sys.argv[1])
    files = sorted(p for p in directory.iterdir() if p.suffix in {".vtp", ".vtk", ".stl", ".obj", ".glb"})
    if not files:
        raise SystemExit(f"no simulation files in {directory}")
    print(f"VTK {vtk.vtkVersion.GetVTKVersion()}, PyVista {pv.__version__}, meshio {meshio.__version__}")
    for path in files:
        n_points, n_tris, faces, names = expected(path)
        check_pyvista(path, n_points, n_tris, faces)
        if path.suffix in {".stl", ".obj"}:
            check_patches(path, names)
        readers = "VTK/PyVista"
        if path.suffix in MESHIO_FORMATS:
            check_meshio(path, n_points, n_tris, faces)
            readers += " + meshio"
        print(f"ok {path.name}: {n_tris} triangles, {len(faces)} faces ({readers})")
    print(f"{len(files)} passed, 0 failed")


if __name__ == "__main__":
    main()
