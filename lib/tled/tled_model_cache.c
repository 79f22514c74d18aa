/* SPDX-License-Identifier: MIT */
/*
 * The last growth model kept for the next growth of the same inputs
 * (tled_model.h, "Model reuse").  A [tune] search of the push depth grows
 * the same nodes with the same parameters once per depth; the model (the
 * supports, the MLS shape functions and their consistency correction)
 * does not depend on the depth, and its build was 2.9 s of a 9.1 s growth
 * at 3 mm nodes on the GPU host (bench/tled/results.md).  One entry, the
 * last model handed back; a mutex makes take/keep safe from concurrent
 * stages.  What a growth changes in the model (the nodes' labels and
 * kinds, the points' materials and growth stretches) is put back as it
 * was built before the model is kept, so a model taken from here hashes
 * as the fresh build (tled_model_hash; lib/tled/tests/test_core.c).
 */
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "tled_model.h"

typedef struct {
	int valid;
	uint64_t key;
	tled_model_t m;
	tled_model_snap_t snap;
} cache_t;

static cache_t g_cache;
static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
static uint64_t g_hits; /* models taken (tled_model_cache_hits) */

/* ---------------------------------------------------------------- hashing */

uint64_t tled_hash_bytes(uint64_t h, const void *p, size_t n)
{
	/* FNV-1a, 64 bits */
	const unsigned char *b = p;
	if (!p)
		n = 0;
	for (size_t i = 0; i < n; i++) {
		h ^= b[i];
		h *= UINT64_C(1099511628211);
	}
	/* the length too: NULL and empty differ from absent trailing data */
	for (int i = 0; i < 8; i++) {
		h ^= (unsigned char)(n >> (8 * i));
		h *= UINT64_C(1099511628211);
	}
	return h;
}

uint64_t tled_model_hash(const tled_model_t *m)
{
	uint64_t h = TLED_HASH_INIT;
	int64_t n = m->n, nip = m->nip;
	int64_t ne = m->ipptr ? m->ipptr[nip] : 0;
	int64_t nr = m->rk > 0 ? n * m->rk : 0;
#define HA(p, cnt) h = tled_hash_bytes(h, (p), (p) ? (size_t)(cnt) * sizeof *(p) : 0)
	HA(m->X, 3 * n);
	HA(m->label, n);
	HA(m->kind, n);
	HA(m->mass, n);
	HA(m->nn_dist, n);
	HA(m->rep, m->n_in);
	HA(m->ipX, 3 * nip);
	HA(m->ipV, nip);
	HA(m->ipmat, nip);
	HA(m->ipg, nip);
	HA(m->ipptr, nip + 1);
	HA(m->ipnode, ne);
	HA(m->entip, ne);
	HA(m->N, ne);
	HA(m->dN, 3 * ne);
	HA(m->nptr, n + 1);
	HA(m->nent, ne);
	HA(m->gdN, 3 * ne);
	HA(m->gip, ne);
	HA(m->ipn32, ne);
	HA(m->gip32, ne);
	HA(m->fb_loc, ne);
	HA(m->fb_ptr, m->fb_ptr ? m->fb_n + 1 : 0);
	HA(m->fs_ptr, n + 1);
	HA(m->fs_slot, m->fs_ptr ? m->fs_ptr[n] : 0);
	HA(m->bnode, m->nb);
	HA(m->bX, 3 * m->nb);
	HA(m->bn, 3 * m->nb);
	HA(m->rid, nr);
	HA(m->rN, nr);
	HA(m->bt, 3 * m->nb);
	HA(m->Ra, n);
#undef HA
	double sc[] = { m->h_min, m->h_mean, m->ip_h, m->dt_wave, m->Ra_max,
			(double)m->n_merged, (double)m->Kn, (double)m->ebc,
			(double)m->ebc_fixed, (double)m->support_nodal,
			(double)m->rk, (double)m->fb_n, (double)m->fb_size };
	h = tled_hash_bytes(h, sc, sizeof sc);
	for (int i = 0; i < MAT_N; i++) {
		const tled_material_t *t = &m->mat[i];
		double mv[] = { t->E, t->nu, t->rho, t->mu, t->kappa,
				t->lambda, t->c, (double)t->vol };
		h = tled_hash_bytes(h, mv, sizeof mv);
	}
	return h;
}

uint64_t tled_model_opts_hash(uint64_t h, const tled_model_opts_t *o)
{
	/* every setting of the build; the callbacks and their contexts are
	 * the caller's to hash (what they read), the thread count is left
	 * out: the build is the same bits on any count (test_core) */
	double d[] = { (double)o->support_k, o->support_dilation, o->ip_factor,
		       o->merge_tol, (double)o->corr, (double)o->corr_coarse,
		       (double)o->ebc, (double)o->ebc_fixed,
		       (double)o->support_nodal, (double)o->geometry_only,
		       o->inside ? 1.0 : 0.0, o->material ? 1.0 : 0.0 };
	h = tled_hash_bytes(h, d, sizeof d);
	for (int i = 0; i < MAT_N; i++) {
		const tled_material_t *t = &o->mat[i];
		double mv[] = { t->E, t->nu, t->rho, (double)t->vol };
		h = tled_hash_bytes(h, mv, sizeof mv);
	}
	return h;
}

/* ------------------------------------------------------------ snapshots */

int tled_model_snap(tled_model_snap_t *s, const tled_model_t *m)
{
	memset(s, 0, sizeof *s);
	s->n = m->n;
	s->nip = m->nip;
	s->label = malloc((size_t)(m->n > 0 ? m->n : 1) * sizeof *s->label);
	s->kind = malloc((size_t)(m->n > 0 ? m->n : 1) * sizeof *s->kind);
	s->ipmat = malloc((size_t)(m->nip > 0 ? m->nip : 1) * sizeof *s->ipmat);
	if (!s->label || !s->kind || !s->ipmat) {
		tled_model_snap_free(s);
		return -1;
	}
	memcpy(s->label, m->label, (size_t)m->n * sizeof *s->label);
	memcpy(s->kind, m->kind, (size_t)m->n * sizeof *s->kind);
	memcpy(s->ipmat, m->ipmat, (size_t)m->nip * sizeof *s->ipmat);
	s->valid = 1;
	return 0;
}

void tled_model_snap_free(tled_model_snap_t *s)
{
	free(s->label);
	free(s->kind);
	free(s->ipmat);
	memset(s, 0, sizeof *s);
}

/* the model as it was built: the snapshot's arrays back, no growth
 * stretch (NULL at build), a new build number (a backend holding a copy of
 * the changed model uploads again) */
static void snap_restore(tled_model_t *m, const tled_model_snap_t *s)
{
	memcpy(m->label, s->label, (size_t)m->n * sizeof *m->label);
	memcpy(m->kind, s->kind, (size_t)m->n * sizeof *m->kind);
	memcpy(m->ipmat, s->ipmat, (size_t)m->nip * sizeof *m->ipmat);
	free(m->ipg);
	m->ipg = NULL;
	m->gen = tled_model_next_gen();
}

/* ---------------------------------------------------------------- cache */

int tled_model_cache_take(uint64_t key, tled_model_t *m, tled_model_snap_t *s)
{
	int hit = 0;
	pthread_mutex_lock(&g_lock);
	if (g_cache.valid && g_cache.key == key) {
		*m = g_cache.m;
		*s = g_cache.snap;
		memset(&g_cache, 0, sizeof g_cache);
		m->gen = tled_model_next_gen();
		g_hits++;
		hit = 1;
	}
	pthread_mutex_unlock(&g_lock);
	return hit;
}

void tled_model_cache_keep(uint64_t key, tled_model_t *m, tled_model_snap_t *s)
{
	if (!s->valid || s->n != m->n || s->nip != m->nip) {
		tled_model_free(m);
		tled_model_snap_free(s);
		return;
	}
	snap_restore(m, s);
	cache_t old;
	pthread_mutex_lock(&g_lock);
	old = g_cache;
	g_cache.valid = 1;
	g_cache.key = key;
	g_cache.m = *m;
	g_cache.snap = *s;
	pthread_mutex_unlock(&g_lock);
	memset(m, 0, sizeof *m);
	memset(s, 0, sizeof *s);
	if (old.valid) {
		tled_model_free(&old.m);
		tled_model_snap_free(&old.snap);
	}
}

uint64_t tled_model_cache_hits(void)
{
	pthread_mutex_lock(&g_lock);
	uint64_t n = g_hits;
	pthread_mutex_unlock(&g_lock);
	return n;
}

void tled_model_cache_clear(void)
{
	cache_t old;
	pthread_mutex_lock(&g_lock);
	old = g_cache;
	memset(&g_cache, 0, sizeof g_cache);
	pthread_mutex_unlock(&g_lock);
	if (old.valid) {
		tled_model_free(&old.m);
		tled_model_snap_free(&old.snap);
	}
}

/* the plugin's shared object unloaded (dlclose) or the process ends */
__attribute__((destructor)) static void cache_fini(void)
{
	tled_model_cache_clear();
}
