#!/usr/bin/env bash
# Fails when comments, help text or docs narrate history ("Issue 12's engine", "the earlier
# generator took ...", "before, every reference waited"): they describe the present, and history
# lives in git log and CHANGELOG.md. scripts/test.sh runs it before the build.
#
#   scripts/check_history.sh    list each offending line (file:line: text) and exit 1; else exit 0
#
# Code (*.cpp, *.h, *.py, *.sh, *.sbatch, .ci/run) is searched line by line; its identifiers never
# hold these phrases, so every hit is in a comment or a string. Docs (docs/*.md, README.md) get
# the before-stop hook's patterns too (sessions, issue numbers, a commit hash ending a line),
# outside code blocks and table rows. CHANGELOG.md is history by design and is not searched.
set -euo pipefail
cd "$(dirname "$0")/.."

# Phrases that tell what code or text used to be. Tight on purpose: "the previous checkpoint",
# "a previous run" and "no longer needed" describe the present and pass.
phrases=(
  '\bissues? #?[0-9]+'
  '\b(the|an?) (earlier|previous|former|old|older) (generator|loader|code|version|implementation|commit|release|behaviou?r|estimates?|design|approach|format|layout|sampler|screening|margins?|tolerances?)\b'
  '\bbefore this (change|issue|commit|session|patch|fix)\b'
  '\b(this|last|previous) session\b'
  '\b(was|were) previously\b'
  '\bpreviously (was|were|did|had|took|used)\b'
  '\bbefore, (every|each|all|the|it|they|we)\b'
  '\bas before\b'
  '\bused to (be|have)\b'
)
code_re=$(IFS='|' && echo "${phrases[*]}")
doc_re="$code_re"'|\b(first|second|third|fourth) session\b'

# The checkout's files: git's list where there is one (not build folders), else a walk.
list() {
  if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    git ls-files -- "$@"
  else
    local args=() p
    for p in "$@"; do args+=(-o -path "./$p"); done
    find . \( -path './build*' -o -path ./.git \) -prune -o \( -false "${args[@]}" \) -type f \
      -print | sed 's|^\./||'
  fi
}

# This script is left out: its comments quote what it looks for.
mapfile -t code < <(list '*.cpp' '*.h' '*.py' '*.sh' '*.sbatch' '.ci/run' |
  grep -v -x scripts/check_history.sh)
mapfile -t docs < <(list 'docs/*.md' README.md)
found=$(
  { ((${#code[@]})) && grep -H -n -i -E "$code_re" "${code[@]}"; } || true
  for f in "${docs[@]}"; do
    # The text outside ``` blocks and table rows (blank lines in their place, to keep the numbers).
    text=$(awk '/^[[:space:]]*```/ { fence = !fence; print ""; next }
                { print (fence || /^[[:space:]]*\|/) ? "" : $0 }' "$f")
    grep -n -i -E "$doc_re" <<<"$text" | sed "s|^|$f:|" || true
    # A commit hash ending a line: 7-40 hex digits, both a letter and a digit among them.
    awk -v f="$f" '{
        if (match($0, /[0-9a-fA-F]+\)?:? *$/)) {
          h = substr($0, RSTART, RLENGTH); sub(/\)?:? *$/, "", h)
          if (length(h) >= 7 && length(h) <= 40 && h ~ /[a-fA-F]/ && h ~ /[0-9]/ &&
              substr($0, RSTART - 1, 1) !~ /[0-9A-Za-z_]/) print f ":" NR ":" $0
        }
      }' <<<"$text"
  done
)
if [[ -n "$found" ]]; then
  echo "check_history: these lines narrate history; say what is true now (history goes to git log):"
  echo "$found" | cut -c1-200 | sed 's/^/  /'
  exit 1
fi
