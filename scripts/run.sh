#!/usr/bin/env bash
# Set-up, build and the main job. This is the README's run command: the work site (MuJoCo world,
# camera, recognizer) and the operator site (world model, simulator, planner, browser UI) in one
# process, linked over loopback; it prints the URL to open. Extra arguments go to `teachsim up`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh release
exec build/src/app/teachsim up --scene scenes/puzzle.json "$@"
