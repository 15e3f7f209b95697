#!/usr/bin/env bash
# Creates (or refreshes) the project's virtual environment in .venv and installs ftc-hw into it.
# Re-runs pip only when pyproject.toml changed since the last successful install.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
py="${FTC_PYTHON:-}"
if [ -z "$py" ]; then
  for cand in python3.13 python3.12 python3.11 python3; do
    if command -v "$cand" >/dev/null 2>&1 && "$cand" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
      py="$cand"; break
    fi
  done
fi
[ -n "$py" ] || { echo "ftc-hw needs Python >= 3.11 on PATH (or set FTC_PYTHON)" >&2; exit 1; }
if [ ! -x "$venv/bin/python" ]; then
  echo "[bootstrap] creating $venv with $py" >&2
  "$py" -m venv "$venv"
fi
stamp="$venv/.ftc-installed"
want="$(cat "$root/pyproject.toml" | sha256sum | cut -d' ' -f1)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "[bootstrap] installing ftc-hw and its dependencies into .venv" >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --upgrade pip >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -e "$root[test]" >&2
  echo "$want" > "$stamp"
fi
