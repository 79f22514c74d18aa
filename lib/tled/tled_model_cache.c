/* SPDX-License-Identifier: MIT */
/*
 * The growth model kept for the next growths of the same inputs
 * (tled_model.h, "Model reuse").  A [tune] search of the push depth grows
 * the same nodes with the same parameters once per depth; the model (the
 * supports, the MLS shape functions and their consistency correction)
 * does not depend on the depth, and its build was 2.3-3.3 s of each
 * growth at 3 mm nodes on the GPU host (bench/pipeline/results.md, "The
 * growth's model built once per search").
 *
 * One entry: a copy of the last model published, as it was built (the
 * growths change their own copies: labels, kinds, materials).  A growth
 * asks for it (tled_model_cache_get): a copy when the key matches; when
 * another growth of this process is building the model of that key (the
 * [tune] candidates run in parallel, runtime/tune_par.c), it waits for it;
 * otherwise it builds the model itself and publishes it
 * (tled_model_cache_put), or gives the build up (tled_model_cache_abandon)
 * so that a waiting one builds it.  A mutex and a condition variable;
 * the copies are made under the mutex (about 350 MB of arrays at 3.6 M
 * support entries).
 */
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "tled_model.h"

typedef struct {
	int valid;
	uint64_t key;
	tled_model_t m;
	double ip_factor;
	int pending;          /* a growth is building pending_key's model */
	uint64_t pending_key;
	uint64_t hits;        /* copies handed out (tled_model_cache_hits) */
} cache_t;

static cache_t g_cache;
static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t g_cv = PTHREAD_COND_INITIALIZER;

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

/* every array of a model with its length (the order of tled_model.h),
 * for the hash and the copy; the fused forces' blocks and the boundary
 * grid are derived (rebuilt by the copy), their scratch is not state */
#define TLED_MODEL_ARRAYS(X_)                                                \
	X_(X, 3 * n)                                                         \
	X_(label, n)                                                         \
	X_(kind, n)                                                          \
	X_(mass, n)                                                          \
	X_(nn_dist, n)                                                       \
	X_(rep, m->n_in)                                                     \
	X_(ipX, 3 * nip)                                                     \
	X_(ipV, nip)                                                         \
	X_(ipmat, nip)                                                       \
	X_(ipg, nip)                                                         \
	X_(ipptr, nip + 1)                                                   \
	X_(ipnode, ne)                                                       \
	X_(entip, ne)                                                        \
	X_(N, ne)                                                            \
	X_(dN, 3 * ne)                                                       \
	X_(nptr, n + 1)                                                      \
	X_(nent, ne)                                                         \
	X_(gdN, 3 * ne)                                                      \
	X_(gip, ne)                                                          \
	X_(ipn32, ne)                                                        \
	X_(gip32, ne)                                                        \
	X_(bnode, m->nb)                                                     \
	X_(bX, 3 * m->nb)                                                    \
	X_(bn, 3 * m->nb)                                                    \
	X_(rid, nr)                                                          \
	X_(rN, nr)                                                           \
	X_(bt, 3 * m->nb)                                                    \
	X_(Ra, n)

uint64_t tled_model_hash(const tled_model_t *m)
{
	uint64_t h = TLED_HASH_INIT;
	int64_t n = m->n, nip = m->nip;
	int64_t ne = m->ipptr ? m->ipptr[nip] : 0;
	int64_t nr = m->rk > 0 ? n * m->rk : 0;
#define HA(f, cnt)                                                           \
	h = tled_hash_bytes(h, m->f, m->f ? (size_t)(cnt) * sizeof *m->f : 0);
	TLED_MODEL_ARRAYS(HA)
#undef HA
	h = tled_hash_bytes(h, m->fb_loc, m->fb_loc ? (size_t)ne * sizeof *m->fb_loc : 0);
	h = tled_hash_bytes(h, m->fb_ptr, m->fb_ptr ? (size_t)(m->fb_n + 1) * sizeof *m->fb_ptr : 0);
	h = tled_hash_bytes(h, m->fs_ptr, m->fs_ptr ? (size_t)(n + 1) * sizeof *m->fs_ptr : 0);
	h = tled_hash_bytes(h, m->fs_slot, m->fs_ptr && m->fs_slot ?
			    (size_t)m->fs_ptr[n] * sizeof *m->fs_slot : 0);
	double sc[] = { m->h_min, m->h_mean, m->ip_h, m->dt_wave, m->Ra_max,
			(double)m->n_merged, (double)m->Kn, (double)m->ebc,
			(double)m->ebc_fixed, (double)m->support_nodal,
			(double)m->rk, (double)m->fb_n, (double)m->fb_size,
			(double)m->nb, (double)m->n_in };
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

/* ------------------------------------------------------------------ copy */

int tled_model_copy(tled_model_t *d, const tled_model_t *s)
{
	const tled_model_t *m = s;
	int64_t n = m->n, nip = m->nip;
	int64_t ne = m->ipptr ? m->ipptr[nip] : 0;
	int64_t nr = m->rk > 0 ? n * m->rk : 0;
	*d = *s;
	/* every pointer of the copy its own (none of s's) */
#define NUL(f, cnt) d->f = NULL;
	TLED_MODEL_ARRAYS(NUL)
#undef NUL
	d->fb_loc = NULL;
	d->fb_ptr = d->fs_ptr = d->fs_slot = d->fb_i = NULL;
	d->fb_buf = d->fb_w = NULL;
	d->fb_n = d->fb_size = 0;
	memset(&d->bgrid, 0, sizeof d->bgrid);
#define DUP(f, cnt)                                                          \
	if (s->f) {                                                          \
		size_t b_ = (size_t)((cnt) > 0 ? (cnt) : 1) * sizeof *s->f;  \
		if (!(d->f = malloc(b_)))                                    \
			goto oom;                                            \
		memcpy(d->f, s->f, (size_t)(cnt) * sizeof *s->f);            \
	}
	TLED_MODEL_ARRAYS(DUP)
#undef DUP
	/* derived: the boundary grid over bX (as tled_model_build makes it)
	 * and the fused forces' blocks (when s has them) */
	if (s->bX && tled_grid_build(&d->bgrid, d->bX, d->nb, d->h_mean))
		goto oom;
	if (s->fb_loc && (tled_model_fb_build(d) || !d->fb_loc))
		goto oom;
	return 0;
oom:
	tled_model_free(d);
	return -1;
}

/* ---------------------------------------------------------------- cache */

int tled_model_cache_get(uint64_t key, tled_model_t *m, double *ip_factor,
			 int *publish)
{
	int hit = 0;
	*publish = 0;
	pthread_mutex_lock(&g_lock);
	for (;;) {
		if (g_cache.valid && g_cache.key == key) {
			if (tled_model_copy(m, &g_cache.m) == 0) {
				m->gen = tled_model_next_gen();
				*ip_factor = g_cache.ip_factor;
				g_cache.hits++;
				hit = 1;
			}
			break;
		}
		if (g_cache.pending && g_cache.pending_key == key) {
			pthread_cond_wait(&g_cv, &g_lock);
			continue;
		}
		if (!g_cache.pending) {
			g_cache.pending = 1;
			g_cache.pending_key = key;
			*publish = 1;
		}
		break;
	}
	pthread_mutex_unlock(&g_lock);
	return hit;
}

void tled_model_cache_put(uint64_t key, const tled_model_t *m,
			  double ip_factor)
{
	tled_model_t c, old;
	memset(&old, 0, sizeof old);
	int ok = tled_model_copy(&c, m) == 0;
	pthread_mutex_lock(&g_lock);
	if (ok) {
		if (g_cache.valid)
			old = g_cache.m;
		g_cache.m = c;
		g_cache.key = key;
		g_cache.ip_factor = ip_factor;
		g_cache.valid = 1;
	}
	if (g_cache.pending && g_cache.pending_key == key)
		g_cache.pending = 0;
	pthread_cond_broadcast(&g_cv);
	pthread_mutex_unlock(&g_lock);
	tled_model_free(&old);
}

void tled_model_cache_abandon(uint64_t key)
{
	pthread_mutex_lock(&g_lock);
	if (g_cache.pending && g_cache.pending_key == key) {
		g_cache.pending = 0;
		pthread_cond_broadcast(&g_cv);
	}
	pthread_mutex_unlock(&g_lock);
}

uint64_t tled_model_cache_hits(void)
{
	pthread_mutex_lock(&g_lock);
	uint64_t n = g_cache.hits;
	pthread_mutex_unlock(&g_lock);
	return n;
}

void tled_model_cache_clear(void)
{
	tled_model_t old;
	memset(&old, 0, sizeof old);
	pthread_mutex_lock(&g_lock);
	if (g_cache.valid)
		old = g_cache.m;
	memset(&g_cache.m, 0, sizeof g_cache.m);
	g_cache.valid = 0;
	pthread_mutex_unlock(&g_lock);
	tled_model_free(&old);
}

/* the plugin's shared object unloaded (dlclose) or the process ends */
__attribute__((destructor)) static void cache_fini(void)
{
	tled_model_cache_clear();
}
