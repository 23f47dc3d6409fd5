#!/usr/bin/env bash
# The lint gate, as tests/test_tooling.py runs it: ruff over src, tests and benchmarks
# (rules in pyproject.toml [tool.ruff]), then mypy over the package's public faces.
#   bash tools/lint.sh         check only (what CI asserts)
#   bash tools/lint.sh --fix   apply ruff's safe autofixes first (import order, docstring
#                              closing quotes, quoted annotations...), then check
# Run --fix once after a wave of merges, not on a branch others are editing beside you.
set -euo pipefail
cd "$(dirname "$0")/.."
PATHS=(src tests benchmarks tools docs)
if [ "${1:-}" = "--fix" ]; then
  ruff check --fix "${PATHS[@]}" || true
fi
ruff check "${PATHS[@]}"
mypy
