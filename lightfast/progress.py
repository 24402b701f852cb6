"""Progress bars for slow steps. The library shows none unless the caller (a CLI) asks for them."""
from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")


def track(iterable: Iterable[T], *, desc: str, total: int | None = None, enabled: bool = False,
          unit: str = "it") -> Iterator[T]:
    """Iterate ``iterable`` with a tqdm bar on stderr when ``enabled``."""
    if not enabled:
        yield from iterable
        return
    yield from tqdm(iterable, desc=desc, total=total, unit=unit, file=sys.stderr, dynamic_ncols=True, leave=False)
