#!/usr/bin/env bash
# Set-up, build and the main job. This is the README's run command.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh release
# Until the operator site exists (teachsim up), the main job is the demonstrations.
exec build/src/app/teachsim demo all --out demo-out "$@"
