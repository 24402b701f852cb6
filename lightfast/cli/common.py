"""What the command groups share: exit codes, the error mapping of :func:`run`, signal handling, option types."""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from lightfast.errors import LightfastError

EXIT_ERROR, EXIT_USAGE, EXIT_INTERNAL, EXIT_DIFFERENT, EXIT_INTERRUPTED = 1, 2, 3, 4, 130
EXIT_CORRUPT = 5  # bag play skipped corrupt chunks (without --skip-corrupt), bag info --check found some

#: A subcommand: parsed arguments in, exit code out.
Command = Callable[[argparse.Namespace], int]


@contextmanager
def stop_on_signals() -> Iterator[threading.Event]:
    """An event set by SIGINT or SIGTERM while the block runs (previous handlers restored after)."""
    stop = threading.Event()
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}

    def handler(signum: int, _frame: object) -> None:
        if stop.is_set() and signum == signal.SIGINT:
            raise KeyboardInterrupt  # a second Ctrl-C aborts
        stop.set()

    for s in previous:
        signal.signal(s, handler)
    try:
        yield stop
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def run(func: Command, args: argparse.Namespace) -> int:
    """Run a subcommand, mapping errors to one line on stderr and an exit code."""
    debug = bool(os.environ.get("LIGHTFAST_DEBUG"))
    try:
        return int(func(args))
    except (LightfastError, OSError) as exc:  # bad input, missing or unreadable files
        if debug:
            raise
        print(f"lightfast: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("lightfast: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:
        if debug:
            raise
        print(f"lightfast: internal error: {type(exc).__name__}: {exc} (set LIGHTFAST_DEBUG=1 for the traceback)",
              file=sys.stderr)
        return EXIT_INTERNAL


def image_size(example: str) -> Callable[[str], tuple[int, int]]:
    """An argparse type for ``WIDTHxHEIGHT``; ``example`` is shown when the text is malformed."""

    def parse(text: str) -> tuple[int, int]:
        try:
            w, h = text.lower().split("x")
            return int(w), int(h)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. {example}, got {text!r}") from None

    return parse
