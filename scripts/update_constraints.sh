#!/usr/bin/env bash
# Regenerate constraints.txt: the exact versions the test suite last passed with.
# pyproject.toml keeps only lower bounds; pins live here, not by hand.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
tmp=$(mktemp -d)
python3 -m venv "$tmp/venv"
"$tmp/venv/bin/pip" install -q "$root[test]"
{ echo "# Tested versions (constraints, not requirements): regenerate with scripts/update_constraints.sh"
  "$tmp/venv/bin/pip" freeze | grep -v '^imucal'; } > "$root/constraints.txt"
rm -rf "$tmp"
echo "wrote $root/constraints.txt"
