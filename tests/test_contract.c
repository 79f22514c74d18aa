/* SPDX-License-Identifier: MIT */
/*
 * Contract driver: every plugin in $BUILD/plugins must pass every check of
 * tests/contract.h; the deliberately broken test plugins must fail the
 * checks they break (proof that the driver bites).
 */
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include "testutil.h"
#include "contract.h"

#define CHECK_TIMEOUT_S 120

/* ---- synthetic inputs ---- */

static msg_t *make_input(int type, int typical)
{
	if (type == MSG_VOLUME) {
		int n = typical ? 12 : 1;
		double A[16] = { 2, 0, 0, -12, 0, 2, 0, -12, 0, 0, 2, -12,
				 0, 0, 0, 1 };
		vol_t *v = vol_new(n, n, n, 1, DT_F32, A);
		if (typical) {
			float *d = v->data;
			for (int k = 0; k < n; k++)
				for (int j = 0; j < n; j++)
					for (int i = 0; i < n; i++) {
						double r = sqrt((i - 5.5) * (i - 5.5) +
								(j - 5.5) * (j - 5.5) +
								(k - 5.5) * (k - 5.5));
						d[(k * n + j) * n + i] =
							r < 4 ? (r < 2 ? 3 : 2) : 0;
					}
		}
		return &v->base;
	}
	if (type == MSG_POINTSET) {
		int n = typical ? 20 : 0;
		ps_t *p = ps_new(n);
		double *lay = ps_add_attr(p, "layer", 1);
		double *par = ps_add_attr(p, "parent", 3);
		for (int i = 0; i < n; i++) {
			double t = 2 * M_PI * i / n;
			p->xyz[3 * i] = 5 * cos(t);
			p->xyz[3 * i + 1] = 5 * sin(t);
			p->xyz[3 * i + 2] = (i % 3) - 1.0;
			p->label[i] = i % 6;
			lay[i] = i % 2;
			par[3 * i] = 6 * cos(t);
			par[3 * i + 1] = 6 * sin(t);
			par[3 * i + 2] = p->xyz[3 * i + 2];
		}
		return &p->base;
	}
	tab_t *t = tab_new();
	if (typical) {
		for (int r = 0; r < 2; r++) {
			int64_t row = tab_add_row(t);
			tab_set_str(t, row, "name", r ? "b" : "a");
			tab_set_num(t, row, "value", r + 0.5);
		}
	}
	return &t->base;
}

/* ---- helpers run inside the child ---- */

static char child_msg[2048];

static int dir_empty(const char *d)
{
	DIR *dp = opendir(d);
	struct dirent *de;
	int n = 0;
	if (!dp)
		return 1;
	while ((de = readdir(dp)))
		if (strcmp(de->d_name, ".") && strcmp(de->d_name, ".."))
			n++;
	closedir(dp);
	return n == 0;
}


/* Set params: hints file first, then dummies for required ones. */
static int setup_params(rt_stage_t *s, const armstg_plugin_t *d,
			const char *hints_dir, int use_hints)
{
	char e[1024];
	unsigned char set[128] = { 0 };
	if (use_hints && hints_dir) {
		char path[1024], line[1024];
		snprintf(path, sizeof path, "%s/%s/contract.ini", hints_dir,
			 d->name);
		FILE *f = fopen(path, "r");
		while (f && fgets(line, sizeof line, f)) {
			char *eq = strchr(line, '=');
			if (line[0] == '#' || line[0] == ';' || !eq)
				continue;
			*eq = 0;
			char *k = line, *v = eq + 1;
			while (*k == ' ')
				k++;
			char *ke = k + strlen(k);
			while (ke > k && (ke[-1] == ' ' || ke[-1] == '\t'))
				*--ke = 0;
			while (*v == ' ')
				v++;
			char *ve = v + strlen(v);
			while (ve > v && (ve[-1] == '\n' || ve[-1] == ' ' ||
					  ve[-1] == '\r'))
				*--ve = 0;
			if (stage_set_param(s, k, v, e, sizeof e)) {
				snprintf(child_msg, sizeof child_msg,
					 "contract.ini: %s", e);
				fclose(f);
				return -1;
			}
			for (int i = 0; i < d->n_params; i++)
				if (!strcmp(d->params[i].name, k))
					set[i] = 1;
		}
		if (f)
			fclose(f);
	}
	for (int i = 0; i < d->n_params && i < 128; i++) {
		const armstg_param_t *p = &d->params[i];
		if (!(p->flags & PARAM_REQUIRED) || set[i])
			continue;
		char v[64];
		if (p->type == PT_STRING)
			snprintf(v, sizeof v, "contract-dummy.out");
		else if (p->type == PT_ENUM) {
			const char *bar = strchr(p->choices, '|');
			snprintf(v, sizeof v, "%.*s",
				 bar ? (int)(bar - p->choices) : 63, p->choices);
		} else if (p->type == PT_BOOL)
			snprintf(v, sizeof v, "false");
		else
			snprintf(v, sizeof v, "%.17g", p->min);
		if (stage_set_param(s, p->name, v, e, sizeof e)) {
			snprintf(child_msg, sizeof child_msg, "%s", e);
			return -1;
		}
	}
	if (stage_finish_params(s, e, sizeof e)) {
		snprintf(child_msg, sizeof child_msg, "%s", e);
		return -1;
	}
	return 0;
}

/* 1 when x is one of the numbers listed in CHOICES ("-1|0.5") */
static int num_listed(const char *choices, double x)
{
	for (const char *c = choices; c && *c;) {
		char *end;
		if (strtod(c, &end) == x && end != c)
			return 1;
		c += strcspn(c, "|");
		if (*c == '|')
			c++;
	}
	return 0;
}

static int check_params(const armstg_plugin_t *d)
{
	char e[1024];
	rt_stage_t *s = stage_new(d, d->name);
	int bad = 0;
	if (!stage_set_param(s, "no_such_parameter_xyz", "1", e, sizeof e) ||
	    !strstr(e, "no_such_parameter_xyz")) {
		snprintf(child_msg, sizeof child_msg,
			 "unknown parameter accepted or not named");
		bad = 1;
	}
	for (int i = 0; i < d->n_params && !bad; i++) {
		const armstg_param_t *p = &d->params[i];
		const char *vals[4];
		char lo[64], hi[64];
		int nv = 0;
		if (p->type == PT_INT || p->type == PT_DOUBLE) {
			/* out of range, and not one of the values the
			 * parameter accepts outside its range (choices:
			 * "-1"), each of which must be accepted */
			if (isfinite(p->min) && p->min > -1e300) {
				double v = p->min - 1 - fabs(p->min);
				while (num_listed(p->choices, v))
					v -= 1;
				snprintf(lo, sizeof lo, "%.17g", v);
				vals[nv++] = lo;
			}
			if (isfinite(p->max) && p->max < 1e300) {
				double v = p->max + 1 + fabs(p->max);
				while (num_listed(p->choices, v))
					v += 1;
				snprintf(hi, sizeof hi, "%.17g", v);
				vals[nv++] = hi;
			}
			for (const char *c = p->choices; c && *c && !bad;) {
				char v[64];
				size_t n = strcspn(c, "|");
				snprintf(v, sizeof v, "%.*s", (int)n, c);
				if (stage_set_param(s, p->name, v, e, sizeof e)) {
					snprintf(child_msg, sizeof child_msg,
						 "parameter '%s' refused its listed "
						 "value '%s': %s", p->name, v, e);
					bad = 1;
				}
				c += n + (c[n] == '|');
			}
			vals[nv++] = "not-a-number";
			if (p->type == PT_INT)
				vals[nv++] = "1.5";
		} else if (p->type == PT_BOOL) {
			vals[nv++] = "maybe";
		} else if (p->type == PT_ENUM) {
			vals[nv++] = "no-such-choice";
		}
		for (int k = 0; k < nv && !bad; k++) {
			e[0] = 0;
			if (!stage_set_param(s, p->name, vals[k], e, sizeof e)) {
				snprintf(child_msg, sizeof child_msg,
					 "parameter '%s' accepted '%s'",
					 p->name, vals[k]);
				bad = 1;
			} else if (!strstr(e, p->name)) {
				snprintf(child_msg, sizeof child_msg,
					 "refusal of '%s' does not name the "
					 "parameter: %s", p->name, e);
				bad = 1;
			}
		}
	}
	stage_free(s);
	return bad;
}

static int run_process(const armstg_plugin_t *d, const char *hints,
		       int typical, const char *outdir, int check_untouched,
		       int check_roundtrip)
{
	rt_stage_t *s = stage_new(d, d->name);
	stage_set_outdir(s, outdir);
	stage_set_threads(s, 2);
	if (setup_params(s, d, hints, 1)) {
		stage_free(s);
		return 1;
	}
	msg_t *in[32] = { 0 };
	uint64_t h[32] = { 0 };
	for (int i = 0; i < d->n_inputs; i++) {
		in[i] = make_input(d->inputs[i].type, typical);
		msg_freeze(in[i]);
		h[i] = msg_hash(in[i]);
	}
	int bad = 0;
	int rc = stage_init(s);
	if (rc) {
		if (!stage_error(s)[0]) {
			snprintf(child_msg, sizeof child_msg,
				 "init failed (%d) without a message", rc);
			bad = 1;
		}
		goto out;
	}
	rc = stage_process(s, (const msg_t *const *)in);
	if (rc && (!stage_error(s)[0] ||
		   !strcmp(stage_error(s), armstg_strerror(rc)))) {
		snprintf(child_msg, sizeof child_msg,
			 "process failed (%s) without a message of its own",
			 armstg_strerror(rc));
		bad = 1;
		goto out;
	}
	for (int i = 0; check_untouched && i < d->n_inputs; i++)
		if (msg_hash(in[i]) != h[i]) {
			snprintf(child_msg, sizeof child_msg,
				 "process modified its input '%s'",
				 d->inputs[i].name);
			bad = 1;
			goto out;
		}
	for (int o = 0; !rc && check_roundtrip && o < d->n_outputs; o++) {
		msg_t *m = stage_output(s, o);
		char *buf = NULL, e[512] = "";
		size_t len = 0;
		msg_t *back = NULL;
		if (!m)
			continue;
		if (msg_pack(m, &buf, &len) ||
		    msg_unpack(buf, len, 0, &back, e, sizeof e) ||
		    !msg_equal(m, back)) {
			snprintf(child_msg, sizeof child_msg,
				 "output '%s' does not survive MessagePack: "
				 "%s", d->outputs[o].name, e);
			bad = 1;
		}
		free(buf);
		msg_unref(back);
	}
out:
	stage_discard_files(s);
	stage_fini(s);
	stage_free(s);
	for (int i = 0; i < d->n_inputs; i++)
		msg_unref(in[i]);
	if (!bad && !dir_empty(outdir)) {
		snprintf(child_msg, sizeof child_msg,
			 "files left in the output folder after a discarded "
			 "run");
		bad = 1;
	}
	return bad;
}

static const char *checks[] = { "load", "params", "init-fini",
				"fini-no-init", "empty-input", "typical-input",
				"inputs-untouched", "roundtrip" };
#define NCHECKS (int)(sizeof checks / sizeof checks[0])

static int child_check(const char *so, const char *hints, int c,
		       const char *outdir)
{
	rt_plugin_t p;
	char e[1024];
	if (plugin_load_file(so, &p, e, sizeof e)) {
		snprintf(child_msg, sizeof child_msg, "%s", e);
		return 1;
	}
	const armstg_plugin_t *d = p.desc;
	int bad = 0;
	switch (c) {
	case 0:
		break;
	case 1:
		bad = check_params(d);
		break;
	case 2:
		for (int k = 0; k < 3 && !bad; k++) {
			rt_stage_t *s = stage_new(d, d->name);
			if (setup_params(s, d, hints, 1))
				bad = 1;
			else if (stage_init(s) && !stage_error(s)[0]) {
				snprintf(child_msg, sizeof child_msg,
					 "init failed without a message");
				bad = 1;
			}
			stage_fini(s);
			stage_free(s);
		}
		break;
	case 3: {
		rt_stage_t *s = stage_new(d, d->name);
		if (setup_params(s, d, hints, 1))
			bad = 1;
		else if (d->fini)
			d->fini(stage_pub(s)); /* as after an init that failed
						  before touching priv */
		stage_free(s);
		break;
	}
	case 4:
		bad = run_process(d, hints, 0, outdir, 0, 1);
		break;
	case 5:
		bad = run_process(d, hints, 1, outdir, 0, 0);
		break;
	case 6:
		bad = run_process(d, hints, 1, outdir, 1, 0) ||
		      run_process(d, hints, 0, outdir, 1, 0);
		break;
	case 7:
		bad = run_process(d, hints, 1, outdir, 0, 1);
		break;
	}
	return bad;
}

int contract_run(const char *so, const char *hints, char *report,
		 size_t reportsize)
{
	int fails = 0;
	size_t o = 0;
	report[0] = 0;
	for (int c = 0; c < NCHECKS; c++) {
		int fd[2];
		char errpath[64];
		snprintf(errpath, sizeof errpath, "/tmp/armstg-contract-%d.err",
			 (int)getpid());
		/* the parent makes and removes the child's output folder:
		 * a child that crashes or hangs cannot remove it */
		char outdir[] = "/tmp/armstg-contract-XXXXXX";
		if (!mkdtemp(outdir))
			return -1;
		if (pipe(fd)) {
			tu_rm_rf(outdir);
			return -1;
		}
		fflush(NULL);
		pid_t pid = fork();
		if (pid == 0) {
			close(fd[0]);
			/* cmocka catches SIGSEGV & co. to longjmp back into
			 * its runner: the child must die of them instead */
			int sigs[] = { SIGSEGV, SIGBUS, SIGILL, SIGFPE,
				       SIGABRT, SIGALRM };
			for (size_t k = 0; k < sizeof sigs / sizeof *sigs; k++)
				signal(sigs[k], SIG_DFL);
			alarm(CHECK_TIMEOUT_S);
			/* the child's stderr goes to a file: plugins log
			 * errors on purpose here, and a sanitizer's report
			 * tells the parent what crashed */
			if (!getenv("CONTRACT_VERBOSE")) {
				int efd = open(errpath, O_WRONLY | O_CREAT |
					       O_TRUNC, 0600);
				if (efd >= 0)
					dup2(efd, 2);
			}
			int bad = child_check(so, hints, c, outdir);
			if (bad && write(fd[1], child_msg, strlen(child_msg))) {
			}
			_exit(bad ? 1 : 0);
		}
		close(fd[1]);
		char msg[2048] = "";
		ssize_t n, tot = 0;
		while ((n = read(fd[0], msg + tot,
				 sizeof msg - 1 - (size_t)tot)) > 0)
			tot += n;
		msg[tot > 0 ? tot : 0] = 0;
		close(fd[0]);
		int status = 0;
		waitpid(pid, &status, 0);
		const char *why = NULL;
		char buf[2300];
		if (WIFSIGNALED(status)) {
			snprintf(buf, sizeof buf, "%s (signal %d)",
				 WTERMSIG(status) == SIGALRM
					 ? "hung: no result within the time "
					   "limit"
					 : "crashed", WTERMSIG(status));
			why = buf;
		} else if (WEXITSTATUS(status)) {
			/* no message of ours: a sanitizer stopped the child */
			char line[512], san[512] = "";
			FILE *ef = fopen(errpath, "r");
			while (ef && fgets(line, sizeof line, ef))
				if (!san[0] && (strstr(line, "ERROR: Address") ||
						strstr(line, "ERROR: Leak") ||
						strstr(line, "runtime error:")))
					snprintf(san, sizeof san, "%s", line);
			if (ef)
				fclose(ef);
			san[strcspn(san, "\n")] = 0;
			if (msg[0])
				snprintf(buf, sizeof buf, "%s", msg);
			else
				snprintf(buf, sizeof buf, "crashed (%s)",
					 san[0] ? san : "exit status without "
					 "a message");
			why = buf;
		}
		unlink(errpath);
		tu_rm_rf(outdir);
		if (why) {
			fails++;
			o += (size_t)snprintf(report + o, o < reportsize
					      ? reportsize - o : 0,
					      "%s: %s\n", checks[c], why);
			if (o >= reportsize)
				o = reportsize - 1;
			if (c == 0)
				break; /* nothing else can run */
		}
	}
	return fails;
}

/* ---- cmocka ---- */

static void test_plugin(void **state)
{
	const char *so = *state;
	char report[8192];
	int fails = contract_run(so, "plugins", report, sizeof report);
	if (fails)
		print_error("%s fails the contract:\n%s", so, report);
	assert_int_equal(fails, 0);
}

static void test_broken_fails(void **state)
{
	(void)state;
	char so[1024], report[8192];
	snprintf(so, sizeof so, "%s/test-plugins/broken.so", tu_build_dir());
	int fails = contract_run(so, NULL, report, sizeof report);
	print_message("broken.so report:\n%s", report);
	assert_true(fails >= 3);
	assert_non_null(strstr(report, "fini-no-init: crashed"));
	assert_non_null(strstr(report, "empty-input: crashed"));
	assert_non_null(strstr(report,
			"inputs-untouched: process modified its input 'points'"));
	assert_null(strstr(report, "load:"));
	assert_null(strstr(report, "params:"));
}

static void test_broken_desc_fails(void **state)
{
	(void)state;
	char so[1024], report[8192];
	snprintf(so, sizeof so, "%s/test-plugins/broken_desc.so", tu_build_dir());
	int fails = contract_run(so, NULL, report, sizeof report);
	print_message("broken_desc.so report:\n%s", report);
	assert_int_equal(fails, 1);
	assert_non_null(strstr(report, "load: "));
	assert_non_null(strstr(report, "broken_desc.so: invalid descriptor: "
			"default of parameter 'spacing': 50 is out of range "
			"[0.5, 20] mm"));
}

static void test_good_test_plugin_passes(void **state)
{
	(void)state;
	char so[1024], report[8192];
	snprintf(so, sizeof so, "%s/test-plugins/tp_add.so", tu_build_dir());
	int fails = contract_run(so, NULL, report, sizeof report);
	if (fails)
		print_error("%s", report);
	assert_int_equal(fails, 0);
}

int main(void)
{
	static char paths[128][1024];
	struct CMUnitTest tests[128 + 3];
	int n = 0;
	char dir[1024];
	snprintf(dir, sizeof dir, "%s/plugins", tu_build_dir());
	DIR *dp = opendir(dir);
	struct dirent *de;
	while (dp && (de = readdir(dp)) && n < 128) {
		size_t l = strlen(de->d_name);
		if (l < 4 || strcmp(de->d_name + l - 3, ".so"))
			continue;
		snprintf(paths[n], sizeof paths[n], "%s/%s", dir, de->d_name);
		tests[n] = (struct CMUnitTest){ .name = paths[n],
			.test_func = test_plugin, .initial_state = paths[n] };
		n++;
	}
	if (dp)
		closedir(dp);
	tests[n++] = (struct CMUnitTest){ .name = "broken plugin is caught",
		.test_func = test_broken_fails };
	tests[n++] = (struct CMUnitTest){ .name = "broken descriptor is caught",
		.test_func = test_broken_desc_fails };
	tests[n++] = (struct CMUnitTest){ .name = "good test plugin passes",
		.test_func = test_good_test_plugin_passes };
	return _cmocka_run_group_tests("contract", tests, (size_t)n, NULL,
				       NULL);
}
