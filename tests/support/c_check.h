/* Checks for the plain-C tests of the C ABI (no test framework in C): each failed check prints
 * where, what and the C ABI's last error, and is counted; main() returns g_failures == 0. And
 * the mesh those tests share. */
#ifndef SOFTSHELL_TESTS_C_CHECK_H
#define SOFTSHELL_TESTS_C_CHECK_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "softshell/softshell_c.h"

static int g_failures = 0;
static int g_checks = 0;

#define CHECK(cond)                                                                                    \
  do {                                                                                                 \
    ++g_checks;                                                                                        \
    if (!(cond)) {                                                                                     \
      fprintf(stderr, "%s:%d: CHECK failed: %s (last error: %s)\n", __FILE__, __LINE__, #cond,          \
              ss_last_error_message());                                                                \
      ++g_failures;                                                                                    \
    }                                                                                                  \
  } while (0)

#define CHECK_STATUS(expr, expected)                                                                   \
  do {                                                                                                 \
    ++g_checks;                                                                                        \
    ss_status s_ = (expr);                                                                             \
    if (s_ != (expected)) {                                                                            \
      fprintf(stderr, "%s:%d: %s returned %s, expected %s (%s)\n", __FILE__, __LINE__, #expr,           \
              ss_status_name(s_), ss_status_name(expected), ss_last_error_message());                  \
      ++g_failures;                                                                                    \
    }                                                                                                  \
  } while (0)

#define CHECK_OK(expr) CHECK_STATUS(expr, SS_OK)

/* A flat n x n grid of quads over [0, 1]^2 in the plane z = 0, counter-clockwise seen from +z. */
static inline ss_mesh* make_grid(int n) {
  const int nv = (n + 1) * (n + 1);
  double* xyz = (double*)malloc(sizeof(double) * 3 * (size_t)nv);
  int32_t* sizes = (int32_t*)malloc(sizeof(int32_t) * (size_t)(n * n));
  int32_t* indices = (int32_t*)malloc(sizeof(int32_t) * 4 * (size_t)(n * n));
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      double* p = xyz + 3 * (j * (n + 1) + i);
      p[0] = (double)i / n;
      p[1] = (double)j / n;
      p[2] = 0.0;
    }
  }
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const int f = j * n + i;
      sizes[f] = 4;
      indices[4 * f + 0] = j * (n + 1) + i;
      indices[4 * f + 1] = j * (n + 1) + i + 1;
      indices[4 * f + 2] = (j + 1) * (n + 1) + i + 1;
      indices[4 * f + 3] = (j + 1) * (n + 1) + i;
    }
  }
  ss_mesh* mesh = NULL;
  CHECK_OK(ss_mesh_create(xyz, nv, sizes, n * n, indices, 4 * n * n, &mesh));
  free(xyz);
  free(sizes);
  free(indices);
  return mesh;
}

#endif /* SOFTSHELL_TESTS_C_CHECK_H */
