#!/usr/bin/env bash
# The learned pose stage's GPU check (issue 19's GPU frame rate), as run on a lent H100 in session 17.
#
#   bash benchmarks/device_pose.sh prepare   # here: .gpu/ (a scene of the real sample, the graph's dense run)
#                                            # and .whl/ (pydantic's wheels for the GPU machine's Python 3.12)
#   bash benchmarks/device_pose.sh run       # there (the device tool, carry .gpu and .whl): figures to $OUT
#
# `prepare` copies scene 000000 of ../shared/data/ycbv_sample (models + 20 frames, about 38 MB) and
# runs/<profile>/pose_ycbv_dense/model.pt into .gpu/ and lists both folders in .git/info/exclude, so they
# travel only when carried. `run` installs the wheels into /tmp/site and writes one result file per command
# of benchmarks/pose.py (end to end with an untrained Mask R-CNN of the cpu and paper profiles, the same on
# the machine's CPU cores, untrained paper-profile networks) into $OUT (default results/device). DEVICE=cpu
# runs the same commands on the CPU (a check of the script itself, with 2 frames).
set -euo pipefail
cd "$(dirname "$0")/.."
profile="${PROFILE:-cpu}"
case "${1:-}" in
  prepare)
    sample="${YCBV_SAMPLE:-../shared/data/ycbv_sample}"
    run="runs/$profile/pose_ycbv_dense"
    [ -f "$run/model.pt" ] || { echo "device_pose.sh: $run/model.pt missing (make runs/$profile/pose_ycbv_dense/model.pt)" >&2; exit 2; }
    [ -d "$sample/train_real/000000" ] || { echo "device_pose.sh: $sample/train_real/000000 missing" >&2; exit 2; }
    mkdir -p .git/info
    for d in /.gpu/ /.whl/; do grep -qxF "$d" .git/info/exclude 2>/dev/null || echo "$d" >> .git/info/exclude; done
    # .gpu/ is this script's own (its marker file); a .gpu/ it did not make is left alone
    if [ -e .gpu ] && [ ! -f .gpu/.made-by-device_pose ]; then
      echo "device_pose.sh: .gpu exists and was not made by this script (no .gpu/.made-by-device_pose); move it away" >&2
      exit 2
    fi
    rm -rf .gpu && mkdir -p .gpu/ycbv_sample/train_real .gpu/runs/pose_ycbv_dense
    echo "made by benchmarks/device_pose.sh prepare; removed and remade by it" > .gpu/.made-by-device_pose
    cp -r "$sample/models" "$sample/README.md" .gpu/ycbv_sample/
    cp -r "$sample/train_real/000000" .gpu/ycbv_sample/train_real/
    cp "$run"/{model.pt,config.json,run.json} .gpu/runs/pose_ycbv_dense/
    mkdir -p .whl
    pip_py=""  # a Python with pip (the project's uv environment has none)
    for py in python3 /usr/bin/python3 /usr/local/bin/python3; do
      if "$py" -m pip --version >/dev/null 2>&1; then pip_py="$py"; break; fi
    done
    [ -n "$pip_py" ] || { echo "device_pose.sh: no Python with pip to download the wheels" >&2; exit 2; }
    "$pip_py" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
      --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d .whl \
      pydantic==2.14.3 pydantic-core==2.50.4 annotated-types==0.8.0 typing-inspection==0.4.5 typing-extensions==4.16.0
    du -sh .gpu .whl
    ;;
  run)
    out="${OUT:-results/device}"
    mkdir -p "$out"
    dev="${DEVICE:-cuda}"
    frames=19; [ "$dev" = cpu ] && frames=2
    if [ "$dev" = cuda ]; then
      python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
      export PYTHONPATH=/tmp/site
      nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
    fi
    export PYTHONUNBUFFERED=1
    d=".gpu/ycbv_sample@train_real"; p=".gpu/runs/pose_ycbv_dense"
    bench() { echo "=== $*"; timeout 300 python3 benchmarks/pose.py "$@" --results-dir "$out"; }
    bench --pose $p --data $d --seg-profile cpu --device "$dev" --frames $frames --steps 20 \
      --result-name "pose_${profile}_dense_local_ycbv_sample_$dev"
    bench --pose $p --data $d --seg-profile paper --device "$dev" --frames $frames --steps 5 \
      --result-name "pose_${profile}_dense_local_ycbv_sample_segpaper_$dev"
    [ "$dev" = cuda ] && bench --pose $p --data $d --seg-profile cpu --device cpu --frames 10 --steps 3 \
      --result-name "pose_${profile}_dense_local_ycbv_sample_cpu16"
    bench --profile paper --head dense --appearance local --device "$dev" --frames $frames --steps 20 \
      --result-name "pose_paper_dense_local_$dev"
    ;;
  *)
    echo "usage: bash benchmarks/device_pose.sh prepare|run" >&2; exit 2 ;;
esac
