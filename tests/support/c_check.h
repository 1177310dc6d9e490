/* Checks for the plain-C tests of the C ABI (no test framework in C): each failed check prints
 * where, what and the C ABI's last error, and is counted; main() returns g_failures == 0. */
#ifndef SOFTSHELL_TESTS_C_CHECK_H
#define SOFTSHELL_TESTS_C_CHECK_H

#include <stdio.h>

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

#endif /* SOFTSHELL_TESTS_C_CHECK_H */
