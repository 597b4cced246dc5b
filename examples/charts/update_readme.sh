#!/bin/sh
# Replaces the lines between the markers <!-- charts:begin --> and <!-- charts:end -->
# of a README (`make charts` passes examples/charts/README.md) with the given generated
# Markdown files (the numbers of `make charts`).
# usage: update_readme.sh README.md ratios.md table_sweeps.md table_long.md table_stability.md
set -eu
readme=$1
shift
tmp=$(mktemp)
gen=$(mktemp)
{
  echo "Speed ratios (\`build/examples/bench_ratios\`, one run):"
  echo
  cat "$1"
  shift
  for f in "$@"; do
    echo
    cat "$f"
  done
} > "$gen"
grep -q '^<!-- charts:begin -->$' "$readme" && grep -q '^<!-- charts:end -->$' "$readme" || {
  echo "update_readme.sh: markers not found in $readme" >&2
  exit 2
}
awk -v gen="$gen" '
  /^<!-- charts:begin -->$/ { print; while ((getline line < gen) > 0) print line; skip = 1; next }
  /^<!-- charts:end -->$/ { skip = 0 }
  !skip { print }
' "$readme" > "$tmp"
cat "$tmp" > "$readme"
rm -f "$tmp"
rm -f "$gen"
