"""``sun_update_node``: publishes the sun direction and streams B̂_sun updates in chunks (paper §III-E).

Publishes ``/sun/direction`` (geometry_msgs/Vector3Stamped, unit vector towards the sun in the map frame) at
``direction_rate_hz`` and ``/radiosity/sun_chunk`` (sensor_msgs/PointCloud2 with fields ``vertex`` uint32 and ``r g
b`` float32: B̂_sun of a contiguous vertex range; ``header.stamp`` is the sun time of the update — its epoch; the
chunks of an epoch cover every vertex of the lighting map exactly once, so a subscriber holding the same map knows
an epoch is complete when it has all vertices). Time is the node clock: with ``use_sim_time`` it follows /clock,
e.g. from ``lightfast bag play --clock``; when it jumps back (a bag played again) the running update is dropped and
one for the new time starts.
"""
from __future__ import annotations

import sys
from typing import Any

import numpy as np
from geometry_msgs.msg import Vector3, Vector3Stamped
from sensor_msgs.msg import PointCloud2

from lightfast.config import ConfigError
from lightfast.daylight.lighting_map import LightingMap
from lightfast.daylight.sun import Site
from lightfast.daylight.sun_update import SunChunk, SunUpdateConfig, SunUpdatePipeline
from lightfast.errors import LightfastError
from lightfast.node_options import TIME_JUMP_BACK_S
from lightfast.ros.clock import on_time_jump_back
from lightfast.ros.convert import make_header, numpy_to_pointcloud2
from lightfast.ros.node import LightfastNode
from lightfast.ros.qos import LATCHED_QOS, OUTPUT_QOS
from lightfast.ros.runtime import run_node
from lightfast.topics import SUN_CHUNK_TOPIC, SUN_DIRECTION_TOPIC

NODE_NAME = "sun_update_node"
CHUNK_DTYPE = np.dtype([("vertex", "<u4"), ("r", "<f4"), ("g", "<f4"), ("b", "<f4")])


def chunk_to_array(chunk: SunChunk) -> np.ndarray:
    out = np.empty(len(chunk.radiosity), dtype=CHUNK_DTYPE)
    out["vertex"] = chunk.vertex_ids
    out["r"], out["g"], out["b"] = chunk.radiosity.T
    return out


class SunUpdateNode(LightfastNode[SunUpdateConfig]):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, SunUpdateConfig, status_topic=None, **kwargs)
        cfg = self.params.config
        if not cfg.lighting_map:
            raise ConfigError("parameter lighting_map is required (a directory made by `lightfast daylight prepare`)")
        lmap = LightingMap.load(cfg.lighting_map)
        site = Site.from_yaml(cfg.site_file) if cfg.site_file else None
        self.pipeline = SunUpdatePipeline(lmap, cfg, site=site)
        self.params.on_change = self._reconfigure
        self.direction_pub = self.create_publisher(Vector3Stamped, SUN_DIRECTION_TOPIC, LATCHED_QOS)
        self.chunk_pub = self.create_publisher(PointCloud2, SUN_CHUNK_TOPIC, OUTPUT_QOS)
        self.direction_timer = self.create_timer(1.0 / cfg.direction_rate_hz, self._publish_direction)
        self.step_timer = self.create_timer(cfg.step_period_s, self._step)
        self._jump_handle = on_time_jump_back(self, TIME_JUMP_BACK_S, self._on_clock_jump)
        self.get_logger().info(
            f"lighting map {cfg.lighting_map}: {lmap.num_vertices} vertices, {lmap.patches.count} patches; "
            f"site {self.pipeline.site.latitude_deg:.4f}, {self.pipeline.site.longitude_deg:.4f}"
        )
        self.announce_ready()

    def _now_ns(self) -> int | None:
        now = self.now_ns()
        return now if now > 0 else None  # use_sim_time before the first /clock message

    def _on_clock_jump(self, now_ns: int, jump_ns: int) -> None:
        """ROS time went back (executor thread, like the timers): start over with an update for the new time."""
        self.pipeline.restart()
        self.get_logger().warning(f"ROS time jumped back {-jump_ns * 1e-9:.3f} s to {now_ns * 1e-9:.3f} s (a bag "
                                  "played again, or looped?): the running sun update is dropped, a new one starts")

    def _reconfigure(self, cfg: SunUpdateConfig) -> None:
        self.pipeline.config = cfg
        self.direction_timer.timer_period_ns = int(1e9 / cfg.direction_rate_hz)
        self.step_timer.timer_period_ns = int(cfg.step_period_s * 1e9)

    def _publish_direction(self) -> None:
        now = self._now_ns()
        if now is None:
            return
        d = self.pipeline.sun(now).direction_map
        msg = Vector3Stamped(header=make_header(now, self.pipeline.config.frame_id),
                             vector=Vector3(x=float(d[0]), y=float(d[1]), z=float(d[2])))
        self.direction_pub.publish(msg)

    def _step(self) -> None:
        now = self._now_ns()
        if now is None:
            return
        try:
            chunk = self.pipeline.step(now)
        except LightfastError as exc:  # keep the last good state and try again next period
            self.get_logger().error(f"sun update step failed: {exc}", throttle_duration_sec=5.0)
            return
        if chunk is not None:
            self.chunk_pub.publish(numpy_to_pointcloud2(chunk_to_array(chunk), stamp_ns=chunk.epoch_ns,
                                                        frame_id=self.pipeline.config.frame_id))


def main(args: list[str] | None = None) -> int:
    return run_node(SunUpdateNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
