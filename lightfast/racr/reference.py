"""The reference observation rACR relocalizes against (paper §3.1: the reference camera's view of the scene), as a
file format: a directory with ``reference.yaml`` (format ``lightfast-racr-reference``, version, scene, camera
intrinsics, reference camera pose ``T_ref_camref``), ``points.npz`` (the cloud in metres, frame ``frame_id``, with
grey intensity in [0, 1]) and ``image.png`` (the reference image, RGB). Written atomically, read with every damage
reported as a :class:`~lightfast.racr.errors.ReferenceFileError`.

The core owns the format (``racr_node`` reads it); the simulator (:mod:`lightfast.sim.racr`) writes one per
scene with the same functions.
"""
from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
import yaml
from numpy.typing import NDArray

from lightfast.camera import PinholeCamera
from lightfast.io import atomic_directory, load_npz, read_versioned_yaml
from lightfast.racr.errors import ReferenceFileError

__all__ = ["REFERENCE_FORMAT", "REFERENCE_VERSION", "ReferenceObservation", "camera_from_dict", "camera_to_dict",
           "load_reference", "matrix_from", "matrix_to_list", "npz_bytes", "png_bytes", "write_reference",
           "yaml_text"]

REFERENCE_FORMAT = "lightfast-racr-reference"
REFERENCE_VERSION = 1


@dataclass(frozen=True, eq=False)
class ReferenceObservation:
    """The reference observation (what rACR reads): cloud ``points_m`` (N, 3) float32 in frame ``frame_id``
    (metres) with ``intensity`` (N,) float32 in [0, 1], reference camera pose ``T_ref_camref``, ``image``
    (H, W, 3) uint8 RGB, ``camera`` intrinsics, the scene name and lighting name."""

    scene: str
    lighting: str
    camera: PinholeCamera
    T_ref_camref: NDArray[np.float64]
    points_m: NDArray[np.float32]
    intensity: NDArray[np.float32]
    image: NDArray[np.uint8]
    frame_id: str = "reference"


def matrix_to_list(T: Any) -> list[list[float]]:
    """A matrix as nested lists of floats (for YAML)."""
    return [[float(x) for x in row] for row in np.asarray(T, float)]


def matrix_from(x: Any, name: str, shape: tuple[int, ...] = (4, 4), *,
                error: type[Exception] = ReferenceFileError) -> NDArray[np.float64]:
    """A finite float matrix of ``shape`` read from YAML; ``error`` naming ``name`` otherwise."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise error(f"{name} must be a numeric matrix") from None
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise error(f"{name} must be a finite {shape} matrix, got shape {a.shape}")
    return a


def camera_to_dict(c: PinholeCamera) -> dict[str, Any]:
    return {"width": c.width, "height": c.height, "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy}


def camera_from_dict(d: Any, where: str, *, error: type[Exception] = ReferenceFileError) -> PinholeCamera:
    try:
        return PinholeCamera(int(d["width"]), int(d["height"]), float(d["fx"]), float(d["fy"]), float(d["cx"]),
                             float(d["cy"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise error(f"{where}: bad camera intrinsics: {exc}") from None


def yaml_text(doc: dict[str, Any]) -> str:
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=200)


def png_bytes(image: NDArray[np.uint8], *, error: type[Exception] = ReferenceFileError) -> bytes:
    """An RGB image as PNG bytes."""
    ok, buf = cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR))
    if not ok:
        raise error("PNG encoding failed")
    return bytes(buf.tobytes())


def npz_bytes(**arrays: NDArray[Any]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, allow_pickle=True, **arrays)  # the default, explicit: **arrays are arrays only
    return buf.getvalue()


def write_reference(ref: ReferenceObservation, path: str | os.PathLike[str]) -> Path:
    """Write the reference observation directory atomically (replacing an existing one)."""
    path = Path(path)
    with atomic_directory(path, overwrite=True) as tmp:
        (tmp / "points.npz").write_bytes(npz_bytes(points_m=np.asarray(ref.points_m, np.float32),
                                                   intensity=np.asarray(ref.intensity, np.float32)))
        (tmp / "image.png").write_bytes(png_bytes(ref.image))
        doc = {
            "format": REFERENCE_FORMAT, "format_version": REFERENCE_VERSION, "scene": ref.scene,
            "lighting": ref.lighting, "frame_id": ref.frame_id,
            "description": "rACR reference observation: point cloud (metres, frame_id) with grey intensity in "
                           "[0, 1], reference camera pose T_ref_camref (optical frame -> frame_id), image, "
                           "intrinsics",
            "camera": camera_to_dict(ref.camera), "T_ref_camref": matrix_to_list(ref.T_ref_camref),
            "points": "points.npz", "image": "image.png", "num_points": len(ref.points_m),
        }
        (tmp / "reference.yaml").write_text(yaml_text(doc))
    return path


def load_reference(path: str | os.PathLike[str], *, scene: str | None = None) -> ReferenceObservation:
    """Load a reference observation directory; with ``scene``, refuse one made for another scene. Raises
    :class:`ReferenceFileError` with the reason for a missing, half-written, damaged or foreign directory."""
    path = Path(path)
    meta = path / "reference.yaml"
    if not meta.is_file():
        raise ReferenceFileError(f"{path}: no reference observation (reference.yaml missing)")
    doc = read_versioned_yaml(meta, format_name=REFERENCE_FORMAT, version=REFERENCE_VERSION,
                              error=ReferenceFileError, what="a reference observation", version_key="format_version")
    if scene is not None and doc.get("scene") != scene:
        raise ReferenceFileError(f"{meta}: reference observation of scene {doc.get('scene')!r}, not {scene!r}")
    z = load_npz(path / str(doc.get("points", "points.npz")), error=ReferenceFileError, what="the reference cloud")
    try:
        pts = np.asarray(z["points_m"], np.float32)
        inten = np.asarray(z["intensity"], np.float32)
    except (KeyError, ValueError, TypeError) as exc:
        raise ReferenceFileError(f"{path}: cannot read the reference cloud: {exc!r}") from None
    if pts.ndim != 2 or pts.shape[1] != 3 or inten.shape != (len(pts),) or len(pts) != doc.get("num_points"):
        raise ReferenceFileError(f"{path}: reference cloud has shape {pts.shape} / intensity {inten.shape}, "
                                 f"expected ({doc.get('num_points')}, 3)")
    img = cv2.imread(str(path / str(doc.get("image", "image.png"))), cv2.IMREAD_COLOR)
    if img is None:
        raise ReferenceFileError(f"{path}: cannot read the reference image")
    cam = camera_from_dict(doc.get("camera"), str(meta))
    if img.shape[:2] != cam.shape:
        raise ReferenceFileError(f"{path}: image {img.shape[:2]} does not match the intrinsics {cam.shape}")
    return ReferenceObservation(str(doc["scene"]), str(doc.get("lighting", "")), cam,
                                matrix_from(doc.get("T_ref_camref"), "T_ref_camref"), pts, inten,
                                cast(NDArray[np.uint8], cv2.cvtColor(img, cv2.COLOR_BGR2RGB)),
                                str(doc.get("frame_id", "reference")))
