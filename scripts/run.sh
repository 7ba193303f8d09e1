#!/usr/bin/env bash
# Set-up, build and the main job. This is the README's run command.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh release
exec build/src/app/teachsim inspect --scene scenes/puzzle.json "$@"
