"""Background update of the normalized sun radiosity B̂_sun in bounded chunks (paper §III-E).

B̂_sun changes with the sun position. The paper computes it in a parallel thread, one chunk per frame, so that the
update never stalls tracking, and — knowing how many frames the update takes — aims it at the sun position of the
moment it will finish. Eq. 1–2 are linear in the light, which is what lets the work be split:

1. *direct* steps, one per block of ``chunk_vertices`` vertices: Eq. 1 for those vertices (|block|·|L_sun| rays)
   and their contribution to each patch's direct irradiance (a sum over blocks);
2. *transport* steps, one Jacobi iteration of Eq. 2 on the patches each;
3. *output* steps, one per block of vertices: B̂_sun = ρ·(E_direct + interpolated indirect irradiance). Each
   output step yields a finished :class:`SunChunk`; together they cover every vertex exactly once.

Every step costs at most max(|block|·|L_sun| rays, one |P|² product). The chunked result equals the one-shot
:func:`sun_radiosity` up to float rounding.
"""
from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.config import Config, param
from lightfast.daylight.lighting_map import LightingMap
from lightfast.daylight.radiosity import PatchRadiositySolver, direct_irradiance, indirect_patch_irradiance
from lightfast.daylight.sun import Site, SunPosition, sun_position

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SunChunk:
    """B̂_sun (normalized sun radiosity, linear RGB) of vertices ``first_vertex .. first_vertex + len - 1``."""

    epoch_ns: int  # the sun time this update is for (ns since the UNIX epoch, UTC)
    first_vertex: int
    radiosity: NDArray[np.float32]  # (n, 3)

    @property
    def vertex_ids(self) -> NDArray[np.uint32]:
        return np.arange(self.first_vertex, self.first_vertex + len(self.radiosity), dtype=np.uint32)


class SunUpdate:
    """One B̂_sun computation for ``direction_to_sun`` (map frame), split into bounded :meth:`step` calls."""

    def __init__(
        self,
        lmap: LightingMap,
        direction_to_sun: ArrayLike,
        *,
        epoch_ns: int = 0,
        chunk_vertices: int = 50_000,
        patches_per_step: int | None = None,
    ) -> None:
        if chunk_vertices < 1:
            raise ValueError(f"chunk_vertices must be >= 1, got {chunk_vertices}")
        self.lmap = lmap
        self.direction = np.asarray(direction_to_sun, dtype=np.float64)
        self.epoch_ns = int(epoch_ns)
        self.patches_per_step = patches_per_step
        self.lights = lmap.sun_lights(self.direction)
        V = lmap.num_vertices
        self._blocks = [slice(s, min(V, s + chunk_vertices)) for s in range(0, V, chunk_vertices)]
        self._direct = np.zeros(V)
        self._patch_direct = np.zeros(lmap.patches.count)
        self._solver: PatchRadiositySolver | None = None
        self._indirect_patch: NDArray[np.float64] | None = None
        self._phase = "direct"
        self._index = 0
        self.steps_done = 0

    @property
    def sun_visible(self) -> bool:
        return len(self.lights.directions) > 0

    @property
    def done(self) -> bool:
        return self._phase == "done"

    @staticmethod
    def estimate_steps(num_vertices: int, chunk_vertices: int, iterations: int, *, num_patches: int = 1,
                       patches_per_step: int | None = None) -> int:
        """Steps an update takes: a direct and an output step per vertex block, plus the transport iterations
        (``iterations``, or a typical 30 when iterating to convergence) times the row blocks per iteration."""
        blocks = 1 if patches_per_step is None else -(-num_patches // max(1, patches_per_step))
        return 2 * -(-num_vertices // chunk_vertices) + (iterations or 30) * blocks

    def step(self) -> SunChunk | None:
        """Do one bounded unit of work; returns a finished chunk during the output phase, else ``None``."""
        lmap = self.lmap
        self.steps_done += 1
        if self._phase == "direct":
            sl = self._blocks[self._index]
            if self.sun_visible:
                e = direct_irradiance(lmap.mesh, lmap.caster, self.lights, vertices=sl,
                                      offset_m=lmap.config.ray_offset_m, openings=lmap.openings,
                                      origins=lmap.ray_origins)
                self._direct[sl] = e
                self._patch_direct += lmap.patches.vertex_to_patch[:, sl] @ e
            self._index += 1
            if self._index == len(self._blocks):
                self._phase = "transport"
                self._solver = PatchRadiositySolver(lmap.transport, lmap.patches.reflectance, self._patch_direct,
                                                    iterations=lmap.config.iterations or None,
                                                    rows_per_step=self.patches_per_step)
            return None
        if self._phase == "transport":
            assert self._solver is not None
            if not self._solver.done:
                self._solver.step()
            if self._solver.done:
                self._indirect_patch = indirect_patch_irradiance(lmap.transport, self._solver.radiosity)
                self._phase, self._index = "output", 0
            return None
        if self._phase == "output":
            sl = self._blocks[self._index]
            assert self._indirect_patch is not None
            indirect = lmap.patches.patch_to_vertex[sl] @ self._indirect_patch
            b = lmap.mesh.reflectance[sl] * (self._direct[sl, None] + indirect)
            self._index += 1
            if self._index == len(self._blocks):
                self._phase = "done"
            return SunChunk(self.epoch_ns, sl.start, b.astype(np.float32))
        raise RuntimeError("SunUpdate.step() called after the update finished")

    def run(self) -> Iterator[SunChunk]:
        """All remaining steps; yields the output chunks."""
        while not self.done:
            chunk = self.step()
            if chunk is not None:
                yield chunk


def sun_radiosity(lmap: LightingMap, direction_to_sun: ArrayLike) -> NDArray[np.float32]:
    """B̂_sun (V, 3) in one go."""
    chunks = list(SunUpdate(lmap, direction_to_sun, chunk_vertices=max(1, lmap.num_vertices)).run())
    return np.concatenate([c.radiosity for c in chunks])


@dataclass(frozen=True)
class SunUpdateConfig(Config):
    """Parameters of ``sun_update_node``."""

    lighting_map: str = param("", description="Lighting map directory made by `lightfast daylight prepare`.",
                              read_only=True)
    site_file: str = param("", description="Site YAML overriding the lighting map's site; empty uses the map's.",
                           read_only=True)
    chunk_vertices: int = param(50_000, description="Vertices per update step: bounds the rays traced per step "
                                "(chunk_vertices x sun samples).", min=1, max=100_000_000)
    update_period_s: float = param(60.0, description="Start a new B̂_sun update this often, in seconds of ROS time "
                                   "(the sun moves 0.25° per minute).", min=0.0, max=86_400.0)
    patches_per_step: int = param(0, description="Patch rows of one Jacobi iteration of Eq. 2 per step (the "
                                  "paper's patches per frame); 0 = a whole iteration per step.", min=0,
                                  max=100_000_000)
    step_period_s: float = param(0.02, description="Period of the update steps in seconds: one bounded step per "
                                 "period (the paper does one chunk per frame).", min=0.001, max=60.0)
    direction_rate_hz: float = param(2.0, description="Rate of /sun/direction in Hz.", min=1.0, max=1000.0)
    frame_id: str = param("map", description="Frame of the published direction and radiosity chunks.")


class SunUpdatePipeline:
    """What ``sun_update_node`` runs, without ROS: the sun direction at any time, and the chunked B̂_sun updates.

    Call :meth:`step` once per step period with the current time. A new update starts when none is running and
    ``update_period_s`` has passed since the last one started; it is aimed at the sun position of the moment it
    will finish (now + estimated steps × step period, as in §III-E).
    """

    def __init__(self, lmap: LightingMap, config: SunUpdateConfig, *, site: Site | None = None) -> None:
        self.lmap = lmap
        _ = lmap.transport  # build it now (a loaded map builds it lazily), not inside the first bounded step
        _ = lmap.ray_origins
        self.config = config
        self.site = site or lmap.site
        self.current: SunUpdate | None = None
        self.last_start_ns: int | None = None
        self.epochs_started = 0

    def restart(self) -> None:
        """Time went back (a bag played again, a restarted simulation): drop the running update (its epoch lies in
        the old future); the next :meth:`step` starts one for the new time."""
        self.current = None
        self.last_start_ns = None

    def sun(self, now_ns: int) -> SunPosition:
        return sun_position(self.site, int(now_ns))

    def _due(self, now_ns: int) -> bool:
        if self.current is not None and not self.current.done:
            return False
        if self.last_start_ns is None:
            return True
        return now_ns - self.last_start_ns >= self.config.update_period_s * 1e9 or now_ns < self.last_start_ns

    def step(self, now_ns: int) -> SunChunk | None:
        """Advance the running update by one step (starting one if due); returns a finished chunk or ``None``."""
        if self._due(now_ns):
            pps = self.config.patches_per_step or None
            steps = SunUpdate.estimate_steps(self.lmap.num_vertices, self.config.chunk_vertices,
                                             self.lmap.config.iterations, num_patches=self.lmap.patches.count,
                                             patches_per_step=pps)
            finish_ns = int(now_ns + steps * self.config.step_period_s * 1e9)
            direction = self.sun(finish_ns).direction_map
            self.current = SunUpdate(self.lmap, direction, epoch_ns=finish_ns,
                                     chunk_vertices=self.config.chunk_vertices, patches_per_step=pps)
            self.last_start_ns = now_ns
            self.epochs_started += 1
            log.info("sun update %d for %.3f s ahead, direction %s", self.epochs_started,
                     (finish_ns - now_ns) * 1e-9, np.round(direction, 4))
        if self.current is None or self.current.done:
            return None
        return self.current.step()


class SunEpochAssembler:
    """Receiver side of the chunk stream (§III-E): collects the chunks of each epoch and hands out B̂_sun only
    when an epoch covers every vertex, so a consumer swaps in a new B̂_sun atomically and never renders a mix.

    Chunks of an older epoch than the newest one seen are dropped (:meth:`drop_reason` says why, for the log); a
    newer epoch replaces an unfinished one. After time went back (a bag played again), :meth:`restart` makes the
    next complete epoch count whatever its time.
    """

    def __init__(self, num_vertices: int) -> None:
        if num_vertices < 1:
            raise ValueError(f"num_vertices must be >= 1, got {num_vertices}")
        self.num_vertices = int(num_vertices)
        self._epoch_ns: int | None = None
        self._values = np.zeros((self.num_vertices, 3), dtype=np.float32)
        self._have = np.zeros(self.num_vertices, dtype=bool)
        self.completed_epoch_ns: int | None = None

    @property
    def pending_epoch_ns(self) -> int | None:
        return self._epoch_ns

    @property
    def progress(self) -> float:
        """Share of the vertices received for the pending epoch."""
        return float(np.count_nonzero(self._have)) / self.num_vertices

    def drop_reason(self, epoch_ns: int) -> str | None:
        """Why :meth:`add` would drop a chunk of ``epoch_ns`` (``None``: it would take it)."""
        if self.completed_epoch_ns is not None and epoch_ns < self.completed_epoch_ns:
            return f"older than the epoch in use ({self.completed_epoch_ns})"
        if self._epoch_ns is not None and epoch_ns < self._epoch_ns:
            return f"older than the epoch being received ({self._epoch_ns})"
        return None

    def restart(self) -> None:
        """Forget the epochs seen (time went back): the next epoch completed is handed out, however old."""
        self.completed_epoch_ns = None
        self._epoch_ns = None
        self._have[:] = False

    def add(self, epoch_ns: int, vertex_ids: ArrayLike, radiosity: ArrayLike) -> NDArray[np.float32] | None:
        """Add one chunk; returns the complete B̂_sun (V, 3) when this chunk completes its epoch, else ``None``.

        Raises ValueError for chunks that do not fit this map (vertex ids out of range, wrong shapes, non-finite
        or negative radiosity) — a stream from another lighting map."""
        ids = np.asarray(vertex_ids)
        rad = np.asarray(radiosity, dtype=np.float32)
        if ids.ndim != 1 or rad.shape != (len(ids), 3):
            raise ValueError(f"chunk needs (n,) vertex ids and (n, 3) radiosity, got {ids.shape} and {rad.shape}")
        if len(ids) and (ids.min() < 0 or ids.max() >= self.num_vertices):
            raise ValueError(f"chunk vertex ids span [{ids.min()}, {ids.max()}], outside this map's "
                             f"{self.num_vertices} vertices (a stream for another lighting map?)")
        if not np.all(np.isfinite(rad)) or np.any(rad < 0):
            raise ValueError("chunk radiosity must be finite and non-negative")
        epoch = int(epoch_ns)
        if self.completed_epoch_ns is not None and epoch <= self.completed_epoch_ns:
            return None  # late chunk of an epoch already swapped in (or older)
        if self._epoch_ns is None or epoch > self._epoch_ns:
            if self._epoch_ns is not None and self._have.any():
                log.warning("sun epoch %d superseded at %.0f%% by epoch %d", self._epoch_ns, 100 * self.progress,
                            epoch)
            self._epoch_ns = epoch
            self._have[:] = False
        elif epoch < self._epoch_ns:
            return None
        self._values[ids] = rad
        self._have[ids] = True
        if not self._have.all():
            return None
        self.completed_epoch_ns = epoch
        self._epoch_ns = None
        self._have[:] = False
        return self._values.copy()
