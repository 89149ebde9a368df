# Sourced by the benchmark scripts: `bench_venv SCRIPT VENV REQUIREMENTS IMPORTS` makes the
# virtual environment VENV with Python 3.11 ($ALFD_BENCH_PYTHON, else python3.11 or python3) and
# installs REQUIREMENTS (pinned, `pip install --no-deps`) once, again only when the file changes;
# IMPORTS is the Python import line that must then work. Exits with 2 without Python 3.11.
bench_venv() {
    local script="$1" venv="$2" requirements="$3" imports="$4"
    local python="${ALFD_BENCH_PYTHON:-}"
    if [[ -z "$python" ]]; then
        for candidate in python3.11 python3; do
            if command -v "$candidate" >/dev/null &&
                "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
                python="$candidate"
                break
            fi
        done
    fi
    if [[ -z "$python" ]]; then
        echo "$script: needs Python 3.11 (the pinned wheels are for CPython 3.11); set ALFD_BENCH_PYTHON" >&2
        exit 2
    fi
    local stamp="$venv/.requirements.sha256"
    local want
    want="$(sha256sum "$requirements" | cut -d' ' -f1)"
    if [[ ! -x "$venv/bin/python" || ! -f "$stamp" || "$(cat "$stamp")" != "$want" ]]; then
        echo "$script: installing $requirements into $venv (once)" >&2
        [[ -x "$venv/bin/python" ]] || "$python" -m venv "$venv"
        "$venv/bin/python" -m pip install --quiet --no-deps -r "$requirements"
        "$venv/bin/python" -c "$imports"
        echo "$want" >"$stamp"
    fi
}
