"""Allocate a ROS domain id that no other process on this machine holds, for isolating test runs.

Two processes on the same ``ROS_DOMAIN_ID`` see each other's topics, even with discovery limited to localhost.
:func:`reserve_domain_id` takes an exclusive ``flock`` on ``<lock_dir>/domain-<id>.lock`` for an id in
``[first, last]``; the lock lives as long as the returned :class:`DomainLease` (or the process), so concurrent test
runs always get distinct ids. Fast DDS accepts ids up to 232 with its default port mapping, but ids from 102 on map
to UDP ports inside Linux's ephemeral range (32768–60999), where any socket may already hold them, or (215–232) leave
room for few participants; ids are therefore handed out from ROS 2's safe range 1–101 ("About Domain ID",
docs.ros.org), as ROS's own ``domain_coordinator`` does.
"""
from __future__ import annotations

import fcntl
import os
import random
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from lightfast.ros.errors import DomainExhaustedError

MAX_DOMAIN_ID = 232
#: The highest id whose ports stay below Linux's ephemeral range (ROS 2 docs: "choose a domain ID between 0 and 101").
MAX_SAFE_DOMAIN_ID = 101


@dataclass
class DomainLease:
    """An exclusively held domain id; :meth:`release` (or process exit) gives it back."""

    domain_id: int
    _fd: int | None = field(default=None, repr=False)

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing drops the flock
            self._fd = None

    def __enter__(self) -> DomainLease:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def default_lock_dir() -> Path:
    return Path(tempfile.gettempdir()) / "lightfast-ros-domains"


def reserve_domain_id(*, first: int = 1, last: int = MAX_SAFE_DOMAIN_ID, lock_dir: Path | None = None) -> DomainLease:
    """Reserve a free domain id in ``[first, last]``, trying them in random order."""
    if not 0 <= first <= last <= MAX_DOMAIN_ID:
        raise ValueError(f"domain range must satisfy 0 <= first <= last <= {MAX_DOMAIN_ID}, got [{first}, {last}]")
    lock_dir = lock_dir or default_lock_dir()
    lock_dir.mkdir(parents=True, exist_ok=True)
    candidates = list(range(first, last + 1))
    random.SystemRandom().shuffle(candidates)
    for domain_id in candidates:
        fd = os.open(lock_dir / f"domain-{domain_id}.lock", os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            continue
        return DomainLease(domain_id, fd)
    raise DomainExhaustedError(f"all ROS domain ids {first}..{last} are held by other processes ({lock_dir})")
