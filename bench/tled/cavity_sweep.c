/* SPDX-License-Identifier: MIT */
/*
 * tled_cpu accuracy/speed sweep on the spherical cavity (tests/tled_cavity.h):
 * node spacing h, support size K and time-step safety against the error of
 * the radial displacement and the CPU time.  Build and run: see
 * bench/tled/run_sweep.sh.  Usage:
 *   cavity_sweep [h=2.5] [K=20] [safety=0.8] [nu=0.49] [a=10] [b=20]
 *                [ebc=1] [corr=2] [steps=1] [ua=0.1] [tol=1e-5] [threads=2]
 *                [ipf=0 (model default)] [legacy=0 (1: K-nearest supports)]
 *                [dump=FILE] [lin=0] [jit=0.2] [dil=0] [ha=0] [ramp=100]
 * (key=value, any order); prints one TSV line.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../plugins/tled_cpu/tests/tled_cavity.h"

int main(int argc, char **argv)
{
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	int steps = 1, header = 0;
	for (int i = 1; i < argc; i++) {
		char *eq = strchr(argv[i], '=');
		if (!strcmp(argv[i], "header")) {
			header = 1;
			continue;
		}
		if (!eq) {
			fprintf(stderr, "bad argument %s\n", argv[i]);
			return 2;
		}
		*eq = 0;
		double v = atof(eq + 1);
		const char *k = argv[i];
		if (!strcmp(k, "h")) c.h = v;
		else if (!strcmp(k, "K")) c.K = (int)v;
		else if (!strcmp(k, "safety")) c.dt_safety = v;
		else if (!strcmp(k, "nu")) c.nu = v;
		else if (!strcmp(k, "a")) c.a = v;
		else if (!strcmp(k, "b")) c.b = v;
		else if (!strcmp(k, "ebc")) c.ebc = (int)v;
		else if (!strcmp(k, "corr")) c.corr = (int)v;
		else if (!strcmp(k, "steps")) steps = (int)v;
		else if (!strcmp(k, "ua")) c.ua = v;
		else if (!strcmp(k, "tol")) c.tol = v;
		else if (!strcmp(k, "threads")) c.nthreads = (int)v;
		else if (!strcmp(k, "maxit")) c.max_iter = (int)v;
		else if (!strcmp(k, "dump")) c.dump = eq + 1;
		else if (!strcmp(k, "ipf")) c.ip_factor = v;
		else if (!strcmp(k, "lin")) c.lin = v;
		else if (!strcmp(k, "jit")) c.jit = v;
		else if (!strcmp(k, "dil")) c.dil = v;
		else if (!strcmp(k, "ha")) c.ha = v;
		else if (!strcmp(k, "ramp")) c.ramp = (int)v;
		else if (!strcmp(k, "legacy")) c.legacy_support = (int)v;
		else {
			fprintf(stderr, "unknown key %s\n", k);
			return 2;
		}
	}
	tled_model_opts_t mo;
	tled_model_opts_default(&mo);
	double ipf = c.ip_factor > 0 ? c.ip_factor : mo.ip_factor;
	const char *sup = c.legacy_support ? "legacy" : "nodal";
	if (header)
		printf("support\tipf\th_mm\tK\tsafety\tnu\tebc\tcorr\tnodes\tips\titers\t"
		       "converged\trms_err\trms_err_interior\tmax_err\t"
		       "ut_max\tjmin\tdt_s\tdt_crit_s\tcpu_s\twall_s\n");
	cavity_res_t r;
	cavity_run(&c, steps, &r);
	if (r.rc) {
		printf("%s\t%g\t%g\t%d\t%g\t%g\t%d\t%d\tERROR: %s\n", sup, ipf, c.h, c.K,
		       c.dt_safety, c.nu, c.ebc, c.corr, r.err);
		return 1;
	}
	printf("%s\t%g\t%g\t%d\t%g\t%g\t%d\t%d\t%lld\t%lld\t%d\t%d\t%.4f\t%.4f\t"
	       "%.4f\t%.4f\t%.4f\t%.3g\t%.3g\t%.2f\t%.2f\n",
	       sup, ipf, c.h, c.K, c.dt_safety, c.nu, c.ebc, c.corr, (long long)r.n,
	       (long long)r.nip, r.iters, r.converged, r.rms, r.rms_in, r.max,
	       r.ut_max, r.jmin, r.dt, r.dt_crit, r.cpu_s, r.wall_s);
	fprintf(stderr, "correction: %d CG iterations, residual %.3g\n",
		r.corr_iters, r.corr_rel);
	return 0;
}
