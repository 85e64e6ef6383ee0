#!/bin/sh
# Build studies/imutk_cv/imutk_cv.cpp: imu_tk's acc + gyro calibration with chosen gyro motion
# segments held out, for studies/gyro_imutk_cv.py (imu_tk cross-validated like ours, issue 11).
# Needs g++, libceres-dev, libeigen3-dev, libboost-dev.
#
#   git clone https://github.com/Kyle-ak/imu_tk SRC   # imu_tk, BSD licence
#   sh studies/build_imutk_cv.sh SRC OUT              # writes OUT/imutk_cv
#
# imu_tk's sources get build_imutk.sh's changes (no plot, no wait for a key, three setters that
# fell off their end return their argument) and one more, none to its maths: in calibrateAccGyro
# the gyro residual block of motion segment i is added only if imutk_cv_keep(i, t0, t1) (defined
# by the driver) says so; held-out blocks are deleted unused. With nothing held out the fit is
# imu_tk's own.
set -eu
SRC=$1
OUT=$2
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$OUT/inc/imu_tk"
cp "$SRC"/include/imu_tk/*.h "$OUT/inc/imu_tk/"
cp "$HERE/imutk_cv/holdout.h" "$OUT/inc/"
sed -i -e 's/init_interval_duration_ = duration; };/init_interval_duration_ = duration; return duration; };/' \
       -e 's/interval_n_samples_ = num; };/interval_n_samples_ = num; return num; };/' \
       -e 's/optimize_gyro_bias_ = enabled; };/optimize_gyro_bias_ = enabled; return enabled; };/' \
       "$OUT/inc/imu_tk/calibration.h"
ADD='problem.AddResidualBlock ( cost_function, NULL \/\* squared loss \*\/, gyro_calib_params.data() );'
KEEP='if( imutk_cv_keep( i, calib_gyro_samples_[gyro_idx0].timestamp(), calib_gyro_samples_[gyro_idx1].timestamp() ) ) '
sed -e '/imu_tk\/visualization.h/d' -e '/Plot plot;/d' -e '/plot\.plotIntervals/d' -e '/waitForKey();/d' \
    -e 's|#include "imu_tk/calibration.h"|#include "imu_tk/calibration.h"\n#include "holdout.h"|' \
    -e "s/$ADD/$KEEP$ADD else delete cost_function;/" \
    "$SRC/src/calibration.cpp" > "$OUT/calibration.cpp"
# the patch must have taken (once), or the driver would silently fit every segment
[ "$(grep -c 'imutk_cv_keep( i,' "$OUT/calibration.cpp")" = 1 ] || { echo "build_imutk_cv.sh: patch did not apply to $SRC/src/calibration.cpp" >&2; exit 1; }
g++ -O2 -std=c++17 -DNDEBUG -Werror=return-type -I "$OUT/inc" -I /usr/include/eigen3 \
    "$OUT/calibration.cpp" "$SRC/src/filters.cpp" "$SRC/src/io_utils.cpp" "$HERE/imutk_cv/imutk_cv.cpp" \
    -o "$OUT/imutk_cv" -lceres -lglog -lgflags -lpthread
echo "$OUT/imutk_cv"
