#!/usr/bin/env bash
# The tree speaks of the product only: fails when a tracked file speaks of how it was developed
# (work sessions, coordinators, work trees, issue numbers). Run by scripts/test.sh.
#   scripts/check_words.sh        prints each offending line and exits 1, or exits 0
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
pattern='session|coordinator|issue [0-9]|issue #[0-9]|wt-'
# pytest's fixture scope is the one product use of the word; it is matched exactly.
allowed='scope="session"'
hits="$(git ls-files -z -- . ':!:scripts/check_words.sh' \
        | xargs -0 grep -n -I -i -E "$pattern" -- 2>/dev/null \
        | grep -v -F "$allowed" || true)"
if [ -n "$hits" ]; then
  echo "check_words: these lines speak of the development process, not the product:" >&2
  echo "$hits" >&2
  exit 1
fi
echo "check_words: ok"
