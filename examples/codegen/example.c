/* example.c: calibrated acceleration (and angular rate, when the calibration has a gyroscope
 * part and the input has gx, gy, gz) from an imucal CSV on stdin, using the two files that
 * `imucal codegen` writes.
 *
 *   imucal codegen calibration.yaml --out gen --prefix NAME
 *   make GEN=gen PREFIX=NAME OUT=build      (creates build/, writes build/NAME_example)
 *   or: cc -std=c99 -O2 -Igen -DIMUCAL_NAME=NAME -DIMUCAL_NAME_UPPER=NAME_IN_CAPITALS \
 *          -o NAME_example example.c gen/NAME.c -lm                (default NAME: imucal)
 *   ./NAME_example < raw.csv > acc.csv
 *       the calibration baked into gen/NAME.c (NAME_apply, or NAME_apply_cov when the
 *       calibration has effects: temp [degC] from the temp column, time [s] from the t column,
 *       counted from the first sample)
 *   ./NAME_example s1 s2 s3 b1 b2 b3 phi psi theta < raw.csv > acc.csv
 *       run-time parameters, as firmware would read them from flash (NAME_prepare and
 *       NAME_apply_coeffs; base model only)
 *
 * Input: imucal's layout. A header line names the columns (t, ax, ay, az, gx, gy, gz, temp; also
 * x y z, acc_x ..., gyro_x ..., wx ..., time, temperature), in any order, separated by commas,
 * spaces, tabs or semicolons. Gyroscope columns are read by header only.
 * Without a header, the columns are taken as imucal reads them: 3 columns ax ay az, 4 columns
 * t ax ay az, 5 or more t ax ay az temp. Lines starting with # are skipped.
 * Output: a header line, then t (when the input has one, as it was) and ax,ay,az in m/s^2 in
 * the Theorem's orthonormal frame, then gx,gy,gz in rad/s in the same frame when the calibration
 * has a gyroscope part and the input has gx, gy, gz (NAME_apply_gyro with the calibrated
 * acceleration of the same sample; the input's gyro columns are ignored, with a note on stderr,
 * when the calibration has no gyroscope), printed with enough digits to round-trip (9 for
 * float, 17 for double).
 * Exit status: 0 on success, 1 on a malformed line or header, 2 on invalid parameters.
 */
#include <ctype.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef IMUCAL_NAME
#define IMUCAL_NAME imucal
#define IMUCAL_NAME_UPPER IMUCAL
#endif
#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
#define STR_(x) #x
#define STR(x) STR_(x)
#define FN(x) CAT(IMUCAL_NAME, x)
#define MACRO(x) CAT(IMUCAL_NAME_UPPER, x)

#include STR(IMUCAL_NAME.h)

typedef FN(_real) real;
#define N_COV MACRO(_N_COV)
#define MAX_COLS 64

enum { COL_T, COL_AX, COL_AY, COL_AZ, COL_TEMP, COL_GX, COL_GY, COL_GZ, N_ROLES };

/* Split line into at most MAX_COLS fields in place; returns how many. */
static int split(char *line, char **field)
{
  int n = 0;
  char *p = line;
  while (n < MAX_COLS) {
    while (*p == ' ' || *p == '\t') ++p;
    if (*p == '\0' || *p == '\n' || *p == '\r') break;
    field[n++] = p;
    while (*p && *p != ',' && *p != ';' && *p != ' ' && *p != '\t' && *p != '\n' && *p != '\r') ++p;
    while (*p == ' ' || *p == '\t') ++p;
    if (*p == ',' || *p == ';') {
      *p++ = '\0';
    } else if (*p == '\n' || *p == '\r') {
      *p = '\0';
      break;
    } else if (*p != '\0') {
      p[-1] = '\0'; /* whitespace-separated: end the field at the blank before p */
    }
  }
  for (; n > 0 && *field[n - 1] == '\0'; --n) {}
  return n;
}

static int is_number(const char *s)
{
  char *end;
  strtod(s, &end);
  return end != s && *end == '\0';
}

/* The role of a header name, or -1. */
static int role_of(const char *name)
{
  static const char *const names[N_ROLES][4] = {
    {"t", "time", "timestamp", NULL}, {"ax", "x", "acc_x", "accx"}, {"ay", "y", "acc_y", "accy"},
    {"az", "z", "acc_z", "accz"}, {"temp", "temperature", "t_c", NULL},
    {"gx", "gyro_x", "gyrx", "wx"}, {"gy", "gyro_y", "gyry", "wy"}, {"gz", "gyro_z", "gyrz", "wz"}};
  char low[32];
  size_t i;
  int r, k;
  for (i = 0; name[i] && i + 1 < sizeof low; ++i) low[i] = (char)tolower((unsigned char)name[i]);
  low[i] = '\0';
  if (name[i]) return -1;
  for (r = 0; r < N_ROLES; ++r)
    for (k = 0; k < 4 && names[r][k]; ++k)
      if (strcmp(low, names[r][k]) == 0) return r;
  return -1;
}

int main(int argc, char **argv)
{
  char line[4096];
  char *field[MAX_COLS];
  long lineno = 0;
  int col[N_ROLES];
  int have_layout = 0, gyro = 0, r;
#if N_COV > 0 && MACRO(_COV_TIME) >= 0
  double t0 = 0.0;
  int have_t0 = 0;
#endif
  int baked = argc == 1;
  const char *fmt = sizeof(real) == sizeof(float) ? "%.9g,%.9g,%.9g" : "%.17g,%.17g,%.17g";
  FN(_coeffs) coeffs;

  for (r = 0; r < N_ROLES; ++r) col[r] = -1;
  if (!baked) {
    real params[9];
    int i, rc;
    if (argc != 10) {
      fprintf(stderr, "usage: %s [s1 s2 s3 b1 b2 b3 phi psi theta] < raw.csv > acc.csv\n", argv[0]);
      return 2;
    }
    for (i = 0; i < 9; ++i) params[i] = (real)strtod(argv[i + 1], NULL);
    rc = FN(_prepare)(params, &coeffs);
    if (rc != MACRO(_OK)) {
      fprintf(stderr, "%s: invalid parameters (%s_prepare returned %d)\n", argv[0], STR(IMUCAL_NAME), rc);
      return 2;
    }
  }
  while (fgets(line, sizeof line, stdin)) {
    double v[N_ROLES];
    real raw[3], acc[3];
    int i, n;
    ++lineno;
    if (line[0] == '#') continue;
    n = split(line, field);
    if (n == 0) continue;
    if (!have_layout) {
      have_layout = 1;
      if (!is_number(field[0])) { /* a header: find the roles by name */
        for (i = 0; i < n; ++i)
          if ((r = role_of(field[i])) >= 0 && col[r] < 0) col[r] = i;
        if (col[COL_AX] < 0 || col[COL_AY] < 0 || col[COL_AZ] < 0) {
          fprintf(stderr, "%s: line %ld: header names no ax, ay, az columns\n", argv[0], lineno);
          return 1;
        }
        gyro = col[COL_GX] >= 0 && col[COL_GY] >= 0 && col[COL_GZ] >= 0;
        if (!gyro && (col[COL_GX] >= 0 || col[COL_GY] >= 0 || col[COL_GZ] >= 0)) {
          fprintf(stderr, "%s: line %ld: header names some but not all of gx, gy, gz\n", argv[0], lineno);
          return 1;
        }
        if (gyro && !MACRO(_HAS_GYRO)) {
          fprintf(stderr, "%s: note: the calibration has no gyroscope part; gx, gy, gz ignored\n", argv[0]);
          gyro = 0;
          col[COL_GX] = col[COL_GY] = col[COL_GZ] = -1;
        }
        printf("%s%s\n", col[COL_T] >= 0 ? "t,ax,ay,az" : "ax,ay,az", gyro ? ",gx,gy,gz" : "");
        continue;
      }
      if (n == 3) { /* no header: imucal's default layout by column count */
        col[COL_AX] = 0, col[COL_AY] = 1, col[COL_AZ] = 2;
      } else if (n >= 4) {
        col[COL_T] = 0, col[COL_AX] = 1, col[COL_AY] = 2, col[COL_AZ] = 3;
        if (n >= 5) col[COL_TEMP] = 4;
      } else {
        fprintf(stderr, "%s: line %ld: expected 3 numbers, got %d\n", argv[0], lineno, n);
        return 1;
      }
      printf(col[COL_T] >= 0 ? "t,ax,ay,az\n" : "ax,ay,az\n");
    }
    for (r = 0; r < N_ROLES; ++r) {
      if (col[r] < 0) continue;
      if (col[r] >= n || !is_number(field[col[r]])) {
        fprintf(stderr, "%s: line %ld: expected a number in column %d\n", argv[0], lineno, col[r] + 1);
        return 1;
      }
      v[r] = strtod(field[col[r]], NULL);
    }
    for (i = 0; i < 3; ++i) raw[i] = (real)v[COL_AX + i];
    if (!baked) {
      FN(_apply_coeffs)(&coeffs, raw, acc);
    } else {
#if N_COV > 0
      real cov[N_COV];
#if MACRO(_COV_TEMP) >= 0
      if (col[COL_TEMP] < 0) {
        fprintf(stderr, "%s: the calibration needs a temp column [degC]\n", argv[0]);
        return 1;
      }
      cov[MACRO(_COV_TEMP)] = (real)v[COL_TEMP];
#endif
#if MACRO(_COV_TIME) >= 0
      if (col[COL_T] < 0) {
        fprintf(stderr, "%s: the calibration needs a t column [s]\n", argv[0]);
        return 1;
      }
      if (!have_t0) t0 = v[COL_T], have_t0 = 1;
      cov[MACRO(_COV_TIME)] = (real)(v[COL_T] - t0); /* time since the first sample [s] */
#endif
      FN(_apply_cov)(raw, cov, acc);
#else
      FN(_apply)(raw, acc);
#endif
    }
    if (col[COL_T] >= 0) printf("%s,", field[col[COL_T]]); /* the time as it was */
    printf(fmt, (double)acc[0], (double)acc[1], (double)acc[2]);
#if MACRO(_HAS_GYRO)
    if (gyro) {
      real omega[3];
      for (i = 0; i < 3; ++i) raw[i] = (real)v[COL_GX + i];
      FN(_apply_gyro)(raw, acc, omega); /* acc: the calibrated acceleration of this sample */
      putchar(',');
      printf(fmt, (double)omega[0], (double)omega[1], (double)omega[2]);
    }
#endif
    putchar('\n');
  }
  return 0;
}
