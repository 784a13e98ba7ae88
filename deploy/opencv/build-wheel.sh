#!/usr/bin/env bash
# OpenCV's Python wheel for the service image, built from its PyPI sdist with only what FishLoc
# calls: core, imgproc (remap, resize, drawing), imgcodecs (JPEG and PNG through the bundled
# libjpeg-turbo, libpng and zlib) and video (the Kalman filter of site tracks). No video input
# (FFmpeg, V4L), no BLAS/LAPACK, no other codecs or modules: the PyPI wheel's 162 MB of files
# become about 12 MB. The wheel keeps its name and version, so fishloc's dependency on
# opencv-python-headless is met by it; `fishloc gateway` reading video runs from a pip install.
#
# Usage: deploy/opencv/build-wheel.sh VERSION OUT_DIR
# Needs python3 with pip (a venv), python3-dev, g++, cmake, ninja and nasm (libjpeg-turbo's SIMD).
set -euo pipefail

VERSION=$1
OUT=$2
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

pip download --disable-pip-version-check --no-deps --no-binary opencv-python-headless --dest "$WORK" \
    "opencv-python-headless==$VERSION"
tar -xzf "$WORK/opencv_python_headless-$VERSION.tar.gz" -C "$WORK"
cd "$WORK/opencv_python_headless-$VERSION"

# OpenCV's typing stubs refer to modules left out (features2d), so their generation is skipped
# and the wheel must not expect py.typed or cv2/typing. Each edit is checked: a new sdist that
# changes these lines stops the build here, not with a wheel missing files.
grep -q '\[ r"python/cv2/py.typed" \]' setup.py
grep -q 'rearrange_cmake_output_data\["cv2.typing"\] = ' setup.py
sed -i -e 's|\[ r"python/cv2/py.typed" \]|[]|' \
    -e 's|rearrange_cmake_output_data\["cv2.typing"\] = .*|pass|' setup.py

OFF=(FFMPEG GSTREAMER V4L 1394 IPP LAPACK EIGEN OPENCL TIFF WEBP OPENJPEG JASPER OPENEXR AVIF JPEGXL
     ITT PROTOBUF QUIRC FLATBUFFERS VA VA_INTEL OBSENSOR KLEIDICV IMGCODEC_HDR IMGCODEC_SUNRASTER
     IMGCODEC_PFM IMGCODEC_GIF)
ARGS=(-DBUILD_LIST=core,imgproc,imgcodecs,video,python3 -DBUILD_OPENEXR=OFF -DBUILD_JPEG=ON
      -DBUILD_PNG=ON -DBUILD_ZLIB=ON -DENABLE_PRECOMPILED_HEADERS=OFF -DCMAKE_BUILD_TYPE=Release)
for feature in "${OFF[@]}"; do
    ARGS+=("-DWITH_$feature=OFF")
done
export ENABLE_HEADLESS=1 CMAKE_BUILD_PARALLEL_LEVEL
CMAKE_BUILD_PARALLEL_LEVEL=$(nproc)
CMAKE_ARGS="${ARGS[*]}" pip wheel --disable-pip-version-check --no-deps --wheel-dir "$OUT" .
ls -l "$OUT"
