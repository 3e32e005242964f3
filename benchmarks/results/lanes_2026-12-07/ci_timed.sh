#!/usr/bin/env bash
set -uo pipefail
cd /work/fresh-clone
t0=$(date +%s)
echo "start $(date) $(git log --oneline | head -1)"
python3 -m venv .venv && .venv/bin/pip install -q ".[test]"; echo "install rc=$? $(( $(date +%s) - t0 )) s"
t1=$(date +%s); .venv/bin/python -m pytest -q 2>&1 | tail -15; echo "default rc=${PIPESTATUS[0]} $(( $(date +%s) - t1 )) s"
t2=$(date +%s); .venv/bin/python -m pytest -q -m "slow and not expensive" --no-loadscope-reorder 2>&1 | tail -15; echo "slow rc=${PIPESTATUS[0]} $(( $(date +%s) - t2 )) s"
t3=$(date +%s); .venv/bin/pip install -q ".[docs]" && NO_MKDOCS_2_WARNING=1 .venv/bin/mkdocs build --strict -q; echo "docs rc=$? $(( $(date +%s) - t3 )) s"
echo "total $(( $(date +%s) - t0 )) s"
