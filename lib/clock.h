/* SPDX-License-Identifier: MIT */
/*
 * A monotonic wall clock in seconds, for the time splits and progress lines
 * that plugins and libraries log (the runtime has its own, sched_now).
 * Header only: every plugin and library compiles with -Ilib, none has to
 * link anything for it.
 */
#ifndef ARMSTG_LIB_CLOCK_H
#define ARMSTG_LIB_CLOCK_H

#include <time.h>

/* seconds since an arbitrary start (CLOCK_MONOTONIC) */
static inline double lib_now_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

#endif
