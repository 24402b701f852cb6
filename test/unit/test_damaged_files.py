"""Every file a node reads at start-up, damaged in the usual ways (empty, cut in half, garbage bytes, a YAML list,
fields of the wrong type): the loader raises its own LightfastError with the reason -- the node turns that into one
line and exit 1, or a throttled log line -- and never anything else (a traceback)."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from lightfast.config import load_config_yaml
from lightfast.daylight.crf import CameraResponse, load_crf, save_crf
from lightfast.daylight.sun import FREIBURG, Site
from lightfast.errors import LightfastError
from lightfast.tracking.pipeline import TrackerConfig


def damaged_variants(good: bytes) -> dict[str, bytes]:
    doc = yaml.safe_load(good)
    wrong_types = {k: ([1, 2] if isinstance(v, str) else "x") for k, v in doc.items()} if isinstance(doc, dict) else []
    return {
        "empty": b"",
        "half": good[: len(good) // 2],
        "garbage": bytes(range(256)) * 4,
        "a list": b"- 1\n- 2\n",
        "a scalar": b"42\n",
        "wrong types": yaml.safe_dump(wrong_types).encode(),
        "unclosed": b"key: [1, 2\n",
    }


def crf_file(tmp: Path) -> Path:
    return save_crf(CameraResponse.from_function(lambda v: (v / 255.0) ** 2.2, exposure_s=0.004), tmp / "crf.yaml")


def site_file(tmp: Path) -> Path:
    path = tmp / "site.yaml"
    path.write_text(yaml.safe_dump(FREIBURG.to_dict()))
    return path


def params_file(tmp: Path) -> Path:
    from lightfast.config import config_yaml

    path = tmp / "params.yaml"
    path.write_text(config_yaml(TrackerConfig, node_name="rgbd_tracker_node"))
    return path


LOADERS: dict[str, tuple[Callable[[Path], Path], Callable[[Path], object]]] = {
    "crf": (crf_file, load_crf),
    "site": (site_file, Site.from_yaml),
    "params": (params_file, lambda p: load_config_yaml(TrackerConfig, p, node_name="rgbd_tracker_node")),
}


def outcome(load: Callable[[Path], object], path: Path, what: str) -> str:
    """"ok", or "refused" for the loader's LightfastError; anything else fails the test (a traceback in a node)."""
    try:
        load(path)
    except LightfastError:
        return "refused"
    except Exception as exc:
        pytest.fail(f"{what}: {type(exc).__name__}: {exc}")
    return "ok"


@pytest.mark.parametrize("kind", sorted(LOADERS))
def test_damaged_files_raise_the_loaders_error(kind: str, tmp_path: Path) -> None:
    make, load = LOADERS[kind]
    good = make(tmp_path)
    assert outcome(load, good, "the good file") == "ok"
    for name, data in damaged_variants(good.read_bytes()).items():
        bad = tmp_path / f"{name}.yaml"
        bad.write_bytes(data)
        # a file cut at a line end can still be valid YAML with fewer keys (defaults fill in): either is right
        allowed = {"ok", "refused"} if name == "half" else {"refused"}
        assert outcome(load, bad, f"{kind} file {name!r}") in allowed, f"{kind} file {name!r} was accepted"
    assert outcome(load, tmp_path / "missing.yaml", "missing") == "refused"
