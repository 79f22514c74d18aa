/* SPDX-License-Identifier: MIT */
/*
 * armstg batch (runtime/batch.c) on this host: tests/graphs/batch_case.ini
 * (a 32x32x24 phantom at 6 mm, demons, the labels through the field) over
 * real `armstg worker` processes on ipc:// endpoints in the test's own
 * folder (dt_worker_start_ipc): a killed worker's tcp://127.0.0.1:* port
 * went to the next worker another program on the host started, which then
 * answered the coordinator for the killed one (test_batch failed 4 of 20
 * runs with a second test_batch beside it, 2026-11-27).
 *
 *   - 20 cases (phantom seeds 1-20) over 4 workers, two of them SIGKILLed
 *     while they run a case's phantom: all 20 cases finish, their NIfTI
 *     files are the bytes of 20 sequential local runs, batch.tsv lists the
 *     20 cases as ok and says which were retried (the stage and the dead
 *     worker -> the new one), the progress lines end at 20/20 with 2 of 4
 *     workers up
 *   - a case that fails in its plugin (a mass effect out of reach) is
 *     reported with its error, the other cases run, exit status 1
 *   - a case whose graph does not load stops the batch before anything
 *     runs (exit status 2, the case and line named)
 */
#include "distutil.h"
#include "graph.h"

#define NCASES 20
#define GRAPH "tests/graphs/batch_case.ini"

static char local_dir[600];

static int setup(void **state)
{
	(void)state;
	char pp[1024];
	snprintf(pp, sizeof pp, "%s/plugins", tu_build_dir());
	setenv("ARMSTG_PLUGIN_PATH", pp, 1);
	if (tu_tmpdir_make("batch"))
		return -1;
	snprintf(local_dir, sizeof local_dir, "%s/local", tu_tmpdir());
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	tu_tmpdir_remove();
	return 0;
}

/* run armstg batch with args (NULL-terminated after the command), its
 * output in log; the child's pid */
static pid_t spawn_batch(const char *const *args, const char *log)
{
	char exe[512];
	snprintf(exe, sizeof exe, "%s/armstg", tu_build_dir());
	const char *argv[40] = { exe, "batch" };
	int n = 2;
	for (int i = 0; args[i] && n < 39; i++)
		argv[n++] = args[i];
	argv[n] = NULL;
	fflush(NULL);
	pid_t pid = fork();
	if (pid == 0) {
		int fd = open(log, O_WRONLY | O_CREAT | O_TRUNC, 0644);
		if (fd >= 0) {
			dup2(fd, 1);
			dup2(fd, 2);
			close(fd);
		}
		execv(exe, (char *const *)argv);
		_exit(127);
	}
	return pid;
}

static int wait_exit(pid_t pid, double seconds)
{
	int st;
	for (double t0 = dt_now(); dt_now() - t0 < seconds; dt_sleep(0.05))
		if (waitpid(pid, &st, WNOHANG) == pid)
			return WIFEXITED(st) ? WEXITSTATUS(st) : 128;
	kill(pid, SIGKILL);
	waitpid(pid, &st, 0);
	return -1;
}

/* the row of a case in batch.tsv: status and retried columns */
static int row(const char *tsv, const char *name, char *status, char *retried,
	       char *error)
{
	FILE *f = fopen(tsv, "r");
	char line[8192];
	int found = 0;
	while (f && !found && fgets(line, sizeof line, f)) {
		line[strcspn(line, "\n")] = 0;
		char *col[6];
		int n = 0;
		for (char *p = line; n < 6;) {
			col[n++] = p;
			char *t = strchr(p, '\t');
			if (!t)
				break;
			*t = 0;
			p = t + 1;
		}
		if (n == 6 && !strcmp(col[0], name)) {
			strcpy(status, col[1]);
			strcpy(retried, col[4]);
			strcpy(error, col[5]);
			found = 1;
		}
	}
	if (f)
		fclose(f);
	return found;
}

static void write_cases(const char *path, int n, const char *extra_row)
{
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fprintf(f, "# seeds of the phantom\ncase\tPHANTOM_SEED\tMASS_EFFECT\n");
	for (int i = 1; i <= n; i++)
		fprintf(f, "p%02d\t%d\t\n", i, i);
	if (extra_row)
		fputs(extra_row, f);
	assert_int_equal(fclose(f), 0);
}

static void test_batch_with_two_workers_killed(void **state)
{
	(void)state;
	/* the reference: every case run here, one after the other */
	double t0 = dt_now();
	for (int i = 1; i <= NCASES; i++) {
		char var[32], out[700], err[4096];
		snprintf(var, sizeof var, "PHANTOM_SEED=%d", i);
		const char *vars[] = { var };
		snprintf(out, sizeof out, "%s/p%02d", local_dir, i);
		graph_t *g = graph_load_vars(GRAPH, NULL, 0, vars, 1, err,
					     sizeof err);
		if (!g)
			fail_msg("%s", err);
		run_opts_t o = { .outdir = out, .jobs = 1, .quiet = 1 };
		int rc = graph_run(g, &o, err, sizeof err);
		if (rc)
			fail_msg("local p%02d: %s", i, err);
		graph_free(g);
	}
	print_message("%d local runs: %.1f s\n", NCASES, dt_now() - t0);

	dt_worker_t w[4];
	const char *vv[] = { "-v", "-v", NULL };
	char eps[1200] = "";
	for (int i = 0; i < 4; i++) {
		char name[16];
		snprintf(name, sizeof name, "bw%d", i + 1);
		assert_int_equal(dt_worker_start_ipc(&w[i], name, vv), 0);
		snprintf(eps + strlen(eps), sizeof eps - strlen(eps), "%s%s",
			 i ? "," : "", w[i].ep);
	}
	char cases[600], out[600], log[600];
	snprintf(cases, sizeof cases, "%s/cases.tsv", tu_tmpdir());
	snprintf(out, sizeof out, "%s/batch", tu_tmpdir());
	snprintf(log, sizeof log, "%s/batch.log", tu_tmpdir());
	write_cases(cases, NCASES, NULL);
	const char *args[] = { GRAPH, "--cases", cases, "--workers", eps,
			       "--out", out, "--timeout", "2", "--progress",
			       "1", NULL };
	t0 = dt_now();
	pid_t pid = spawn_batch(args, log);
	/* kill bw1 when it starts its second case's phantom, bw3 its third:
	 * the case still has stages to run there, so they must move */
	int k1 = 0, k3 = 0;
	for (double tk = dt_now(); (!k1 || !k3) && dt_now() - tk < 120;
	     dt_sleep(0.01)) {
		if (!k1 && dt_log_count(w[0].log, "start stage 'phantom'") >= 2) {
			dt_worker_kill(&w[0]);
			k1 = 1;
		}
		if (!k3 && dt_log_count(w[2].log, "start stage 'phantom'") >= 3) {
			dt_worker_kill(&w[2]);
			k3 = 1;
		}
		int st;
		if (waitpid(pid, &st, WNOHANG) == pid) {
			pid = 0;
			break;
		}
	}
	int code = pid ? wait_exit(pid, 180) : 0;
	print_message("batch: %.1f s, exit %d\n", dt_now() - t0, code);
	for (int i = 0; i < 4; i++)
		if (dt_worker_alive(&w[i]))
			assert_int_equal(dt_worker_stop(&w[i]), 0);
	dt_print_log(log);
	assert_true(k1 && k3);
	assert_int_equal(code, 0);
	char tsv[700];
	snprintf(tsv, sizeof tsv, "%s/batch.tsv", out);
	int nretried = 0;
	for (int i = 1; i <= NCASES; i++) {
		char name[16], status[64], retried[1200], error[4096];
		snprintf(name, sizeof name, "p%02d", i);
		assert_true(row(tsv, name, status, retried, error));
		assert_string_equal(status, "ok");
		assert_string_equal(error, "-");
		if (strcmp(retried, "-")) {
			nretried++;
			/* "stage: dead worker -> new worker" */
			if (!strstr(retried, w[0].ep) && !strstr(retried, w[2].ep))
				fail_msg("%s retried from a live worker: %s",
					 name, retried);
			assert_non_null(strstr(retried, " -> "));
		}
		static const char *files[] = { "labels.nii.gz", "field.nii.gz" };
		for (int k = 0; k < 2; k++) {
			char a[800], b[800];
			snprintf(a, sizeof a, "%s/%s/%s", local_dir, name,
				 files[k]);
			snprintf(b, sizeof b, "%s/%s/%s", out, name, files[k]);
			assert_true(dt_file_size(a) > 0);
			if (!dt_same_file(a, b))
				fail_msg("%s/%s differs from the local run",
					 name, files[k]);
		}
	}
	print_message("%d cases retried on another worker\n", nretried);
	assert_true(nretried >= 2);
	assert_true(dt_log_count(log, "20/20 finished (20 ok, 0 failed)") >= 1);
	assert_true(dt_log_count(log, "2/4 workers up") >= 1);
	/* the killed workers never wrote their case's stage line: whatever
	 * they ran was redone */
	assert_int_equal(dt_log_count(log, "its slot stops"), 2);
}

static void test_batch_failed_case(void **state)
{
	(void)state;
	dt_worker_t w;
	assert_int_equal(dt_worker_start_ipc(&w, "bf", NULL), 0);
	char cases[600], out[600], log[600];
	snprintf(cases, sizeof cases, "%s/cases2.tsv", tu_tmpdir());
	snprintf(out, sizeof out, "%s/batch2", tu_tmpdir());
	snprintf(log, sizeof log, "%s/batch2.log", tu_tmpdir());
	write_cases(cases, 2, "toofar\t3\t15\n");
	const char *args[] = { GRAPH, "--cases", cases, "--workers", w.ep,
			       "--out", out, NULL };
	int code = wait_exit(spawn_batch(args, log), 120);
	assert_int_equal(dt_worker_stop(&w), 0);
	dt_print_log(log);
	assert_int_equal(code, 1);
	char tsv[700], status[64], retried[1200], error[4096];
	snprintf(tsv, sizeof tsv, "%s/batch.tsv", out);
	assert_true(row(tsv, "toofar", status, retried, error));
	assert_string_equal(status, "failed");
	assert_non_null(strstr(error, "stage 'phantom' (plugin phantom) "
				      "failed: mass_effect 15.00 mm"));
	assert_true(row(tsv, "p01", status, retried, error));
	assert_string_equal(status, "ok");
	assert_true(row(tsv, "p02", status, retried, error));
	assert_string_equal(status, "ok");
	/* the failed case left no NIfTI behind */
	char p[800];
	snprintf(p, sizeof p, "%s/toofar/labels.nii.gz", out);
	assert_false(tu_exists(p));
}

static void test_batch_bad_case(void **state)
{
	(void)state;
	char cases[600], out[600], log[600];
	snprintf(cases, sizeof cases, "%s/cases3.tsv", tu_tmpdir());
	snprintf(out, sizeof out, "%s/batch3", tu_tmpdir());
	snprintf(log, sizeof log, "%s/batch3.log", tu_tmpdir());
	write_cases(cases, 1, "negative\t-4\t\n");
	/* nothing listens there: the batch must stop before asking */
	const char *args[] = { GRAPH, "--cases", cases, "--workers",
			       "tcp://127.0.0.1:1", "--out", out, NULL };
	double t0 = dt_now();
	int code = wait_exit(spawn_batch(args, log), 60);
	dt_print_log(log);
	assert_int_equal(code, 2);
	assert_true(dt_now() - t0 < 5);
	char want[800];
	snprintf(want, sizeof want, "case 'negative' (%s:4)", cases);
	assert_int_equal(dt_log_count(log, want), 1);
	assert_int_equal(dt_log_count(log, "key 'seed': parameter 'seed': -4 "
					   "is out of range"), 1);
	assert_int_equal(dt_log_count(log, "1 of 2 cases do not load"), 1);
	assert_false(tu_exists(out));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_batch_bad_case),
		cmocka_unit_test(test_batch_failed_case),
		cmocka_unit_test(test_batch_with_two_workers_killed),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
