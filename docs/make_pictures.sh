#!/usr/bin/env bash
# Regenerate the pictures of docs/taxonomy.md with the project's own `stori-jax show`.
set -euo pipefail
cd "$(dirname "$0")/.."
STORI=${STORI:-.venv/bin/stori-jax}
mkdir -p docs/img
"$STORI" list | awk '/^  (Breakout|Boxing|Gopher|BankHeist) /{print $1, $2}' | while read -r game preset; do
  "$STORI" show "$game" "$preset" --steps 700 --out "docs/img/$game-$preset.png"
done
