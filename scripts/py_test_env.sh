#!/usr/bin/env bash
# The Python clients the tests check dualgeo's outputs with (issue #14): pymavlink (the
# MAVLink reference implementation's Python side) and mcap (Foxglove's reader), from
# PyPI, in a venv of the project's own: target/pyenv. Idempotent; prints the venv's
# python on success. Called by scripts/setup.sh and by the tests themselves.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=target/pyenv
want=(pymavlink==2.4.49 mcap==1.3.0)
if ! [ -x "$venv/bin/python" ]; then
  mkdir -p target
  python3 -m venv "$venv"
fi
if ! "$venv/bin/python" -c 'import pymavlink, mcap' >/dev/null 2>&1; then
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "${want[@]}" >&2
fi
echo "$PWD/$venv/bin/python"
