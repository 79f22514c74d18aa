/* SPDX-License-Identifier: MIT */
/*
 * The k-th smallest of an array (order statistic) in linear expected time,
 * for quantiles without a sort (metrics, masseffect).
 */
#ifndef IMG_SELECT_H
#define IMG_SELECT_H

#include <stddef.h>
#include <stdint.h>

/*
 * k-th smallest of a[0..n-1] (0-based; k < n), N. Wirth's selection
 * ("Algorithms + Data Structures = Programs", 1976, section 2.3.4): the
 * value a sort would put at k (the same value, whichever equal element
 * lands there).  a is reordered: afterwards a[0..k-1] <= a[k] <=
 * a[k+1..n-1].  No NaN in a.
 */
static inline double img_select_k(double *a, size_t n, size_t k)
{
	int64_t l = 0, m = (int64_t)n - 1, kk = (int64_t)k;
	while (l < m) {
		double x = a[kk];
		int64_t i = l, j = m;
		do {
			while (a[i] < x)
				i++;
			while (x < a[j])
				j--;
			if (i <= j) {
				double t = a[i];
				a[i] = a[j];
				a[j] = t;
				i++;
				j--;
			}
		} while (i <= j);
		if (j < kk)
			l = i;
		if (kk < i)
			m = j;
	}
	return a[kk];
}

#endif
