/* example.c: calibrated acceleration from raw CSV on stdin, using the two files that
 * `imucal codegen` writes (default NAME imucal).
 *
 *   imucal codegen calibration.yaml --out gen
 *   cc -std=c99 -O2 -Igen -o imucal_example example.c gen/imucal.c -lm     (or: make GEN=gen)
 *   ./imucal_example < raw.csv > acc.csv
 *       the calibration baked into gen/imucal.c (imucal_apply, or imucal_apply_cov when the
 *       calibration has effects: then the covariate columns follow x, y, z)
 *   ./imucal_example s1 s2 s3 b1 b2 b3 phi psi theta < raw.csv > acc.csv
 *       run-time parameters, as firmware would read them from flash (imucal_prepare and
 *       imucal_apply_coeffs; base model only)
 *
 * Input: one sample per line, numbers separated by commas, spaces, tabs or semicolons; extra
 * columns are ignored; lines that do not start with a number (a header) are skipped.
 * Output: a header line, then ax,ay,az in m/s^2 in the Theorem's orthonormal frame, printed
 * with enough digits to round-trip (9 for float, 17 for double).
 * Exit status: 0 on success, 1 on a malformed line, 2 on invalid parameters.
 */
#include <ctype.h>
#include <stdio.h>
#include <stdlib.h>

#include "imucal.h"

#ifdef IMUCAL_N_COV
#define N_IN (3 + IMUCAL_N_COV)
#else
#define N_IN 3
#endif

/* Parse up to n numbers from line into v; returns how many were read. */
static int parse(const char *line, double *v, int n)
{
  int k = 0;
  while (k < n) {
    char *end;
    while (*line == ',' || *line == ';' || isspace((unsigned char)*line)) ++line;
    if (*line == '\0') break;
    v[k] = strtod(line, &end);
    if (end == line) break;
    ++k;
    line = end;
  }
  return k;
}

int main(int argc, char **argv)
{
  char line[4096];
  long lineno = 0;
  int baked = argc == 1;
  const char *fmt = sizeof(imucal_real) == sizeof(float) ? "%.9g,%.9g,%.9g\n" : "%.17g,%.17g,%.17g\n";
  imucal_coeffs coeffs;

  if (!baked) {
    imucal_real params[9];
    int i, rc;
    if (argc != 10) {
      fprintf(stderr, "usage: %s [s1 s2 s3 b1 b2 b3 phi psi theta] < raw.csv > acc.csv\n", argv[0]);
      return 2;
    }
    for (i = 0; i < 9; ++i) params[i] = (imucal_real)strtod(argv[i + 1], NULL);
    rc = imucal_prepare(params, &coeffs);
    if (rc != IMUCAL_OK) {
      fprintf(stderr, "%s: invalid parameters (imucal_prepare returned %d)\n", argv[0], rc);
      return 2;
    }
  }
  printf("ax,ay,az\n");
  while (fgets(line, sizeof line, stdin)) {
    double v[N_IN];
    imucal_real raw[3], acc[3];
    int i, k;
    ++lineno;
    k = parse(line, v, N_IN);
    if (k == 0) continue; /* header or empty line */
    if (k < N_IN) {
      fprintf(stderr, "%s: line %ld: expected %d numbers, got %d\n", argv[0], lineno, N_IN, k);
      return 1;
    }
    for (i = 0; i < 3; ++i) raw[i] = (imucal_real)v[i];
    if (!baked) {
      imucal_apply_coeffs(&coeffs, raw, acc);
    } else {
#ifdef IMUCAL_N_COV
      imucal_real cov[IMUCAL_N_COV];
      for (i = 0; i < IMUCAL_N_COV; ++i) cov[i] = (imucal_real)v[3 + i];
      imucal_apply_cov(raw, cov, acc);
#else
      imucal_apply(raw, acc);
#endif
    }
    printf(fmt, (double)acc[0], (double)acc[1], (double)acc[2]);
  }
  return 0;
}
