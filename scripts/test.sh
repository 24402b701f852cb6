#!/usr/bin/env bash
# Set up lightfast if needed (scripts/setup.sh), then the gates: ruff (lint), mypy (types, mypy.ini), the node
# parameter files current (`lightfast config write --check`), and the test suite. Extra arguments go to pytest, e.g.
# `bash scripts/test.sh test/unit -x`.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$root/scripts/setup.sh"
cd "$root"
echo "lightfast test: ruff" >&2
"$root/.venv/bin/ruff" check --quiet "$root"
echo "lightfast test: mypy" >&2
"$root/.venv/bin/mypy" --config-file "$root/mypy.ini"
echo "lightfast test: config/*.yaml current" >&2
"$root/.venv/bin/lightfast" config write --check
exec "$root/.venv/bin/python" -m pytest "$@"
