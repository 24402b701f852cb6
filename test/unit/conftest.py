"""Fixtures shared by the core unit tests."""
from __future__ import annotations

import pytest
import yaml

from lightfast.camera import PinholeCamera
from lightfast.daylight.crf import CameraResponse
from lightfast.sim.daylight.recordings import _camera_yaml
from lightfast.sim.daylight.sensors import CameraResponse as SimCameraResponse
from lightfast.sim.daylight.sensors import DepthSensor


@pytest.fixture(scope="module")
def true_crf() -> CameraResponse:
    """The simulator's true camera (sRGB + shoulder), through its camera.yaml."""
    sim = SimCameraResponse(exposure_s=0.004)
    doc = yaml.safe_load(_camera_yaml(sim, DepthSensor(), PinholeCamera(320, 240, 250.0, 250.0, 159.5, 119.5)))
    return CameraResponse.from_dict(doc)
