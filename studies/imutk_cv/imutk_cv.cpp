// imu_tk's accelerometer + gyroscope calibration with some gyro motion segments held out (issue 11).
//
//   imutk_cv ACC GYRO OUTDIR [HOLDOUT]
//
// Same data import and settings as imu_tk's apps/test_imu_calib.cpp (verbose output off). HOLDOUT:
// comma-separated indices of imu_tk's motion segments (0 = between its first two static intervals)
// whose residual blocks are not added to the gyro fit; none given = imu_tk unchanged. Writes
// OUTDIR/test_imu_acc.calib, OUTDIR/test_imu_gyro.calib and OUTDIR/segments.txt ("index t0 t1 kept"
// per segment, the gyro time stamps imu_tk integrates between).
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "imu_tk/calibration.h"
#include "imu_tk/io_utils.h"
#include "holdout.h"

using namespace imu_tk;
using namespace Eigen;

static std::set<int> held_out;
static std::ofstream segments;

bool imutk_cv_keep(int segment, double t0, double t1)
{
  bool keep = held_out.count(segment) == 0;
  segments.precision(17);
  segments << segment << " " << t0 << " " << t1 << " " << (keep ? 1 : 0) << "\n";
  return keep;
}

int main(int argc, char** argv)
{
  if (argc < 4 || argc > 5)
  {
    std::cerr << "usage: imutk_cv ACC GYRO OUTDIR [HOLDOUT, e.g. 0,5,10]" << std::endl;
    return 2;
  }
  const std::string out = argv[3];
  if (argc == 5)
  {
    std::stringstream list(argv[4]);
    std::string item;
    while (std::getline(list, item, ','))
      if (!item.empty())
        held_out.insert(std::stoi(item));
  }
  segments.open(out + "/segments.txt");
  if (!segments)
  {
    std::cerr << out << ": cannot write segments.txt" << std::endl;
    return 2;
  }
  std::vector<TriadData> acc_data, gyro_data;
  importAsciiData(argv[1], acc_data, imu_tk::TIMESTAMP_UNIT_SEC);
  importAsciiData(argv[2], gyro_data, imu_tk::TIMESTAMP_UNIT_SEC);
  for (int k = 1; k <= 2; k++)
    if ((k == 1 ? acc_data : gyro_data).empty())
    {
      std::cerr << argv[k] << ": no samples read (fix: give imu_tk's ASCII format, t x y z per line)" << std::endl;
      return 2;
    }

  // the settings of imu_tk's apps/test_imu_calib.cpp
  CalibratedTriad init_acc_calib, init_gyro_calib;
  init_acc_calib.setBias(Vector3d(32768, 32768, 32768));
  init_gyro_calib.setScale(Vector3d(1.0 / 6258.0, 1.0 / 6258.0, 1.0 / 6258.0));
  MultiPosCalibration mp_calib;
  mp_calib.setInitStaticIntervalDuration(50.0);
  mp_calib.setInitAccCalibration(init_acc_calib);
  mp_calib.setInitGyroCalibration(init_gyro_calib);
  mp_calib.setGravityMagnitude(9.81744);
  mp_calib.enableVerboseOutput(false);
  mp_calib.enableAccUseMeans(false);
  if (!mp_calib.calibrateAccGyro(acc_data, gyro_data))
    return 1;
  segments.close();
  mp_calib.getAccCalib().save(out + "/test_imu_acc.calib");
  mp_calib.getGyroCalib().save(out + "/test_imu_gyro.calib");
  return 0;
}
