"""The teach map of colour-constant VT&R and its versioned on-disk format: paper §IV-B ("keyframes in the new map
contain independent sets of SURF features from all three image sources, linked by relative transformations
computed by VO").

In memory: :class:`TeachMap` — keyframes (:class:`Keyframe`: per image source the landmarks of the keyframe's
stereo pair, :class:`Landmarks`: left pixels, 3-D points in the keyframe's left camera frame (m), descriptors),
the edges between consecutive keyframes (:class:`Edge`, ``T_parent_child`` from greyscale VO), the keyframe poses
chained from the first keyframe (``T_map_kf``, the "map" frame being the first keyframe's camera frame; only
relative poses between nearby keyframes are meaningful, as in the paper's relative map), and the cumulative path
distance (sum of edge translations, m) with :meth:`TeachMap.nearest` and :meth:`TeachMap.window`.

On disk (format ``lightfast-vtr-map``, :data:`MAP_VERSION` = 1), a directory::

    MAP/
      manifest.json           written last: format, version, camera, image sources, descriptor kind and size,
                              teach configuration; per keyframe its file, SHA-256, stamp, path distance, landmark
                              counts per source and the edge T_parent_child (4×4, row-major)
      staging.json            camera, sources and configuration, written first (lets a crashed teach be recovered)
      keyframes/kf_000000.npz one per keyframe (np.savez, no pickle): ``index``, ``stamp_ns``, ``T_parent_child``
                              and per source ``<s>_uv`` (N, 2) float32, ``<s>_points`` (N, 3) float64,
                              ``<s>_descriptors`` (N, D) uint8 (ORB) or float32 (SIFT)

Atomicity: :class:`MapWriter` builds the map beside the target (:func:`lightfast.io.atomic_directory`), writes
each keyframe file atomically as it comes and the manifest last, then renames the directory into place, replacing
a previous map (untouched until :meth:`MapWriter.commit`); an interrupted teach leaves a hidden ``.MAP.*.partial``
directory, from which :meth:`MapStore.recover` rebuilds the keyframes written so far. :meth:`MapStore.load` refuses
a bad map with a :class:`MapError`: :class:`MapNotFoundError` (no directory or manifest), :class:`MapVersionError`
(another format or version), :class:`MapCorruptError` (unreadable JSON, missing or truncated keyframe file,
checksum mismatch, wrong shapes, dtypes or counts, non-finite values, an edge that is not a rigid transform).
"""
from __future__ import annotations

import datetime as dt
import hashlib
import io
import json
import logging
import math
import os
from collections.abc import Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.io import atomic_directory, load_npz, read_json_mapping, write_bytes_atomic, write_text_atomic
from lightfast.vtr.errors import (
    MapCorruptError,
    MapExistsError,
    MapNotFoundError,
    MapVersionError,
    VtrInputError,
    VtrStateError,
)
from lightfast.vtr.features import StereoFeatures
from lightfast.vtr.stereo_config import FEATURE_TYPES
from lightfast.vtr.stereo_front_end import check_stereo_pair

__all__ = [
    "MAP_FORMAT",
    "MAP_VERSION",
    "Edge",
    "Keyframe",
    "Landmarks",
    "MapStore",
    "MapWriter",
    "TeachMap",
]

log = logging.getLogger(__name__)

MAP_FORMAT: Final = "lightfast-vtr-map"
MAP_VERSION: Final = 1
MANIFEST: Final = "manifest.json"
STAGING: Final = "staging.json"
KEYFRAME_DIR: Final = "keyframes"
_DESCRIPTOR_DTYPE: Final[dict[str, np.dtype[Any]]] = {"orb": np.dtype(np.uint8), "sift": np.dtype(np.float32)}
_RIGID_ATOL: Final = 1e-6


# --------------------------------------------------------------------------------------------------------------
# In-memory map


@dataclass(frozen=True)
class Landmarks:
    """Stereo landmarks of one image source in a keyframe: left pixels ``uv`` (N, 2) float32, ``points`` (N, 3)
    float64 in the keyframe's left camera frame (m), ``descriptors`` (N, D) of the left image."""

    uv: NDArray[np.float32]
    points: NDArray[np.float64]
    descriptors: NDArray[np.generic]

    def __len__(self) -> int:
        return int(self.uv.shape[0])

    @classmethod
    def from_stereo(cls, features: StereoFeatures) -> Landmarks:
        return cls(
            np.ascontiguousarray(features.uv_left, np.float32),
            np.ascontiguousarray(features.points, np.float64),
            np.ascontiguousarray(features.descriptors),
        )


@dataclass(frozen=True)
class Keyframe:
    """A keyframe: its index along the path, time stamp (ns) and landmarks per image source."""

    index: int
    stamp_ns: int
    landmarks: Mapping[str, Landmarks]

    def counts(self) -> dict[str, int]:
        return {s: len(lm) for s, lm in self.landmarks.items()}


@dataclass(frozen=True)
class Edge:
    """Relative transform between consecutive keyframes from greyscale VO: ``T_parent_child`` maps points of the
    child keyframe's camera frame into the parent's (m)."""

    parent: int
    child: int
    T_parent_child: NDArray[np.float64]


@dataclass(frozen=True)
class TeachMap:
    """Keyframes linked by VO edges (module docstring). Build with :meth:`from_parts`; load with
    :meth:`MapStore.load`."""

    keyframes: tuple[Keyframe, ...]
    edges: tuple[Edge, ...]
    sources: tuple[str, ...]
    feature: str
    descriptor_dim: int
    P_left: NDArray[np.float64]
    P_right: NDArray[np.float64]
    image_size: tuple[int, int]  # (width, height), px
    metadata: Mapping[str, Any] = field(default_factory=dict)
    T_map_kf: NDArray[np.float64] = field(init=False, repr=False)
    distance_m: NDArray[np.float64] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        k = len(self.keyframes)
        if k == 0:
            raise MapCorruptError("a teach map needs at least one keyframe")
        if len(self.edges) != k - 1:
            raise MapCorruptError(f"{k} keyframes need {k - 1} edges, got {len(self.edges)}")
        T = np.zeros((k, 4, 4))
        T[0] = np.eye(4)
        dist = np.zeros(k)
        for i, e in enumerate(self.edges, start=1):
            if e.parent != i - 1 or e.child != i:
                raise MapCorruptError(f"edge {i - 1} links {e.parent} -> {e.child}, expected {i - 1} -> {i}")
            T[i] = T[i - 1] @ e.T_parent_child
            dist[i] = dist[i - 1] + float(np.linalg.norm(e.T_parent_child[:3, 3]))
        object.__setattr__(self, "T_map_kf", T)
        object.__setattr__(self, "distance_m", dist)

    def __len__(self) -> int:
        return len(self.keyframes)

    @property
    def length_m(self) -> float:
        """Path length from the first to the last keyframe (m)."""
        return float(self.distance_m[-1])

    def T_a_b(self, a: int, b: int) -> NDArray[np.float64]:
        """Pose of keyframe ``b`` in keyframe ``a``'s frame (chained VO edges)."""
        self._check_index(a)
        self._check_index(b)
        if a == b:
            return np.eye(4)
        Ta, Tb = self.T_map_kf[a], self.T_map_kf[b]
        out = np.eye(4)
        out[:3, :3] = Ta[:3, :3].T @ Tb[:3, :3]
        out[:3, 3] = Ta[:3, :3].T @ (Tb[:3, 3] - Ta[:3, 3])
        return out

    def nearest(self, distance_along_path_m: float) -> int:
        """Index of the keyframe whose path distance is nearest to ``distance_along_path_m`` (clamped to the path;
        ties go to the earlier keyframe)."""
        if not math.isfinite(distance_along_path_m):
            raise VtrInputError(f"distance along the path must be finite, got {distance_along_path_m}")
        d = self.distance_m
        j = int(np.searchsorted(d, distance_along_path_m, side="left"))
        if j <= 0:
            return 0
        if j >= len(d):
            return len(d) - 1
        return j - 1 if distance_along_path_m - d[j - 1] <= d[j] - distance_along_path_m else j

    def window(self, index: int, radius: int) -> range:
        """Keyframe indices within ``radius`` keyframes of ``index`` (clipped to the map), in path order."""
        self._check_index(index)
        if radius < 0:
            raise VtrInputError(f"window radius must be >= 0, got {radius}")
        return range(max(0, index - radius), min(len(self.keyframes), index + radius + 1))

    def path_direction(self, index: int) -> NDArray[np.float64]:
        """Unit direction of travel at keyframe ``index`` in its own frame (towards the next keyframe, or from
        the previous one at the end of the path); the optical axis (0, 0, 1) for a single-keyframe map or a
        zero-length edge."""
        self._check_index(index)
        if index + 1 < len(self.keyframes):
            v = self.edges[index].T_parent_child[:3, 3]
        elif index > 0:
            v = self.T_a_b(index, index - 1)[:3, 3] * -1.0
        else:
            v = np.zeros(3)
        n = float(np.linalg.norm(v))
        return v / n if n > 1e-9 else np.array([0.0, 0.0, 1.0])

    def along_path_m(self, index: int, T_kf_cam: NDArray[np.float64]) -> float:
        """Distance along the taught path (m) of a camera pose given in keyframe ``index``'s frame."""
        return float(self.distance_m[index] + T_kf_cam[:3, 3] @ self.path_direction(index))

    def _check_index(self, index: int) -> None:
        if not 0 <= index < len(self.keyframes):
            raise VtrInputError(f"keyframe index {index} outside the map (0..{len(self.keyframes) - 1})")


# --------------------------------------------------------------------------------------------------------------
# Writing


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _keyframe_file(index: int) -> str:
    return f"{KEYFRAME_DIR}/kf_{index:06d}.npz"


def _check_rigid(T: ArrayLike, what: str, error: type[Exception]) -> NDArray[np.float64]:
    m = np.asarray(T, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise error(f"{what} must be a finite 4x4 transform, got shape {m.shape}")
    R = m[:3, :3]
    if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0]) or not np.allclose(R.T @ R, np.eye(3), atol=_RIGID_ATOL) \
            or np.linalg.det(R) <= 0.0:
        raise error(f"{what} is not a rigid transform")
    return m


def _camera_json(P_left: NDArray[np.float64], P_right: NDArray[np.float64], image_size: tuple[int, int]
                 ) -> dict[str, Any]:
    return {"P_left": P_left.tolist(), "P_right": P_right.tolist(), "width": int(image_size[0]),
            "height": int(image_size[1])}


class MapWriter:
    """Writes a map directory incrementally and atomically (module docstring). Use as a context manager (commit
    on success, abort on an exception) or call :meth:`add_keyframe` … :meth:`commit` / :meth:`abort`."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        sources: Sequence[str],
        feature: str,
        descriptor_dim: int,
        P_left: ArrayLike,
        P_right: ArrayLike,
        image_size: tuple[int, int],
        metadata: Mapping[str, Any] | None = None,
        overwrite: bool = False,
    ) -> None:
        if feature not in FEATURE_TYPES:
            raise VtrInputError(f"unknown feature type {feature!r} (one of {list(FEATURE_TYPES)})")
        if not sources or len(set(sources)) != len(sources):
            raise VtrInputError(f"sources must be distinct and non-empty, got {list(sources)}")
        self.path = Path(path)
        self.sources = tuple(sources)
        self.feature = feature
        self.descriptor_dim = int(descriptor_dim)
        Pl, Pr = check_stereo_pair(P_left, P_right)
        self.P_left, self.P_right = Pl, Pr
        w, h = (int(x) for x in image_size)
        if w <= 0 or h <= 0:
            raise VtrInputError(f"image size must be positive, got {image_size}")
        self.image_size = (w, h)
        self.metadata = dict(metadata or {})
        self._entries: list[dict[str, Any]] = []
        self._stack = ExitStack()
        try:
            self._tmp = self._stack.enter_context(atomic_directory(self.path, overwrite=overwrite))
        except FileExistsError as exc:
            raise MapExistsError(f"a map exists at {self.path} (allow overwriting to replace it)") from exc
        self._open = True
        (self._tmp / KEYFRAME_DIR).mkdir()
        write_text_atomic(self._tmp / STAGING, json.dumps(self._header(), indent=1) + "\n")
        log.debug("writing map %s in %s", self.path, self._tmp)

    def _header(self) -> dict[str, Any]:
        return {
            "format": MAP_FORMAT,
            "version": MAP_VERSION,
            "sources": list(self.sources),
            "feature": self.feature,
            "descriptor_dim": self.descriptor_dim,
            "descriptor_dtype": _DESCRIPTOR_DTYPE[self.feature].name,
            "camera": _camera_json(self.P_left, self.P_right, self.image_size),
            "metadata": self.metadata,
        }

    @property
    def staging_path(self) -> Path:
        """The hidden directory the map is built in until :meth:`commit`."""
        return self._tmp

    def __len__(self) -> int:
        return len(self._entries)

    def add_keyframe(
        self, stamp_ns: int, landmarks: Mapping[str, Landmarks], T_parent_child: ArrayLike | None = None
    ) -> int:
        """Write the next keyframe (atomically) and return its index. ``T_parent_child`` links it to the previous
        keyframe (required except for the first)."""
        if not self._open:
            raise VtrStateError("the map writer is closed")
        index = len(self._entries)
        if index == 0:
            T = np.eye(4)
            if T_parent_child is not None and not np.allclose(T_parent_child, np.eye(4)):
                raise VtrInputError("the first keyframe has no parent: T_parent_child must be None")
        else:
            if T_parent_child is None:
                raise VtrInputError(f"keyframe {index} needs T_parent_child")
            T = _check_rigid(T_parent_child, "T_parent_child", VtrInputError)
        missing = [s for s in self.sources if s not in landmarks]
        if missing:
            raise VtrInputError(f"keyframe {index} lacks landmarks of {missing}")
        arrays: dict[str, NDArray[np.generic]] = {
            "index": np.array(index, np.int64),
            "stamp_ns": np.array(int(stamp_ns), np.int64),
            "T_parent_child": T,
        }
        counts = {}
        for s in self.sources:
            lm = landmarks[s]
            _check_landmarks(lm, self.feature, self.descriptor_dim, f"keyframe {index} source {s}", VtrInputError)
            arrays[f"{s}_uv"] = np.ascontiguousarray(lm.uv, np.float32)
            arrays[f"{s}_points"] = np.ascontiguousarray(lm.points, np.float64)
            arrays[f"{s}_descriptors"] = np.ascontiguousarray(lm.descriptors, _DESCRIPTOR_DTYPE[self.feature])
            counts[s] = len(lm)
        buf = io.BytesIO()
        np.savez(buf, allow_pickle=True, **arrays)  # the default, explicit: **arrays are arrays only
        data = buf.getvalue()
        name = _keyframe_file(index)
        write_bytes_atomic(self._tmp / name, data)
        self._entries.append({
            "index": index,
            "file": name,
            "sha256": _sha256(data),
            "stamp_ns": int(stamp_ns),
            "counts": counts,
            "T_parent_child": T.tolist(),
        })
        return index

    def commit(self) -> Path:
        """Write the manifest (last) and move the map into place, replacing a previous one (if allowed)."""
        if not self._open:
            raise VtrStateError("the map writer is closed")
        if not self._entries:
            self.abort()
            raise VtrInputError(f"no keyframes: nothing to save at {self.path}")
        dist = 0.0
        for i, e in enumerate(self._entries):
            if i:
                dist += float(np.linalg.norm(np.asarray(e["T_parent_child"])[:3, 3]))
            e["distance_m"] = dist
        manifest = self._header() | {
            "created": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "num_keyframes": len(self._entries),
            "length_m": dist,
            "keyframes": self._entries,
        }
        write_text_atomic(self._tmp / MANIFEST, json.dumps(manifest, indent=1) + "\n")
        self._open = False
        self._stack.close()  # moves the directory into place
        log.info("map with %d keyframes (%.1f m) written to %s", len(self._entries), dist, self.path)
        return self.path

    def abort(self) -> None:
        """Discard the keyframes written so far; a previous map at the path stays as it was."""
        if not self._open:
            return
        self._open = False
        self._stack.__exit__(VtrStateError, VtrStateError("map writing aborted"), None)

    def __enter__(self) -> MapWriter:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            if self._open:
                self.commit()
        else:
            self.abort()


def _check_landmarks(lm: Landmarks, feature: str, dim: int, what: str, error: type[Exception]) -> None:
    n = lm.uv.shape[0] if lm.uv.ndim == 2 else -1
    if lm.uv.shape != (n, 2) or n < 0:
        raise error(f"{what}: uv must be (N, 2), got {lm.uv.shape}")
    if lm.points.shape != (n, 3):
        raise error(f"{what}: points must be ({n}, 3), got {lm.points.shape}")
    if lm.descriptors.shape != (n, dim):
        raise error(f"{what}: descriptors must be ({n}, {dim}), got {lm.descriptors.shape}")
    if lm.descriptors.dtype != _DESCRIPTOR_DTYPE[feature]:
        raise error(f"{what}: {feature} descriptors must be {_DESCRIPTOR_DTYPE[feature]}, got {lm.descriptors.dtype}")
    if not (np.all(np.isfinite(lm.uv)) and np.all(np.isfinite(lm.points))):
        raise error(f"{what}: non-finite pixels or points")


# --------------------------------------------------------------------------------------------------------------
# Reading


def _get(d: Mapping[str, Any], key: str, kind: type | tuple[type, ...], what: str) -> Any:
    if key not in d:
        raise MapCorruptError(f"{what}: missing {key!r}")
    v = d[key]
    if not isinstance(v, kind) or (kind is int and isinstance(v, bool)):
        raise MapCorruptError(f"{what}: {key!r} has the wrong type ({type(v).__name__})")
    return v


def _check_header(h: Mapping[str, Any], where: Path) -> tuple[tuple[str, ...], str, int, NDArray[np.float64],
                                                               NDArray[np.float64], tuple[int, int]]:
    if h.get("format") != MAP_FORMAT:
        raise MapVersionError(f"{where} is not a {MAP_FORMAT} map (format {h.get('format')!r})")
    if h.get("version") != MAP_VERSION:
        raise MapVersionError(f"{where} has map version {h.get('version')!r}; this code reads version {MAP_VERSION}")
    what = str(where)
    sources = tuple(_get(h, "sources", list, what))
    if not sources or not all(isinstance(s, str) for s in sources) or len(set(sources)) != len(sources):
        raise MapCorruptError(f"{what}: bad source list {list(sources)}")
    feature = _get(h, "feature", str, what)
    if feature not in FEATURE_TYPES:
        raise MapCorruptError(f"{what}: unknown feature type {feature!r}")
    dim = _get(h, "descriptor_dim", int, what)
    if dim <= 0 or h.get("descriptor_dtype") != _DESCRIPTOR_DTYPE[feature].name:
        raise MapCorruptError(f"{what}: bad descriptor size/dtype for {feature}")
    cam = _get(h, "camera", dict, what)
    try:
        Pl, Pr = check_stereo_pair(np.asarray(cam["P_left"], float), np.asarray(cam["P_right"], float))
        size = (int(cam["width"]), int(cam["height"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise MapCorruptError(f"{what}: bad camera block: {exc}") from exc
    if size[0] <= 0 or size[1] <= 0:
        raise MapCorruptError(f"{what}: bad image size {size}")
    return sources, feature, dim, Pl, Pr, size


def _load_keyframe(root: Path, entry: Mapping[str, Any], index: int, sources: tuple[str, ...], feature: str,
                   dim: int, check_sha: str | None) -> tuple[Keyframe, NDArray[np.float64]]:
    what = f"keyframe {index}"
    name = _keyframe_file(index)
    path = root / name
    try:
        data = path.read_bytes()
    except FileNotFoundError as exc:
        raise MapCorruptError(f"{what}: file {path} is missing") from exc
    except OSError as exc:
        raise MapCorruptError(f"{what}: cannot read {path}: {exc}") from exc
    if check_sha is not None and _sha256(data) != check_sha:
        raise MapCorruptError(f"{what}: {path} does not match its checksum (truncated or altered)")
    arrays = load_npz(path, error=MapCorruptError, what=what, data=data)
    try:
        file_index = int(arrays["index"])
        stamp_ns = int(arrays["stamp_ns"])
        T = _check_rigid(arrays["T_parent_child"], f"{what}: T_parent_child", MapCorruptError)
        landmarks = {}
        for s in sources:
            uv, pts, desc = arrays[f"{s}_uv"], arrays[f"{s}_points"], arrays[f"{s}_descriptors"]
            if uv.dtype != np.float32 or pts.dtype != np.float64:
                raise MapCorruptError(f"{what} source {s}: uv must be float32 and points float64")
            lm = Landmarks(uv, pts, desc)
            _check_landmarks(lm, feature, dim, f"{what} source {s}", MapCorruptError)
            landmarks[s] = lm
    except KeyError as exc:
        raise MapCorruptError(f"{what}: {path} lacks array {exc}") from exc
    except (TypeError, ValueError) as exc:
        raise MapCorruptError(f"{what}: {path} has malformed arrays: {exc}") from exc
    if file_index != index:
        raise MapCorruptError(f"{what}: {path} holds keyframe {file_index}")
    if entry:
        counts = entry.get("counts")
        if not isinstance(counts, dict) or {s: len(landmarks[s]) for s in sources} != counts:
            raise MapCorruptError(f"{what}: landmark counts {counts} differ from the file's")
        if entry.get("stamp_ns") != stamp_ns:
            raise MapCorruptError(f"{what}: stamp differs between manifest and file")
        try:
            T_manifest = np.asarray(entry["T_parent_child"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as exc:
            raise MapCorruptError(f"{what}: bad edge in the manifest: {exc}") from exc
        if T_manifest.shape != (4, 4) or not np.array_equal(T_manifest, T):
            raise MapCorruptError(f"{what}: edge differs between manifest and file")
    return Keyframe(index, stamp_ns, landmarks), T


def _assemble(keyframes: list[Keyframe], Ts: list[NDArray[np.float64]], sources: tuple[str, ...], feature: str,
              dim: int, Pl: NDArray[np.float64], Pr: NDArray[np.float64], size: tuple[int, int],
              metadata: Mapping[str, Any]) -> TeachMap:
    if not np.allclose(Ts[0], np.eye(4)):
        raise MapCorruptError("the first keyframe must have the identity as its edge")
    edges = tuple(Edge(i - 1, i, Ts[i]) for i in range(1, len(keyframes)))
    return TeachMap(tuple(keyframes), edges, sources, feature, dim, Pl, Pr, size, dict(metadata))


class MapStore:
    """Loads, saves and recovers teach maps (module docstring). All methods are static."""

    @staticmethod
    def exists(path: str | os.PathLike[str]) -> bool:
        """Whether ``path`` holds a manifest (a finished map; not validated)."""
        return (Path(path) / MANIFEST).is_file()

    @staticmethod
    def load(path: str | os.PathLike[str]) -> TeachMap:
        """Load and validate a map directory; raises :class:`MapNotFoundError`, :class:`MapVersionError` or
        :class:`MapCorruptError` (all :class:`MapError`, a :class:`~lightfast.vtr.errors.VtrError`)."""
        root = Path(path)
        if not root.is_dir():
            raise MapNotFoundError(f"no teach map at {root} (no such directory)")
        manifest_path = root / MANIFEST
        if not manifest_path.is_file():
            raise MapNotFoundError(f"no complete teach map at {root}: {MANIFEST} is missing (unfinished teach?)")
        m = read_json_mapping(manifest_path, error=MapCorruptError, what="manifest")
        sources, feature, dim, Pl, Pr, size = _check_header(m, manifest_path)
        what = str(manifest_path)
        entries = _get(m, "keyframes", list, what)
        n = _get(m, "num_keyframes", int, what)
        if n != len(entries) or n < 1:
            raise MapCorruptError(f"{what}: num_keyframes {n} but {len(entries)} keyframe entries")
        keyframes, Ts = [], []
        for i, e in enumerate(entries):
            if not isinstance(e, dict) or e.get("index") != i or e.get("file") != _keyframe_file(i):
                raise MapCorruptError(f"{what}: keyframe entry {i} is malformed")
            sha = e.get("sha256")
            if not isinstance(sha, str) or len(sha) != 64:
                raise MapCorruptError(f"{what}: keyframe entry {i} lacks its SHA-256")
            kf, T = _load_keyframe(root, e, i, sources, feature, dim, sha)
            keyframes.append(kf)
            Ts.append(T)
        metadata = m.get("metadata", {})
        if not isinstance(metadata, dict):
            raise MapCorruptError(f"{what}: metadata must be an object")
        teach_map = _assemble(keyframes, Ts, sources, feature, dim, Pl, Pr, size, metadata)
        for i, e in enumerate(entries):
            if not isinstance(e.get("distance_m"), (int, float)) or abs(e["distance_m"] - teach_map.distance_m[i]) \
                    > 1e-6 * max(1.0, teach_map.distance_m[i]):
                raise MapCorruptError(f"{what}: path distance of keyframe {i} disagrees with its edges")
        log.info("loaded map %s: %d keyframes, %.1f m, sources %s", root, len(teach_map), teach_map.length_m,
                 ",".join(sources))
        return teach_map

    @staticmethod
    def save(teach_map: TeachMap, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write a whole map atomically (same format as a teach)."""
        with MapWriter(path, sources=teach_map.sources, feature=teach_map.feature,
                       descriptor_dim=teach_map.descriptor_dim, P_left=teach_map.P_left, P_right=teach_map.P_right,
                       image_size=teach_map.image_size, metadata=teach_map.metadata, overwrite=overwrite) as w:
            for i, kf in enumerate(teach_map.keyframes):
                w.add_keyframe(kf.stamp_ns, kf.landmarks, teach_map.edges[i - 1].T_parent_child if i else None)
        return Path(path)

    @staticmethod
    def recover(partial: str | os.PathLike[str], path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Rebuild a map from the staging directory of an interrupted teach (``.MAP.*.partial``): the keyframes
        written before the interruption (consecutive from 0; each was written atomically) become a new map at
        ``path``. Raises :class:`MapNotFoundError` if the directory is not a staging directory or holds no
        keyframe."""
        root = Path(partial)
        if not (root / STAGING).is_file():
            raise MapNotFoundError(f"{root} is not the staging directory of a teach ({STAGING} missing)")
        h = read_json_mapping(root / STAGING, error=MapCorruptError, what="staging header")
        sources, feature, dim, Pl, Pr, size = _check_header(h, root / STAGING)
        keyframes: list[Keyframe] = []
        Ts: list[NDArray[np.float64]] = []
        while (root / _keyframe_file(len(keyframes))).is_file():
            kf, T = _load_keyframe(root, {}, len(keyframes), sources, feature, dim, None)
            keyframes.append(kf)
            Ts.append(T)
        if not keyframes:
            raise MapNotFoundError(f"{root} holds no keyframe to recover")
        metadata = h.get("metadata", {})
        recovered = _assemble(keyframes, Ts, sources, feature, dim, Pl, Pr, size,
                              (metadata if isinstance(metadata, dict) else {}) | {"recovered_from": str(root)})
        log.warning("recovered %d keyframes (%.1f m) from %s", len(recovered), recovered.length_m, root)
        return MapStore.save(recovered, path, overwrite=overwrite)
