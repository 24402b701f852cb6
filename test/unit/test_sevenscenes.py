"""The 7-Scenes converter on the real frames in ../shared/data (read in place)."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from lightfast.bag import open_bag
from lightfast.data.errors import DatasetError
from lightfast.data.sevenscenes import (
    COLOR_INFO_TOPIC,
    COLOR_TOPIC,
    DEPTH_TOPIC,
    GT_POSE_TOPIC,
    SevenScenes,
    colour_offset,
    convert_7scenes,
    shift_colour,
)
from lightfast.geometry import is_rotation
from lightfast.ros.convert import camera_from_camera_info, image_to_numpy, pose_stamped_to_matrix, stamp_to_ns


@pytest.fixture(scope="module")
def small_bag(sevenscenes_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return convert_7scenes(sevenscenes_dir, tmp_path_factory.mktemp("7s") / "bag", first=10, count=12, rate_hz=15.0)


def test_topics_counts_and_stamps(small_bag: Path) -> None:
    with open_bag(small_bag) as bag:
        info = bag.info
        assert {t.name: t.message_count for t in info.topics} == {
            "/camera/color/camera_info": 12, "/camera/color/image_raw": 12, "/camera/depth/camera_info": 12,
            "/camera/depth/image_raw": 12, "/ground_truth/pose": 12,
        }
        assert info.duration_ns == round(11 * 1e9 / 15.0)
        stamps = [stamp_to_ns(bag.deserialize(m).header.stamp) for m in bag.messages(topics=[COLOR_TOPIC])]
        logs = [m.log_time_ns for m in bag.messages(topics=[COLOR_TOPIC])]
        assert stamps == logs


def test_images_camera_and_pose_match_the_files(small_bag: Path, sevenscenes_dir: Path) -> None:
    with open_bag(small_bag) as bag:
        msgs = {t: [bag.deserialize(m) for m in bag.messages(topics=[t])] for t in
                (COLOR_TOPIC, DEPTH_TOPIC, COLOR_INFO_TOPIC, GT_POSE_TOPIC)}
    rgb = image_to_numpy(msgs[COLOR_TOPIC][0])
    expected = cv2.cvtColor(cv2.imread(str(sevenscenes_dir / "frame-000010.color.jpg")), cv2.COLOR_BGR2RGB)
    np.testing.assert_array_equal(rgb, expected)
    assert msgs[COLOR_TOPIC][0].encoding == "rgb8" and msgs[COLOR_TOPIC][0].header.frame_id == (
        "camera_color_optical_frame")
    depth = image_to_numpy(msgs[DEPTH_TOPIC][3])
    raw = cv2.imread(str(sevenscenes_dir / "frame-000013.depth.png"), cv2.IMREAD_UNCHANGED)
    assert depth.dtype == np.uint16 and msgs[DEPTH_TOPIC][3].encoding == "16UC1"
    np.testing.assert_array_equal(depth[raw != 65535], raw[raw != 65535])
    assert not np.any(depth == 65535)
    cam = camera_from_camera_info(msgs[COLOR_INFO_TOPIC][0])
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (585.0, 585.0, 320.0, 240.0, 640, 480)
    T_map_cam, _, frame = pose_stamped_to_matrix(msgs[GT_POSE_TOPIC][5])
    assert frame == "map"
    T_world_cam = np.loadtxt(sevenscenes_dir / "frame-000015.pose.txt")
    data = SevenScenes(sevenscenes_dir)
    np.testing.assert_allclose(T_map_cam, data.T_map_world @ T_world_cam, atol=2e-4)
    assert is_rotation(T_map_cam[:3, :3], atol=1e-9)


def test_map_frame_is_z_up(sevenscenes_dir: Path) -> None:
    data = SevenScenes(sevenscenes_dir)
    gravity_world = np.loadtxt(sevenscenes_dir / "gravity-direction.txt")
    gravity_map = data.T_map_world[:3, :3] @ (gravity_world / np.linalg.norm(gravity_world))
    np.testing.assert_allclose(gravity_map, [0.0, 0.0, -1.0], atol=1e-9)


def test_the_invalid_depth_marker_is_present_in_the_data(sevenscenes_dir: Path) -> None:
    """PROVENANCE: 108 px of 65535 in 4 frames. The converter maps them to 0; make sure the case is exercised."""
    data = SevenScenes(sevenscenes_dir)
    marked = [i for i in data.indices
              if np.any(cv2.imread(str(sevenscenes_dir / f"frame-{i:06d}.depth.png"), cv2.IMREAD_UNCHANGED) == 65535)]
    assert len(marked) == 4
    assert not np.any(data.frame(marked[0]).depth_mm == 65535)


def test_bad_input(tmp_path: Path, sevenscenes_dir: Path) -> None:
    with pytest.raises(DatasetError, match="no 7-Scenes folder"):
        SevenScenes(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError, match="no frame-NNNNNN"):
        SevenScenes(tmp_path / "empty")
    with pytest.raises(DatasetError, match="no frames selected"):
        convert_7scenes(sevenscenes_dir, tmp_path / "out", first=1000)
    assert not (tmp_path / "out").exists()


def test_colour_offset_recovers_a_known_misregistration() -> None:
    """Boxes in front of a wall: depth edges at the boxes' outlines; the colour image shows the same boxes moved by
    (6, -4) px (plus texture noise); the estimated registration moves them back."""
    rng = np.random.default_rng(5)
    frames = []
    for _ in range(4):
        depth = np.full((240, 320), 3000, np.uint16)
        colour = np.full((240, 320, 3), 90, np.uint8)
        for _ in range(5):
            x, y = rng.integers(50, 230), rng.integers(50, 150)
            w, h = rng.integers(15, 40, size=2)
            depth[y:y + h, x:x + w] = 1500
            colour[y:y + h, x:x + w] = rng.integers(150, 250, 3)
        colour = np.clip(colour + rng.normal(0, 4, colour.shape), 0, 255).astype(np.uint8)
        frames.append((shift_colour(colour, (6, -4)), depth))
    assert colour_offset(frames, search_px=12, step_px=2) == (-6, 4)
    assert colour_offset(frames, search_px=12, step_px=1) == (-6, 4)
