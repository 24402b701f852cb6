"""The 7-Scenes converter on the real frames in ../shared/data (read in place)."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from lightfast.bag import open_bag
from lightfast.camera import PinholeCamera
from lightfast.data.errors import DatasetError
from lightfast.data.sevenscenes import (
    COLOR_INFO_TOPIC,
    COLOR_TOPIC,
    DEPTH_TOPIC,
    GT_POSE_TOPIC,
    ColourRegistration,
    SevenScenes,
    colour_registration,
    convert_7scenes,
    register_colour,
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


def test_colour_registration_recovers_a_known_similarity() -> None:
    """Boxes in front of a wall: depth edges at the boxes' outlines; the colour image is what a camera with 0.9 times
    the depth camera's focal length, shifted by (-8, +3) px, sees (plus texture noise): the estimate recovers it,
    and registering the colour with it puts the boxes' colour back on their depth."""
    rng = np.random.default_rng(5)
    camera = PinholeCamera(320, 240, 292.5, 292.5, 160.0, 120.0)
    truth = ColourRegistration(0.9, -8.0, 3.0)
    frames, boxes = [], []
    for _ in range(4):
        depth = np.full((240, 320), 3000, np.uint16)
        colour = np.full((240, 320, 3), 90, np.uint8)
        for _ in range(6):
            x, y = rng.integers(40, 250), rng.integers(40, 170)
            w, h = rng.integers(15, 40, size=2)
            depth[y:y + h, x:x + w] = 1500
            colour[y:y + h, x:x + w] = rng.integers(150, 250, 3)
        colour = np.clip(colour + rng.normal(0, 4, colour.shape), 0, 255).astype(np.uint8)
        # the colour camera's image: colour pixel truth(u, v) shows depth pixel (u, v)
        seen = cv2.warpAffine(colour, truth.matrix(camera), (320, 240), flags=cv2.INTER_NEAREST,
                              borderMode=cv2.BORDER_REPLICATE)
        frames.append((seen, depth))
        boxes.append(colour)
    est = colour_registration(frames, camera)
    assert abs(est.scale - 0.9) <= 0.0051 and abs(est.dx_px + 8.0) <= 1.0 and abs(est.dy_px - 3.0) <= 1.0, est
    for (seen, _), colour in zip(frames, boxes, strict=True):
        inner = np.s_[30:-30, 30:-30]
        back = register_colour(seen, est, camera)[inner].astype(int)
        moved, unregistered = np.abs(back - colour[inner]).mean(), np.abs(seen[inner] - colour[inner]).mean()
        assert moved < 0.25 * unregistered, (moved, unregistered)
    with pytest.raises(DatasetError, match="at least one frame"):
        colour_registration([], camera)


def test_colour_registration_of_the_real_frames_is_one_similarity(sevenscenes_dir: Path) -> None:
    """On the real Kinect v1 frames, both halves of the sequence (every 15th frame, estimated separately) give the
    same scale, near the colour / depth focal-length ratio of the OpenNI defaults (525 / 585 = 0.897), and shifts
    within 4 px of each other (the shift stands for the baseline at the scene's depth)."""
    ds = SevenScenes(sevenscenes_dir)
    halves = [ds.indices[:150:15], ds.indices[150::15]]
    est = [colour_registration([(f.rgb, f.depth_mm) for f in map(ds.frame, half)], ds.camera) for half in halves]
    assert all(abs(e.scale - 0.897) < 0.02 for e in est), est
    assert abs(est[0].scale - est[1].scale) <= 0.01 and abs(est[0].dx_px - est[1].dx_px) <= 4.0, est
    assert abs(est[0].dy_px - est[1].dy_px) <= 4.0, est
