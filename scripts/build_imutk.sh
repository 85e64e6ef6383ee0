#!/bin/sh
# Build imu_tk's test program (acc + gyro calibration of two files) without its Qt/OpenGL viewer,
# for scripts/bench_gyro.py, and the same program calibrating the accelerometer alone (one file),
# for scripts/bench_memory.py. Needs g++, libceres-dev, libeigen3-dev, libboost-dev.
#
#   git clone https://github.com/Kyle-ak/imu_tk SRC   # imu_tk, BSD licence
#   sh scripts/build_imutk.sh SRC OUT                 # writes OUT/test_imu_calib and OUT/test_imu_acc
#
# Changes to imu_tk's sources, none to its maths: the plot and the wait for a key in verbose mode
# are removed (src/calibration.cpp), verbose output is off in the test program, and three setters
# declared to return a value but falling off their end (undefined behaviour: g++ -O2 builds a
# program that crashes) return their argument (include/imu_tk/calibration.h).
set -eu
SRC=$1
OUT=$2
mkdir -p "$OUT/inc/imu_tk"
cp "$SRC"/include/imu_tk/*.h "$OUT/inc/imu_tk/"
sed -i -e 's/init_interval_duration_ = duration; };/init_interval_duration_ = duration; return duration; };/' \
       -e 's/interval_n_samples_ = num; };/interval_n_samples_ = num; return num; };/' \
       -e 's/optimize_gyro_bias_ = enabled; };/optimize_gyro_bias_ = enabled; return enabled; };/' \
       "$OUT/inc/imu_tk/calibration.h"
sed -e '/imu_tk\/visualization.h/d' -e '/Plot plot;/d' -e '/plot\.plotIntervals/d' -e '/waitForKey();/d' \
    "$SRC/src/calibration.cpp" > "$OUT/calibration.cpp"
sed -e '/visualization.h/d' -e 's/enableVerboseOutput(true)/enableVerboseOutput(false)/' \
    "$SRC/apps/test_imu_calib.cpp" > "$OUT/test_imu_calib.cpp"
g++ -O2 -std=c++17 -DNDEBUG -Werror=return-type -I "$OUT/inc" -I /usr/include/eigen3 \
    "$OUT/calibration.cpp" "$SRC/src/filters.cpp" "$SRC/src/io_utils.cpp" "$OUT/test_imu_calib.cpp" \
    -o "$OUT/test_imu_calib" -lceres -lglog -lgflags -lpthread
# test_imu_acc: the same program with its gyroscope file and calls removed (calibrateAcc, one file).
sed -e '/importAsciiData( argv\[2\]/d' -e '/argv\[2\]/d' -e 's/argc < 3/argc < 2/' \
    -e 's/mp_calib.calibrateAccGyro(acc_data, gyro_data );/mp_calib.calibrateAcc(acc_data);/' \
    -e '/getGyroCalib().save/d' "$OUT/test_imu_calib.cpp" > "$OUT/test_imu_acc.cpp"
g++ -O2 -std=c++17 -DNDEBUG -Werror=return-type -I "$OUT/inc" -I /usr/include/eigen3 \
    "$OUT/calibration.cpp" "$SRC/src/filters.cpp" "$SRC/src/io_utils.cpp" "$OUT/test_imu_acc.cpp" \
    -o "$OUT/test_imu_acc" -lceres -lglog -lgflags -lpthread
echo "$OUT/test_imu_calib"
echo "$OUT/test_imu_acc"
