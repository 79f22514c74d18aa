/* SPDX-License-Identifier: MIT */
/*
 * Remote stages, the coordinator's side (remote.c): the [node] sections
 * of a graph (remote_node_set: endpoint, fallback, server_key, client_key,
 * timeout, threads; remote_node_check: an endpoint at least, CURVE's keys
 * off this host, the key files readable), what a request may carry
 * (remote_param_ok: no path outside the stage's folder) and which stages
 * a batch may send (remote_batch_eligible), and a run's call context.
 */
#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "remote_int.h"

/* ------------------------------------------------------------------ */
/* [node] sections                                                     */

void remote_node_init(remote_node_t *n, const char *name)
{
	memset(n, 0, sizeof *n);
	snprintf(n->name, sizeof n->name, "%s", name);
	n->timeout_s = REMOTE_DEFAULT_TIMEOUT_S;
}

static int ep_syntax(const char *ep)
{
	if (!strncmp(ep, "ipc://", 6) || !strncmp(ep, "inproc://", 9))
		return ep[strncmp(ep, "ipc://", 6) ? 9 : 6] != 0;
	if (strncmp(ep, "tcp://", 6))
		return 0;
	const char *colon = strrchr(ep + 6, ':');
	if (!colon || colon == ep + 6 || !colon[1])
		return 0;
	for (const char *p = colon + 1; *p; p++)
		if (!isdigit((unsigned char)*p) && !(p == colon + 1 &&
						      *p == '*' && !p[1]))
			return 0;
	return 1;
}

int remote_endpoint_local(const char *ep)
{
	if (!strncmp(ep, "ipc://", 6) || !strncmp(ep, "inproc://", 9))
		return 1;
	if (strncmp(ep, "tcp://", 6))
		return 0;
	const char *h = ep + 6;
	const char *semi = strchr(h, ';'); /* tcp://src;dst */
	if (semi)
		h = semi + 1;
	return !strncmp(h, "127.", 4) || !strncmp(h, "localhost:", 10) ||
	       !strncmp(h, "[::1]:", 6);
}

static int add_ep(remote_node_t *n, const char *ep, char *err, size_t errsize)
{
	if (!ep_syntax(ep)) {
		snprintf(err, errsize, "'%s' is not a ZeroMQ endpoint "
			 "(tcp://HOST:PORT, ipc://PATH)", ep);
		return ARMSTG_EINVAL;
	}
	if (strchr(ep, '*')) {
		snprintf(err, errsize, "'%s': a worker's endpoint needs its "
			 "port number", ep);
		return ARMSTG_EINVAL;
	}
	for (int i = 0; i < n->nep; i++)
		if (!strcmp(n->ep[i], ep)) {
			snprintf(err, errsize, "endpoint '%s' listed twice", ep);
			return ARMSTG_EINVAL;
		}
	if (n->nep >= REMOTE_MAX_EP || strlen(ep) >= sizeof n->ep[0]) {
		snprintf(err, errsize, "too many or too long endpoints (at most "
			 "%d of %zu characters)", REMOTE_MAX_EP,
			 sizeof n->ep[0] - 1);
		return ARMSTG_EINVAL;
	}
	snprintf(n->ep[n->nep++], sizeof n->ep[0], "%s", ep);
	return 0;
}

/* comma- or blank-separated endpoints */
static int add_list(remote_node_t *n, const char *val, char *err,
		    size_t errsize)
{
	char buf[4096];
	snprintf(buf, sizeof buf, "%s", val);
	int any = 0;
	for (char *sv = NULL, *t = strtok_r(buf, ", \t", &sv); t;
	     t = strtok_r(NULL, ", \t", &sv)) {
		int rc = add_ep(n, t, err, errsize);
		if (rc)
			return rc;
		any = 1;
	}
	if (!any) {
		snprintf(err, errsize, "no endpoint in '%s'", val);
		return ARMSTG_EINVAL;
	}
	return 0;
}

int remote_node_set(remote_node_t *n, const char *key, const char *val,
		    char *err, size_t errsize)
{
	if (!strcmp(key, "endpoint")) {
		/* the first endpoint, whatever order the keys came in */
		remote_node_t tmp = *n;
		tmp.nep = 0;
		int rc = add_ep(&tmp, val, err, errsize);
		if (rc)
			return rc;
		for (int i = 0; i < n->nep; i++)
			if ((rc = add_ep(&tmp, n->ep[i], err, errsize)))
				return rc;
		*n = tmp;
		return 0;
	}
	if (!strcmp(key, "fallback"))
		return add_list(n, val, err, errsize);
	if (!strcmp(key, "server_key") || !strcmp(key, "client_key")) {
		char *dst = key[0] == 's' ? n->server_key : n->client_key;
		if (strlen(val) >= PATH_MAX) {
			snprintf(err, errsize, "path too long");
			return ARMSTG_EINVAL;
		}
		snprintf(dst, PATH_MAX, "%s", val);
		return 0;
	}
	if (!strcmp(key, "timeout")) {
		char *end;
		double t = strtod(val, &end);
		if (end == val || *end || !(t >= 0.2 && t <= 86400)) {
			snprintf(err, errsize, "timeout must be seconds in "
				 "[0.2, 86400], got '%s'", val);
			return ARMSTG_EINVAL;
		}
		n->timeout_s = t;
		return 0;
	}
	if (!strcmp(key, "threads")) {
		char *end;
		long t = strtol(val, &end, 10);
		if (end == val || *end || t < 1 || t > 1024) {
			snprintf(err, errsize, "threads must be 1..1024, got "
				 "'%s'", val);
			return ARMSTG_EINVAL;
		}
		n->threads = (int)t;
		return 0;
	}
	snprintf(err, errsize, "unknown key in [node %s] (known: endpoint, "
		 "fallback, server_key, client_key, timeout, threads)",
		 n->name);
	return ARMSTG_EINVAL;
}

/* zcert_load of a file we were told to use; the error names it */
zcert_t *remote_load_cert(const char *path, int need_secret, char *err,
			  size_t errsize)
{
	struct stat st;
	if (stat(path, &st)) {
		snprintf(err, errsize, "cannot read key file '%s': %s", path,
			 strerror(errno));
		return NULL;
	}
	remote_zsys_init();
	zcert_t *c = zcert_load(path);
	if (!c) {
		snprintf(err, errsize, "'%s' is not a ZeroMQ certificate "
			 "(make one with 'armstg keygen')", path);
		return NULL;
	}
	if (need_secret && !strcmp(zcert_secret_txt(c),
				   "0000000000000000000000000000000000000000")) {
		snprintf(err, errsize, "'%s' holds no secret key (give the "
			 "certificate whose '%s_secret' file is beside it, or "
			 "that file)", path, path);
		zcert_destroy(&c);
		return NULL;
	}
	return c;
}

int remote_node_check(const remote_node_t *n, char *err, size_t errsize)
{
	if (!n->nep) {
		snprintf(err, errsize, "node '%s' has no endpoint", n->name);
		return ARMSTG_EINVAL;
	}
	if (!n->server_key[0] != !n->client_key[0]) {
		snprintf(err, errsize, "node '%s': CURVE needs both server_key "
			 "(the workers' public certificate) and client_key "
			 "(ours)", n->name);
		return ARMSTG_EINVAL;
	}
	if (!n->server_key[0]) {
		for (int i = 0; i < n->nep; i++)
			if (!remote_endpoint_local(n->ep[i])) {
				snprintf(err, errsize, "node '%s': endpoint "
					 "'%s' is off this host: give "
					 "server_key and client_key (CURVE; "
					 "'armstg keygen', README)", n->name,
					 n->ep[i]);
				return ARMSTG_EINVAL;
			}
		return 0;
	}
	char e[1024] = "";
	zcert_t *s = remote_load_cert(n->server_key, 0, e, sizeof e);
	zcert_t *c = s ? remote_load_cert(n->client_key, 1, e, sizeof e)
		      : NULL;
	int ok = s && c;
	zcert_destroy(&s);
	zcert_destroy(&c);
	if (!ok) {
		snprintf(err, errsize, "node '%s': %s", n->name, e);
		return ARMSTG_EINVAL;
	}
	return 0;
}

int remote_param_ok(const char *v)
{
	/* a request can never make the worker read or write outside the
	 * stage's folder */
	if (v[0] == '/')
		return 0;
	for (const char *p = v; (p = strstr(p, "..")); p += 2)
		if ((p == v || p[-1] == '/' || p[-1] == ',' || p[-1] == ' ') &&
		    (!p[2] || p[2] == '/' || p[2] == ',' || p[2] == ' '))
			return 0;
	return 1;
}

int remote_batch_eligible(const armstg_plugin_t *d)
{
	if (d->n_outputs == 0)
		return 0;
	for (int i = 0; i < d->n_params; i++)
		if (!strcmp(d->params[i].name, "path"))
			return 0;
	return 1;
}

void remote_ctx_init(remote_ctx_t *c)
{
	memset(c, 0, sizeof *c);
	pthread_mutex_init(&c->mu, NULL);
}

void remote_ctx_destroy(remote_ctx_t *c)
{
	pthread_mutex_destroy(&c->mu);
}
