/* The structures' compiled kernel (src/structure_kernel.cpp), in the joint's library
 * libtensegrity_stiffness_kernel.so: the C ABI that tensegrity_stiffness/structures/kernel.py
 * loads with ctypes. Status codes, modes and force laws are those of kernel.h. */
#ifndef TENSEGRITY_STIFFNESS__STRUCTURE_KERNEL_H_
#define TENSEGRITY_STIFFNESS__STRUCTURE_KERNEL_H_

#include <stdint.h>

#include "tensegrity_stiffness/kernel.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Doubles of tsk_structure_evaluate's output buffer for n_bodies bodies and n_strings strings:
 * s (3n), lengths (n), tensions (n), wrenches (6N), K (36 N^2), then the slack and saturated flags
 * as 2n bytes; a negative status for bad counts. */
int64_t tsk_structure_size(int64_t n_bodies, int64_t n_strings);

/* Evaluate a structure: ends (n, 2) the body index of each string end (-1: the world), points
 * (n, 2, 3) the ends in their body's frame (in the world for -1), k, rest, max_stretch (n),
 * law TSK_LAW_*, transforms (N, 4, 4) row-major, mode TSK_MODE_FULL or TSK_MODE_WRENCH (K not
 * written). Returns TSK_OK or a TSK_ERROR_* code (TSK_ERROR_ZERO_LENGTH: a string shorter than
 * min_string_length; the outputs are then partly written). */
int64_t tsk_structure_evaluate(int64_t n_bodies, int64_t n_strings, const int64_t* ends,
                               const double* points, const double* k, const double* rest,
                               const double* max_stretch, int64_t law,
                               double min_string_length, const double* transforms, int64_t mode,
                               double* out, int64_t out_size);

#ifdef __cplusplus
}
#endif

#endif  /* TENSEGRITY_STIFFNESS__STRUCTURE_KERNEL_H_ */
