/* SPDX-License-Identifier: MIT */
/*
 * The solver's internals (private to lib/tled: plugins include
 * tled_solve.h).  tled_solve.c holds the relaxation loop, tled_solve_dt.c
 * the time step estimate (Lanczos), tled_solve_con.c the collocated
 * conditions and the contact; what more than one of them uses is declared
 * here.  SI units.
 */
#ifndef TLED_SOLVE_INT_H
#define TLED_SOLVE_INT_H

#include "tled_solve.h"

/* the plain C reference backend (tled_step.c): host forces and step, the
 * operations of a NULL tled_solver_opts_t.ops.  tled_solve.c */
extern const tled_ops_t tled_cpu_ops;

/* Impose the collocated conditions u^h(X_c) = s->cbar_c by the smallest
 * mass-weighted correction du = M^-1 Phi_C^T lambda (added to s->u, left
 * in s->wn); returns the largest violation before it (m).
 * tled_solve_con.c */
double tled_ebc_project(tled_solver_t *s);

/* Project y (3n, a Lanczos vector in the mass-scaled space M^1/2 u) onto
 * the null space of the collocated conditions.  tled_solve_con.c */
void tled_ebc_project_scaled(tled_solver_t *s, double *y);

#endif
