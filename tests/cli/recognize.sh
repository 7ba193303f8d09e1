#!/bin/sh
# `teachsim recognize` as a user runs it (issue 7, item 7): a dev-set image (../shared/data/vision-dev,
# case_009) with its camera and the dev set's models; RESULT.json and the overlay written; bad input
# answered with exit status 2 and a message naming the file, nothing half-written.
# usage: recognize.sh TEACHSIM SHARED_DIR WORK_DIR
set -u
teachsim=$1 shared=$2 work=$3
here=$(cd "$(dirname "$0")" && pwd)
image=$shared/data/vision-dev/case_009.png
fail() { echo "FAIL: $*"; exit 1; }
[ -f "$image" ] || { echo "SKIPPED: $image not found"; exit 77; }
rm -rf "$work" && mkdir -p "$work" || fail "cannot make $work"

run() {  # run EXPECTED_STATUS ARGS...: the command's output in $work/out.txt
  expected=$1; shift
  "$teachsim" recognize --image "$image" --camera "$here/case_009_camera.json" --models "$here/dev_models.json" \
    --cache "$work/cache" "$@" > "$work/out.txt" 2>&1
  status=$?
  [ "$status" -eq "$expected" ] || { cat "$work/out.txt"; fail "exit status $status, expected $expected ($*)"; }
}

# 1. Recognized, written: RESULT.json with its objects, the overlay a PNG.
run 0 --out "$work/result.json" --overlay "$work/overlay.png"
grep -q '"objects"' "$work/result.json" || fail "result.json has no objects list"
grep -q '"model": *"cube45"' "$work/result.json" || fail "the cube in the frame was not recognized"
[ "$(head -c 8 "$work/overlay.png" | od -An -c | tr -d ' \n')" = '211PNG\r\n032\n' ] || fail "overlay.png is not a PNG"
grep -q 'objects;' "$work/out.txt" || fail "no summary line"

# 2. The overlay into a folder that does not exist: status 2, the folder named; RESULT.json, asked
#    for too, written whole (it is written first), and no temporary file left behind.
run 2 --out "$work/result2.json" --overlay "$work/missing/overlay.png"
grep -q "$work/missing" "$work/out.txt" || fail "the overlay's folder is not named: $(cat "$work/out.txt")"
grep -q '"timing_ms"' "$work/result2.json" || fail "result2.json is not whole"
[ -z "$(ls -A "$work" | grep -v -e '^cache$' -e '\.json$' -e '\.png$' -e '^out\.txt$')" ] || fail "stray files: $(ls -A "$work")"

# 3. A malformed camera file: status 2, the file named; nothing written.
printf '{"width": 640, "height": 480, "fx": "wide"' > "$work/bad_camera.json"
"$teachsim" recognize --image "$image" --camera "$work/bad_camera.json" --models "$here/dev_models.json" \
  --out "$work/bad.json" --overlay "$work/bad.png" > "$work/out.txt" 2>&1
[ $? -eq 2 ] || fail "a malformed camera did not give status 2"
grep -q "bad_camera.json" "$work/out.txt" || fail "the malformed camera is not named: $(cat "$work/out.txt")"
[ ! -e "$work/bad.json" ] && [ ! -e "$work/bad.png" ] || fail "output written after bad input"

echo "recognize: 3 cases passed"
