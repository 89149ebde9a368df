#!/usr/bin/env bash
# Makes the virtual environment of alfd's Python adapter on first use and prints its python.
#
#   bash deploy/python/setup-venv.sh      # prints /path/to/.venv/bin/python
#
# The environment is $ALFD_VENV (default: .venv at the repository's root), made with python3.11
# or python3 (3.10 or later; $ALFD_BOOTSTRAP_PYTHON chooses another), with the pinned
# deploy/python/requirements.txt from PyPI. It is made again when requirements.txt changes.
# The alfd processes call this script themselves: nobody has to run it by hand.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
venv="${ALFD_VENV:-$root/.venv}"
requirements="$here/requirements.txt"
want="$(sha256sum "$requirements" | cut -d' ' -f1)"
stamp="$venv/.alfd-requirements.sha256"

up_to_date() { [[ -x "$venv/bin/python" && -f "$stamp" && "$(cat "$stamp")" == "$want" ]]; }

if ! up_to_date; then
    mkdir -p "$(dirname "$venv")"
    # One installer at a time (several actors may start at once).
    exec 9>"$venv.lock"
    flock 9
    if ! up_to_date; then
        python="${ALFD_BOOTSTRAP_PYTHON:-}"
        if [[ -z "$python" ]]; then
            for candidate in python3.11 python3.12 python3.13 python3.10 python3; do
                if command -v "$candidate" >/dev/null &&
                    "$candidate" -c 'import sys; sys.exit(sys.version_info < (3, 10))'; then
                    python="$candidate"
                    break
                fi
            done
        fi
        if [[ -z "$python" ]]; then
            echo "setup-venv.sh: alfd's Gymnasium environments and Python experts need Python 3.10 or later (python3.11 recommended); none found (set ALFD_BOOTSTRAP_PYTHON)" >&2
            exit 2
        fi
        echo "setup-venv.sh: installing alfd's Python adapter into $venv (once)" >&2
        [[ -x "$venv/bin/python" ]] || "$python" -m venv "$venv"
        "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps -r "$requirements" >&2
        "$venv/bin/python" -c 'import iceoryx2, gymnasium, numpy, minari, pyarrow' >&2
        echo "$want" >"$stamp"
    fi
fi
echo "$venv/bin/python"
