/* SPDX-License-Identifier: MIT */
/*
 * Helpers of the distributed tests (test_remote.c, test_batch.c): start
 * `armstg worker` processes on loopback, stop or kill them, read their
 * logs, compare output folders.
 *
 *   dt_worker_start(&w, "a", extra_args)  a worker on tcp://127.0.0.1:*
 *                                          (w.ep: its endpoint, w.log: its
 *                                          log file), plugins from
 *                                          $BUILD/plugins and
 *                                          $BUILD/test-plugins
 *   dt_worker_start_ipc(&w, "a", extra)    the same on ipc://TMPDIR/a.sock
 *                                          (see there: for tests that kill
 *                                          a worker and ask its endpoint
 *                                          again)
 *   dt_worker_stop(&w)                     SIGTERM and wait (exit status)
 *   dt_worker_kill(&w)                     SIGKILL and wait
 *   dt_log_count(path, needle)             lines of a log holding needle
 *   dt_wait_log(path, needle, seconds)     wait until a line holds needle
 */
#ifndef ARMSTG_DISTUTIL_H
#define ARMSTG_DISTUTIL_H

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <time.h>

#include "testutil.h"

typedef struct dt_worker {
	pid_t pid;
	char name[64];
	char ep[256];
	char log[512];
} dt_worker_t;

static inline double dt_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static inline void dt_sleep(double s)
{
	struct timespec ts = { (time_t)s, (long)((s - (time_t)s) * 1e9) };
	nanosleep(&ts, NULL);
}

/* bind: the worker's --bind; extra: NULL-terminated extra arguments (or
 * NULL).  0 once the worker listens (its --ready-file exists), -1 after
 * 20 s or when it exited. */
static inline int dt_worker_start_at(dt_worker_t *w, const char *name,
				     const char *bind,
				     const char *const *extra)
{
	char exe[512], ready[512], p1[512], p2[512];
	memset(w, 0, sizeof *w);
	snprintf(w->name, sizeof w->name, "%s", name);
	snprintf(exe, sizeof exe, "%s/armstg", tu_build_dir());
	snprintf(ready, sizeof ready, "%s/%s.ep", tu_tmpdir(), name);
	snprintf(w->log, sizeof w->log, "%s/%s.log", tu_tmpdir(), name);
	snprintf(p1, sizeof p1, "%s/plugins", tu_build_dir());
	snprintf(p2, sizeof p2, "%s/test-plugins", tu_build_dir());
	unlink(ready);
	const char *argv[48] = { exe, "worker", "--bind", bind,
				 "--name", name, "--ready-file", ready,
				 "--plugins", p1, "--plugins", p2 };
	int n = 12;
	for (int i = 0; extra && extra[i] && n < 46; i++)
		argv[n++] = extra[i];
	argv[n] = NULL;
	fflush(NULL);
	pid_t pid = fork();
	if (pid < 0)
		return -1;
	if (pid == 0) {
		int fd = open(w->log, O_WRONLY | O_CREAT | O_APPEND, 0644);
		if (fd >= 0) {
			dup2(fd, 1);
			dup2(fd, 2);
			close(fd);
		}
		execv(exe, (char *const *)argv);
		_exit(127);
	}
	w->pid = pid;
	for (double t0 = dt_now(); dt_now() - t0 < 20;) {
		FILE *f = fopen(ready, "r");
		if (f) {
			int ok = fgets(w->ep, sizeof w->ep, f) != NULL;
			fclose(f);
			w->ep[strcspn(w->ep, "\n")] = 0;
			if (ok && w->ep[0])
				return 0;
		}
		int st;
		if (waitpid(pid, &st, WNOHANG) == pid) {
			w->pid = 0;
			return -1;
		}
		dt_sleep(0.02);
	}
	return -1;
}

static inline int dt_worker_start(dt_worker_t *w, const char *name,
				  const char *const *extra)
{
	return dt_worker_start_at(w, name, "tcp://127.0.0.1:*", extra);
}

/* A worker on ipc://TMPDIR/NAME.sock, an endpoint of this test program
 * only.  A tcp://127.0.0.1:* port is czmq's first free one from 49152 up:
 * once a worker there is killed, the next `:*` bind on the host (another
 * test program's worker, another make test beside this one) gets that
 * port, and its worker answers for the killed one.  Tests that kill a
 * worker and then count on its endpoint staying silent use this. */
static inline int dt_worker_start_ipc(dt_worker_t *w, const char *name,
				      const char *const *extra)
{
	char bind[512];
	snprintf(bind, sizeof bind, "ipc://%s/%s.sock", tu_tmpdir(), name);
	return dt_worker_start_at(w, name, bind, extra);
}

/* exit status of the worker after SIGTERM (-1: it did not stop in 20 s,
 * then it was killed) */
static inline int dt_worker_stop(dt_worker_t *w)
{
	if (w->pid <= 0)
		return -1;
	kill(w->pid, SIGTERM);
	int st = 0;
	for (double t0 = dt_now(); dt_now() - t0 < 20; dt_sleep(0.02))
		if (waitpid(w->pid, &st, WNOHANG) == w->pid) {
			w->pid = 0;
			return WIFEXITED(st) ? WEXITSTATUS(st) : 128;
		}
	kill(w->pid, SIGKILL);
	waitpid(w->pid, &st, 0);
	w->pid = 0;
	return -1;
}

static inline void dt_worker_kill(dt_worker_t *w)
{
	if (w->pid <= 0)
		return;
	kill(w->pid, SIGKILL);
	int st;
	waitpid(w->pid, &st, 0);
	w->pid = 0;
}

/* 1 while the worker process runs */
static inline int dt_worker_alive(dt_worker_t *w)
{
	int st;
	return w->pid > 0 && waitpid(w->pid, &st, WNOHANG) == 0;
}

static inline int dt_log_count(const char *path, const char *needle)
{
	FILE *f = fopen(path, "r");
	char line[4096];
	int n = 0;
	if (!f)
		return 0;
	while (fgets(line, sizeof line, f))
		n += strstr(line, needle) != NULL;
	fclose(f);
	return n;
}

static inline int dt_wait_log(const char *path, const char *needle,
			      double seconds)
{
	for (double t0 = dt_now(); dt_now() - t0 < seconds; dt_sleep(0.02))
		if (dt_log_count(path, needle))
			return 1;
	return 0;
}

/* print a log (cmocka shows it with a failing test) */
static inline void dt_print_log(const char *path)
{
	FILE *f = fopen(path, "r");
	char line[4096];
	if (!f)
		return;
	print_message("---- %s\n", path);
	while (fgets(line, sizeof line, f))
		print_message("%s", line);
	fclose(f);
}

/* the bytes of two files are equal (1), differ or are missing (0) */
static inline int dt_same_file(const char *a, const char *b)
{
	FILE *fa = fopen(a, "rb"), *fb = fopen(b, "rb");
	int same = fa && fb;
	while (same) {
		int ca = fgetc(fa), cb = fgetc(fb);
		if (ca != cb)
			same = 0;
		if (ca == EOF || cb == EOF)
			break;
	}
	if (fa)
		fclose(fa);
	if (fb)
		fclose(fb);
	return same;
}

/* number of bytes of a file (-1 when missing) */
static inline long dt_file_size(const char *p)
{
	struct stat st;
	return stat(p, &st) ? -1 : (long)st.st_size;
}

#endif
