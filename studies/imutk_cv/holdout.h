// Hook patched into imu_tk's MultiPosCalibration::calibrateAccGyro by studies/build_imutk_cv.sh:
// called once per motion segment i (between imu_tk's static intervals i and i + 1, gyro samples
// t0..t1 [s]) before its MultiPosGyroResidual is added; false leaves the segment out of the fit.
#pragma once

bool imutk_cv_keep(int segment, double t0, double t1);
