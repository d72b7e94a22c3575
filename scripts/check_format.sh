#!/usr/bin/env bash
# Checks that every C++ file git tracks is formatted with the repository's .clang-format.
# Usage: scripts/check_format.sh [RESULTS_DIR]
# Prints the files that differ (with `clang-format --dry-run` diagnostics for the first lines) and
# exits 1 when any does; with RESULTS_DIR, also writes RESULTS_DIR/format.xml (JUnit, one case)
# so that CI counts it with the other tests. Fix with: clang-format -i FILE...
set -uo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
results=${1:-}
fmt=$(command -v clang-format || command -v clang-format-14) || {
  echo "check_format: clang-format is not installed (apt-get install clang-format)" >&2
  exit 2
}
cd "$repo" || exit 2
bad=()
while IFS= read -r f; do
  "$fmt" --style=file "$f" | cmp -s - "$f" || bad+=("$f")
done < <(git ls-files '*.cpp' '*.hpp' '*.h' '*.cc')
if [ -n "$results" ]; then
  mkdir -p "$results"
  {
    echo '<?xml version="1.0" encoding="UTF-8"?>'
    echo "<testsuite name=\"format\" tests=\"1\" failures=\"$((${#bad[@]} > 0))\">"
    echo '  <testcase classname="format" name="EveryCppFileMatchesClangFormat">'
    if ((${#bad[@]})); then
      echo "    <failure message=\"${#bad[@]} file(s) differ from .clang-format\">${bad[*]}</failure>"
    fi
    echo '  </testcase>'
    echo '</testsuite>'
  } > "$results/format.xml"
fi
if ((${#bad[@]})); then
  echo "check_format: ${#bad[@]} file(s) differ from .clang-format (clang-format -i to fix):" >&2
  printf '  %s\n' "${bad[@]}" >&2
  "$fmt" --style=file --dry-run "${bad[0]}" 2>&1 | head -20 >&2
  exit 1
fi
echo "check_format: all C++ files match .clang-format"
