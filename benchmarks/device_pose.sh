#!/usr/bin/env bash
# The learned pose stage's GPU check (issue 19's GPU frame rate), as run on a lent H100 in session 17 and on a
# lent H200 in session 31.
#
#   bash benchmarks/device_pose.sh prepare   # here: .gpu/ (a scene of the real sample, the graph's dense run)
#                                            # and .whl/ (pydantic's wheels for the GPU machine's Python 3.12)
#   bash benchmarks/device_pose.sh run       # there (the device tool, carry .gpu and .whl): figures to $OUT
#
# `prepare` copies scene 000000 of ../shared/data/ycbv_sample (models + 20 frames, about 38 MB) and
# runs/<profile>/pose_ycbv_dense/model.pt into .gpu/ and lists both folders in .git/info/exclude, so they
# travel only when carried. `run` installs the wheels into /tmp/site and writes one result file per command
# of benchmarks/pose.py (end to end with an untrained Mask R-CNN of the cpu profile, the same with the pose
# networks in half precision, with 4 CPU threads, with the MobileNetV3 backbone, with the paper
# profile's Mask R-CNN, the same on the machine's CPU cores, untrained paper-profile networks) and a cProfile of
# the pose stage into $OUT (default results/device). The colour-named slides are built here (Open3D) into
# .gpu/slides.npz and read there (--slides). DEVICE=cpu runs the commands here (a check of the script, 2 frames).
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
    # the colour-named slides are model-side data built with Open3D's voxel grid, which the GPU machine lacks:
    # built here and carried, so that it runs the same poses
    "${PYTHON:-.venv/bin/python}" benchmarks/pose.py --pose .gpu/runs/pose_ycbv_dense --data .gpu/ycbv_sample@train_real \
      --frames 19 --save-slides .gpu/slides.npz
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
    d=".gpu/ycbv_sample@train_real"; p=".gpu/runs/pose_ycbv_dense"; sl="--slides .gpu/slides.npz"
    reps=3; [ "$dev" = cpu ] && reps=1  # the median of 3 passes: a fresh machine's first pass runs slower
    bench() { echo "=== $*"; timeout 300 python3 benchmarks/pose.py "$@" --results-dir "$out"; }
    bench --pose $p --data $d $sl --seg-profile cpu --device "$dev" --frames $frames --repeats $reps --steps 20 \
      --result-name "pose_${profile}_dense_local_ycbv_sample_$dev"
    if [ "$dev" = cuda ]; then
      # the dense head in half precision (autocast; its default on a GPU until session 31, now float32), and
      # torch's CPU threads capped at 4 (faster than the default 16 in one call of session 31, slower in the next:
      # a probe of the machine's run-to-run spread, not a setting)
      bench --pose $p --data $d $sl --seg-profile cpu --device "$dev" --frames $frames --repeats $reps --steps 5 \
        --amp --result-name "pose_${profile}_dense_local_ycbv_sample_amp_$dev"
      bench --pose $p --data $d $sl --seg-profile cpu --device "$dev" --frames $frames --repeats $reps --steps 5 \
        --threads 4 --result-name "pose_${profile}_dense_local_ycbv_sample_thr4_$dev"
    fi
    # the cpu graph's real-time segmenter's backbone (MobileNetV3-Large, SEG_FAST_cpu in mk/profiles.mk)
    bench --pose $p --data $d $sl --seg-profile cpu --seg-backbone mobilenet_v3_large --device "$dev" \
      --frames $frames --repeats $reps --steps 5 --result-name "pose_${profile}_dense_local_ycbv_sample_segmobile_$dev"
    bench --pose $p --data $d $sl --seg-profile paper --device "$dev" --frames $frames --repeats $reps --steps 5 \
      --result-name "pose_${profile}_dense_local_ycbv_sample_segpaper_$dev"
    if [ "$dev" = cuda ]; then
      bench --pose $p --data $d $sl --seg-profile cpu --device cpu --frames 10 --steps 3 \
        --result-name "pose_${profile}_dense_local_ycbv_sample_cpu16"
      # where the pose stage's time goes on the GPU machine (host functions by own time), no result file
      timeout 200 python3 -m cProfile -s tottime benchmarks/pose.py --pose $p --data $d $sl --device cuda \
        --frames $frames --repeats 3 --steps 1 --no-result > "$out/profile_cuda.txt" 2>&1 || true
    fi
    bench --profile paper --head dense --appearance local --device "$dev" --frames $frames --steps 20 \
      --result-name "pose_paper_dense_local_$dev"
    ;;
  *)
    echo "usage: bash benchmarks/device_pose.sh prepare|run" >&2; exit 2 ;;
esac
