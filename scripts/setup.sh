#!/usr/bin/env bash
# Create or refresh .venv with trackvkf.
#   bash scripts/setup.sh         the runtime only (pip install -e .): what the demo and the service need
#   bash scripts/setup.sh --dev   also the test and lint tools (pip install -e '.[dev]')
# System libraries (Debian, apt-get, as root, only when missing): Pango and a font for WeasyPrint
# (the planning report's PDF); with --dev also poppler-utils (the tests read the PDF back).
# Without root or apt-get a missing one stops --dev with the packages named (the runtime warns).
# Idempotent: re-installs only when pyproject.toml changed, the package is missing, or
# --dev is asked of a runtime-only environment. Set PYTHON=/path/to/python3.11 to choose
# the interpreter.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

want_kind=runtime
for arg in "$@"; do
  case "$arg" in
    --dev) want_kind=dev ;;
    *) echo "usage: bash scripts/setup.sh [--dev]" >&2; exit 2 ;;
  esac
done

# --- system libraries ------------------------------------------------------------------------------
have_lib() {  # have_lib SONAME: the dynamic linker knows it
  local ldconfig
  ldconfig="$(command -v ldconfig || echo /sbin/ldconfig)"
  "$ldconfig" -p 2>/dev/null | grep -q "^[[:space:]]*$1 "
}
missing_pkgs=()
have_lib libpango-1.0.so.0 || missing_pkgs+=(libpango-1.0-0)
have_lib libpangoft2-1.0.so.0 || missing_pkgs+=(libpangoft2-1.0-0)
# WeasyPrint ≥ 70 subsets the fonts it embeds with HarfBuzz and warns without it (an error in the tests)
have_lib libharfbuzz-subset.so.0 || missing_pkgs+=(libharfbuzz-subset0)
have_lib libfontconfig.so.1 || missing_pkgs+=(libfontconfig1)
[[ -e /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ]] || fc-list 2>/dev/null | grep -q . || missing_pkgs+=(fonts-dejavu-core)
if [[ "$want_kind" == dev ]]; then
  for tool in pdftotext pdftoppm pdfinfo; do
    command -v "$tool" >/dev/null 2>&1 || { missing_pkgs+=(poppler-utils); break; }
  done
fi
if (( ${#missing_pkgs[@]} )); then
  if command -v apt-get >/dev/null 2>&1 && [[ "$(id -u)" == 0 ]]; then
    echo "setup: installing Debian packages ${missing_pkgs[*]} (the planning report's PDF) ..."
    if ! { DEBIAN_FRONTEND=noninteractive apt-get update -qq \
           && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing_pkgs[@]}"; } \
         >/tmp/trackvkf-apt.log 2>&1; then
      tail -n 20 /tmp/trackvkf-apt.log >&2
      echo "error: apt-get install ${missing_pkgs[*]} failed (log: /tmp/trackvkf-apt.log)" >&2
      exit 1
    fi
  else
    msg="the planning report (WeasyPrint) and its tests need the Debian packages ${missing_pkgs[*]}: install them as root (apt-get install ${missing_pkgs[*]}) or the equivalent Pango/poppler packages of your system"
    if [[ "$want_kind" == dev ]]; then echo "error: $msg" >&2; exit 1; fi
    echo "warning: $msg; until then GET /condition/report.pdf answers 503" >&2
  fi
fi

# --- the virtual environment -------------------------------------------------------------------------
py="${PYTHON:-}"
if [[ -z "$py" ]]; then
  for candidate in python3.11 python3 python; do
    if command -v "$candidate" >/dev/null 2>&1 \
      && "$candidate" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
      py="$candidate"
      break
    fi
  done
fi
if [[ -z "$py" ]]; then
  echo "error: Python >= 3.11 not found; set PYTHON=/path/to/python3.11" >&2
  exit 1
fi

if [[ ! -x .venv/bin/python ]]; then
  echo "setup: creating .venv with $("$py" --version 2>&1)"
  "$py" -m venv .venv
fi

# the stamp holds the hash of pyproject.toml and what was installed: "<sha256> runtime|dev"
stamp=.venv/.trackvkf-install-stamp
hash="$(.venv/bin/python -c 'import hashlib; print(hashlib.sha256(open("pyproject.toml", "rb").read()).hexdigest())')"
have_hash="" have_kind=""
if [[ -f "$stamp" ]]; then read -r have_hash have_kind <"$stamp" || true; fi
if [[ -n "$have_hash" && -z "$have_kind" ]]; then
  have_kind=dev  # stamps written before the split held the hash alone (a dev install)
fi
up_to_date=false
if [[ "$have_hash" == "$hash" ]] && { [[ "$have_kind" == dev ]] || [[ "$want_kind" == runtime ]]; } \
  && .venv/bin/python -c 'import importlib.metadata as m; m.version("trackvkf")' >/dev/null 2>&1; then
  up_to_date=true
fi
if [[ "$up_to_date" != true ]]; then
  # an environment that had the dev tools keeps them (a refresh installs them again)
  if [[ "$have_kind" == dev ]]; then want_kind=dev; fi
  if [[ "$want_kind" == dev ]]; then target='.[dev]'; else target='.'; fi
  echo "setup: installing trackvkf ($want_kind: pip install -e '$target') into .venv ..."
  # byte code: where Python writes it (PYTHONDONTWRITEBYTECODE unset) each module is compiled when first
  # imported, so pip need not compile every module of every package (40 of its 110 s on a fresh .venv)
  compile=()
  if [[ -z "${PYTHONDONTWRITEBYTECODE:-}" ]]; then compile=(--no-compile); fi
  if ! .venv/bin/python -m pip install --disable-pip-version-check ${compile[@]+"${compile[@]}"} -e "$target" \
    >.venv/pip-install.log 2>&1; then
    tail -n 40 .venv/pip-install.log >&2
    echo "error: pip install failed (full log: .venv/pip-install.log)" >&2
    exit 1
  fi
  echo "$hash $want_kind" >"$stamp"
fi

# --- byte code of the project's own modules ----------------------------------------------------------
# Every service, worker and CLI process imports most of the ~340 modules of app/ and worker/: compiled
# here once (only what changed since; ~0.4 s when nothing did), they are not compiled again by each process,
# also where PYTHONDONTWRITEBYTECODE keeps Python from writing them (2 s CPU saved per process).
.venv/bin/python -m compileall -q -j 0 app worker migrations >/dev/null \
  || echo "setup: note: app/, worker/ or migrations/ not byte-compiled (read-only?); each process compiles them" >&2
