"""The scene model of the daylight papers: a triangle mesh with per-vertex diffuse reflectance (paper §III, [4]).

Vertices are in metres in the map frame (REP-103: x east, y north, z up when the site heading is 0). Reflectance
``rho`` is linear RGB diffuse albedo in [0, 1] (not sRGB-encoded). Vertex normals are area-weighted face normals
unless the file provides them (a lighting map stores the ones it was made with); each vertex stands for a third of
the area of its triangles.

PLY files (ASCII or binary) carry the reflectance as vertex properties ``red green blue``: float (taken as is) or
uchar (divided by 255). Open3D clamps and quantizes colours and drops other properties, so this module reads and
writes PLY itself (NumPy only).
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.daylight.errors import MeshError
from lightfast.io import write_bytes_atomic


@dataclass(frozen=True, eq=False)
class ReflectanceMesh:
    """Triangle mesh with per-vertex RGB reflectance. Arrays are read-only after construction."""

    vertices_m: NDArray[np.float64]  # (V, 3)
    faces: NDArray[np.int64]  # (F, 3) vertex indices, counter-clockwise seen from the front
    reflectance: NDArray[np.float64]  # (V, 3) linear RGB in [0, 1]
    normals_in: NDArray[np.float64] | None = field(default=None, repr=False)  # (V, 3) optional, from the file

    def __post_init__(self) -> None:
        # own copies: the arrays are made read-only below, which must not freeze the caller's arrays
        v = np.array(self.vertices_m, dtype=np.float64)
        f = np.array(self.faces, dtype=np.int64)
        rho = np.array(self.reflectance, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3:
            raise MeshError(f"vertices must have shape (V>=3, 3), got {v.shape}")
        if not np.all(np.isfinite(v)):
            raise MeshError("vertices contain NaN or infinite coordinates")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
            raise MeshError(f"faces must have shape (F>=1, 3), got {f.shape}")
        if f.min() < 0 or f.max() >= len(v):
            raise MeshError(f"face indices must lie in [0, {len(v) - 1}], got [{f.min()}, {f.max()}]")
        if rho.shape != v.shape:
            raise MeshError(f"reflectance must have shape {v.shape} (RGB per vertex), got {rho.shape}")
        if not np.all(np.isfinite(rho)) or rho.min() < 0.0 or rho.max() > 1.0:
            bad = int(np.count_nonzero(~np.isfinite(rho) | (rho < 0) | (rho > 1)))
            raise MeshError(
                f"reflectance must lie in [0, 1]; {bad} values do not "
                f"(range {np.nanmin(rho):.3g}..{np.nanmax(rho):.3g})"
            )
        for name, arr in (("vertices_m", v), ("faces", f), ("reflectance", rho)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if self.normals_in is not None:
            n = np.asarray(self.normals_in, dtype=np.float64)
            if n.shape != v.shape:
                raise MeshError(f"normals must have shape {v.shape}, got {n.shape}")
            if not np.all(np.isfinite(n)):
                raise MeshError("normals contain NaN or infinite values")
            object.__setattr__(self, "normals_in", n)

    @property
    def num_vertices(self) -> int:
        return len(self.vertices_m)

    @property
    def num_faces(self) -> int:
        return len(self.faces)

    @cached_property
    def face_normals_area2(self) -> NDArray[np.float64]:
        """Face normals scaled by twice the face area (the cross product of two edges)."""
        v = self.vertices_m.T  # (3, V): gathers by coordinate are contiguous
        f = self.faces
        e1 = v[:, f[:, 1]] - v[:, f[:, 0]]
        e2 = v[:, f[:, 2]] - v[:, f[:, 0]]
        return np.stack([e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]],
                        axis=1)

    @cached_property
    def face_areas_m2(self) -> NDArray[np.float64]:
        return 0.5 * np.linalg.norm(self.face_normals_area2, axis=1)

    @cached_property
    def face_normals(self) -> NDArray[np.float64]:
        n = self.face_normals_area2
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)

    @cached_property
    def vertex_areas_m2(self) -> NDArray[np.float64]:
        """A third of the area of every triangle a vertex belongs to."""
        # bincount with weights sums float64 (NumPy's stubs type every bincount as integer)
        return cast(NDArray[np.float64], np.bincount(self.faces.reshape(-1),
                                                     weights=np.repeat(self.face_areas_m2 / 3.0, 3),
                                                     minlength=self.num_vertices))

    @cached_property
    def vertex_normals(self) -> NDArray[np.float64]:
        """Unit vertex normals: from the file, else area-weighted face normals."""
        if self.normals_in is not None:
            n = self.normals_in
        else:
            idx = self.faces.reshape(-1)
            weighted = np.repeat(self.face_normals_area2, 3, axis=0)  # one row per (face, corner)
            n = np.stack([np.bincount(idx, weights=weighted[:, k], minlength=self.num_vertices) for k in range(3)],
                         axis=1)
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return np.where(norm > 1e-12, n / np.maximum(norm, 1e-300), 0.0)

    @cached_property
    def face_reflectance(self) -> NDArray[np.float64]:
        """Mean reflectance of each face's three vertices, (F, 3)."""
        return self.reflectance[self.faces].mean(axis=1)

    @cached_property
    def content_hash(self) -> str:
        """SHA-256 of the geometry and reflectance: identifies the mesh a lighting map was made for.

        Computed on float32-rounded coordinates and reflectance (what PLY files hold), so a mesh and its saved copy
        hash alike."""
        h = hashlib.sha256()
        for arr in (self.vertices_m.astype(np.float32), self.faces, self.reflectance.astype(np.float32)):
            h.update(str(arr.shape).encode())
            h.update(np.ascontiguousarray(arr).tobytes())
        return h.hexdigest()

    def validate_topology(self, *, min_area_m2: float = 1e-12) -> None:
        """Refuse degenerate triangles (repeated vertices or zero area) and non-manifold edges (an edge shared by
        more than two triangles)."""
        f = self.faces
        repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
        tiny = self.face_areas_m2 <= min_area_m2
        if np.any(repeated | tiny):
            idx = np.flatnonzero(repeated | tiny)
            raise MeshError(f"{len(idx)} degenerate triangles (zero area or repeated vertices), e.g. face {idx[0]}")
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        _, counts = np.unique(edges, axis=0, return_counts=True)
        if np.any(counts > 2):
            raise MeshError(f"{int(np.sum(counts > 2))} non-manifold edges (shared by more than two triangles)")


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2", "ushort": "u2",
    "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4",
    "double": "f8", "float64": "f8",
}


def _parse_header(raw: bytes, path: Path) -> tuple[str, list[tuple[str, int, list[tuple]]], int]:
    end = raw.find(b"end_header")
    if not raw.startswith(b"ply") or end < 0:
        raise MeshError(f"{path}: not a PLY file")
    header_end = raw.index(b"\n", end) + 1
    lines = raw[:header_end].decode("ascii", "replace").splitlines()
    fmt = ""
    elements: list[tuple[str, int, list[tuple]]] = []
    for line in lines[1:]:
        parts = line.split()
        if not parts or parts[0] in ("comment", "obj_info", "end_header"):
            continue
        if parts[0] == "format":
            fmt = parts[1]
        elif parts[0] == "element":
            elements.append((parts[1], int(parts[2]), []))
        elif parts[0] == "property" and elements:
            if parts[1] == "list":
                elements[-1][2].append(("list", parts[4], _PLY_TYPES[parts[2]], _PLY_TYPES[parts[3]]))
            else:
                elements[-1][2].append(("scalar", parts[2], _PLY_TYPES[parts[1]]))
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise MeshError(f"{path}: unsupported PLY format {fmt!r}")
    return fmt, elements, header_end


def load_ply(path: str | os.PathLike[str]) -> ReflectanceMesh:
    """Read a PLY triangle mesh with per-vertex reflectance ``red green blue`` (float or uchar)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise MeshError(f"cannot read mesh {path}: {exc.strerror}") from None
    try:
        fmt, elements, offset = _parse_header(raw, path)
    except (KeyError, ValueError, IndexError) as exc:
        raise MeshError(f"{path}: malformed PLY header ({exc})") from None
    data: dict[str, dict[str, np.ndarray]] = {}
    try:
        if fmt == "ascii":
            tokens = raw[offset:].split()
            pos = 0
            for name, count, props in elements:
                cols: dict[str, list] = {p[1]: [] for p in props}
                if all(p[0] == "scalar" for p in props):
                    n = len(props)
                    table = np.array(tokens[pos : pos + n * count], dtype=np.float64).reshape(count, n)
                    pos += n * count
                    data[name] = {p[1]: table[:, i].astype(p[2]) for i, p in enumerate(props)}
                    continue
                for _ in range(count):
                    for p in props:
                        if p[0] == "list":
                            k = int(tokens[pos])
                            cols[p[1]].append([int(t) for t in tokens[pos + 1 : pos + 1 + k]])
                            pos += 1 + k
                        else:
                            cols[p[1]].append(float(tokens[pos]))
                            pos += 1
                data[name] = {k: np.asarray(v) for k, v in cols.items()}
        else:
            endian = "<" if fmt == "binary_little_endian" else ">"
            for name, count, props in elements:
                if all(p[0] == "scalar" for p in props):
                    dtype = np.dtype([(p[1], endian + p[2]) for p in props])
                    arr = np.frombuffer(raw, dtype=dtype, count=count, offset=offset)
                    offset += dtype.itemsize * count
                    data[name] = {p[1]: arr[p[1]] for p in props}
                elif len(props) == 1 and props[0][0] == "list":
                    _, pname, count_t, item_t = props[0]
                    # fast path: every face a triangle
                    rec = np.dtype([("n", endian + count_t), ("idx", endian + item_t, (3,))])
                    arr = np.frombuffer(raw, dtype=rec, count=count, offset=offset)
                    if np.all(arr["n"] == 3):
                        offset += rec.itemsize * count
                        data[name] = {pname: arr["idx"].astype(np.int64)}
                    else:
                        raise MeshError(f"{path}: only triangle faces are supported")
                else:
                    raise MeshError(f"{path}: element {name!r} mixes lists and scalars (unsupported)")
    except MeshError:
        raise
    except (ValueError, IndexError, TypeError) as exc:
        raise MeshError(f"{path}: truncated or malformed PLY data ({exc})") from None
    vertex = data.get("vertex")
    face = data.get("face")
    if vertex is None or face is None:
        raise MeshError(f"{path}: needs 'vertex' and 'face' elements")
    if not all(k in vertex for k in ("x", "y", "z")):
        raise MeshError(f"{path}: vertices lack x, y, z")
    if not all(k in vertex for k in ("red", "green", "blue")):
        raise MeshError(f"{path}: vertices carry no reflectance (red, green, blue properties)")
    xyz = np.stack([vertex[k].astype(np.float64) for k in ("x", "y", "z")], axis=1)
    rgb_raw = [vertex[k] for k in ("red", "green", "blue")]
    scale = 255.0 if rgb_raw[0].dtype == np.uint8 else 1.0
    rho = np.stack([c.astype(np.float64) / scale for c in rgb_raw], axis=1)
    faces_key = next(iter(face))
    faces = face[faces_key]
    if faces.dtype == object or faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshError(f"{path}: only triangle faces are supported")
    normals = None
    if all(k in vertex for k in ("nx", "ny", "nz")):
        normals = np.stack([vertex[k].astype(np.float64) for k in ("nx", "ny", "nz")], axis=1)
    return ReflectanceMesh(xyz, faces.astype(np.int64), rho, normals)


def save_ply(mesh: ReflectanceMesh, path: str | os.PathLike[str]) -> None:
    """Write ``mesh`` as binary little-endian PLY (float32 positions, float32 reflectance), atomically."""
    vdtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "<f4"), ("green", "<f4"),
                       ("blue", "<f4")])
    vert = np.empty(mesh.num_vertices, dtype=vdtype)
    for i, k in enumerate(("x", "y", "z")):
        vert[k] = mesh.vertices_m[:, i]
    for i, k in enumerate(("red", "green", "blue")):
        vert[k] = mesh.reflectance[:, i]
    fdtype = np.dtype([("n", "u1"), ("idx", "<u4", (3,))])
    face = np.empty(mesh.num_faces, dtype=fdtype)
    face["n"] = 3
    face["idx"] = mesh.faces
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment lightfast reflectance mesh: red/green/blue are linear "
        f"diffuse reflectance in [0,1]\nelement vertex {mesh.num_vertices}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float red\nproperty float green\nproperty float blue\n"
        f"element face {mesh.num_faces}\nproperty list uchar uint vertex_indices\nend_header\n"
    )
    write_bytes_atomic(path, header.encode() + vert.tobytes() + face.tobytes())


def merge_meshes(parts: list[ReflectanceMesh]) -> ReflectanceMesh:
    """Concatenate meshes (vertices are not welded)."""
    offsets = np.cumsum([0] + [p.num_vertices for p in parts[:-1]])
    return ReflectanceMesh(
        np.concatenate([p.vertices_m for p in parts]),
        np.concatenate([p.faces + o for p, o in zip(parts, offsets, strict=True)]),
        np.concatenate([p.reflectance for p in parts]),
    )


def as_mesh(vertices_m: ArrayLike, faces: ArrayLike, reflectance: ArrayLike) -> ReflectanceMesh:
    """Build a mesh; a single RGB reflectance broadcasts to every vertex."""
    v = np.asarray(vertices_m, dtype=np.float64)
    rho = np.broadcast_to(np.asarray(reflectance, dtype=np.float64), v.shape).copy()
    return ReflectanceMesh(v, np.asarray(faces), rho)

