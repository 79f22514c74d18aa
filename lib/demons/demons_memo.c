/* SPDX-License-Identifier: MIT */
/*
 * The coarse levels' field kept for a later registration (memo = true).
 *
 * A [tune] search registers each candidate with the coarse levels only
 * (graphs/armstg.ini: iterations 40,30,0), then the final run registers the
 * chosen one with the graph's iterations (40,30,10).  Levels 1..k (k =
 * levels - 1) of the final run are then the candidate's computation over
 * again: the same inputs, the same parameters for those levels.  A level
 * reads only the images, masks and initial field (the same for every
 * level), the parameters and the field S that the level before it left;
 * what crosses from one level to the next is S alone (the level's images,
 * buffers, crop box, step scale and convergence history are rebuilt at
 * each level; the label term's per-level state too, dlabel_level).  So the
 * state at the start of the finest level is S after level k, and a run
 * that starts there from a kept S computes the same bits as one that
 * computes it (the field is the same bits on any thread count,
 * test_threads: a field kept by a run on 16 threads serves one on 2).
 *
 * The key (dm_memo_key) is BLAKE2b-256 (Aumasson, Neves, Wilcox-O'Hearn,
 * Winnerlein 2013; RFC 7693) of everything levels 1..k read: the input
 * volumes (grid, type, affine, every byte), nlev, k, their iterations and
 * every parameter value but the finest level's iterations, 'memo' and,
 * when the label term acts on no level of 1..k, its parameters and the
 * labels (label_where = after, or label_levels 1: the graph's and the
 * candidates' label_weight 0 then share the key).  A parameter added to
 * the plugin enters the key unless dm_memo_key leaves it out by name.  The
 * volumes' bytes go in as the digests of 1 MiB chunks, hashed on the
 * stage's threads (about 0.5 GB/s a core: 0.2 s of one core for a BraTS
 * case's 90 MB of inputs).
 *
 * The entries live in this process (a mutex: [tune] candidates run in
 * parallel, runtime/tune_par.c): at most DM_MEMO_ENTRIES fields and
 * DM_MEMO_BYTES in all, the least recently used dropped first (a BraTS
 * case's level-2 field, 120x120x78 vectors, is 13.5 MB: 8 entries 108 MB).
 * A stage that runs in a remote worker (runtime/worker.c) finds the
 * entries of that worker's process only: it misses and computes the
 * levels, as without the memo.
 */
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/volmath.h"
#include "demons_int.h"
#include "demons_memo.h"

/* ------------------------------------------------------------ BLAKE2b */

/* libsodium's BLAKE2b, unkeyed, 32-byte digest (the value of Python's
 * hashlib.blake2b(digest_size=32)).  sodium_init picks the fastest code
 * and may be called from several threads; it fails only where its random
 * source cannot be opened, which the hash does not use (it then runs the
 * portable code, the same digest) */
void dm_hash_init(dm_hash_t *s)
{
	int r = sodium_init();
	(void)r;
	crypto_generichash_init(&s->st, NULL, 0, 32);
}

void dm_hash_update(dm_hash_t *s, const void *p, size_t n)
{
	crypto_generichash_update(&s->st, p, (unsigned long long)n);
}

void dm_hash_final(dm_hash_t *s, uint8_t out[32])
{
	crypto_generichash_final(&s->st, out, 32);
}

/* ------------------------------------------------------------- the key */

#define CHUNK ((size_t)1 << 20)

static void hash_i64(dm_hash_t *s, int64_t v)
{
	uint8_t b[8];
	for (int i = 0; i < 8; i++)
		b[i] = (uint8_t)((uint64_t)v >> (8 * i));
	dm_hash_update(s, b, 8);
}

static void hash_f64(dm_hash_t *s, double v)
{
	uint64_t u;
	memcpy(&u, &v, sizeof u);
	hash_i64(s, (int64_t)u);
}

static void hash_str(dm_hash_t *s, const char *str)
{
	/* length first: no two lists of strings run together the same */
	const size_t n = str ? strlen(str) : 0;
	hash_i64(s, str ? (int64_t)n : -1);
	dm_hash_update(s, str, n);
}

/* a volume (or its absence): grid, components, type, affine, then the
 * digests of its bytes' 1 MiB chunks in order */
static int hash_vol(dm_hash_t *s, const vol_t *v, int nt)
{
	hash_i64(s, v != NULL);
	if (!v)
		return 0;
	hash_i64(s, v->nx);
	hash_i64(s, v->ny);
	hash_i64(s, v->nz);
	hash_i64(s, v->nc);
	hash_i64(s, v->dtype);
	for (int i = 0; i < 16; i++)
		hash_f64(s, v->affine[i]);
	const size_t bytes = (size_t)vol_nvox(v) * (size_t)v->nc *
			     vol_dtype_size(v->dtype);
	const int64_t nch = (int64_t)((bytes + CHUNK - 1) / CHUNK);
	hash_i64(s, (int64_t)bytes);
	uint8_t *dig = malloc(32 * (size_t)(nch > 0 ? nch : 1));
	if (!dig)
		return ARMSTG_ENOMEM;
	const uint8_t *d = v->data;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t c = 0; c < nch; c++) {
		dm_hash_t h;
		const size_t o = (size_t)c * CHUNK;
		dm_hash_init(&h);
		dm_hash_update(&h, d + o, bytes - o < CHUNK ? bytes - o : CHUNK);
		dm_hash_final(&h, dig + 32 * c);
	}
	dm_hash_update(s, dig, 32 * (size_t)nch);
	free(dig);
	return 0;
}

int dm_memo_key(dm_key_t *key, const armstg_param_t *params, int np,
		const struct demons_priv *p, const vol_t *const in[7], int nlev,
		int k, const int *iters, int label_prefix, int nt)
{
	dm_hash_t s;
	dm_hash_init(&s);
	hash_str(&s, "armstg demons: the field after levels 1..k, v1");
	hash_i64(&s, nlev);
	hash_i64(&s, k);
	for (int l = 0; l < k; l++)
		hash_i64(&s, iters[l]);
	hash_i64(&s, label_prefix);
	for (int i = 0; i < np; i++) {
		const armstg_param_t *q = &params[i];
		if (!strcmp(q->name, "iterations") || !strcmp(q->name, "memo") ||
		    (!label_prefix && !strncmp(q->name, "label_", 6)))
			continue;
		const char *at = (const char *)p + q->offset;
		hash_str(&s, q->name);
		hash_i64(&s, q->type);
		switch (q->type) {
		case PT_DOUBLE: {
			double v;
			memcpy(&v, at, sizeof v);
			hash_f64(&s, v);
			break;
		}
		case PT_STRING: {
			const char *v;
			memcpy(&v, at, sizeof v);
			hash_str(&s, v);
			break;
		}
		default: { /* PT_INT, PT_BOOL, PT_ENUM: int */
			int v;
			memcpy(&v, at, sizeof v);
			hash_i64(&s, v);
			break;
		}
		}
	}
	for (int i = 0; i < 7; i++) {
		const int label = i == IN_FLABEL || i == IN_MLABEL;
		int rc = hash_vol(&s, label && !label_prefix ? NULL : in[i], nt);
		if (rc)
			return rc;
	}
	dm_hash_final(&s, key->b);
	return 0;
}

/* ------------------------------------------------------------ the memo */

typedef struct entry {
	int valid;
	dm_key_t key;
	fimg_t S;
	dm_memo_row_t *rows;
	int nrows;
	size_t bytes;
	uint64_t used; /* tick of the last put or get */
} entry_t;

static entry_t g_memo[DM_MEMO_ENTRIES];
static size_t g_bytes;
static uint64_t g_tick, g_hits;
static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;

static void entry_drop(entry_t *e)
{
	g_bytes -= e->bytes;
	fimg_free(&e->S);
	free(e->rows);
	memset(e, 0, sizeof *e);
}

static entry_t *find(const dm_key_t *key)
{
	for (int i = 0; i < DM_MEMO_ENTRIES; i++)
		if (g_memo[i].valid && !memcmp(g_memo[i].key.b, key->b, 32))
			return &g_memo[i];
	return NULL;
}

int dm_memo_put(const dm_key_t *key, const fimg_t *S,
		const dm_memo_row_t *rows, int nrows)
{
	const size_t nf = (size_t)fgrid_nvox(&S->g) * (size_t)S->nc;
	const size_t bytes = nf * sizeof(float) +
			     (size_t)nrows * sizeof(dm_memo_row_t);
	if (bytes > DM_MEMO_BYTES)
		return 0;
	/* the copy first, outside the lock */
	entry_t e = { 0 };
	e.key = *key;
	e.nrows = nrows;
	e.bytes = bytes;
	if (fimg_alloc(&e.S, &S->g, S->nc) ||
	    !(e.rows = malloc(sizeof *rows * (size_t)(nrows > 0 ? nrows : 1)))) {
		fimg_free(&e.S);
		return ARMSTG_ENOMEM;
	}
	memcpy(e.S.d, S->d, nf * sizeof(float));
	if (nrows > 0)
		memcpy(e.rows, rows, sizeof *rows * (size_t)nrows);
	e.valid = 1;
	pthread_mutex_lock(&g_lock);
	entry_t *old = find(key);
	if (old) {
		/* kept already (the same bits: the same computation) */
		old->used = ++g_tick;
		pthread_mutex_unlock(&g_lock);
		fimg_free(&e.S);
		free(e.rows);
		return 0;
	}
	/* room: a free slot and the bytes, the least recently used out */
	for (;;) {
		int freeslot = -1, lru = -1;
		for (int i = 0; i < DM_MEMO_ENTRIES; i++) {
			if (!g_memo[i].valid) {
				if (freeslot < 0)
					freeslot = i;
			} else if (lru < 0 || g_memo[i].used < g_memo[lru].used) {
				lru = i;
			}
		}
		if (freeslot >= 0 && g_bytes + bytes <= DM_MEMO_BYTES) {
			e.used = ++g_tick;
			g_memo[freeslot] = e;
			g_bytes += bytes;
			break;
		}
		entry_drop(&g_memo[lru]);
	}
	pthread_mutex_unlock(&g_lock);
	return 0;
}

int dm_memo_get(const dm_key_t *key, fimg_t *S, dm_memo_row_t **rows,
		int *nrows)
{
	int rc = 0;
	*rows = NULL;
	*nrows = 0;
	pthread_mutex_lock(&g_lock);
	entry_t *e = find(key);
	if (e) {
		const size_t nf = (size_t)fgrid_nvox(&e->S.g) * (size_t)e->S.nc;
		if (fimg_alloc(S, &e->S.g, e->S.nc) ||
		    !(*rows = malloc(sizeof **rows *
				     (size_t)(e->nrows > 0 ? e->nrows : 1)))) {
			fimg_free(S);
			rc = ARMSTG_ENOMEM;
		} else {
			memcpy(S->d, e->S.d, nf * sizeof(float));
			if (e->nrows > 0)
				memcpy(*rows, e->rows,
				       sizeof **rows * (size_t)e->nrows);
			*nrows = e->nrows;
			e->used = ++g_tick;
			g_hits++;
			rc = 1;
		}
	}
	pthread_mutex_unlock(&g_lock);
	return rc;
}

uint64_t dm_memo_hits(void)
{
	pthread_mutex_lock(&g_lock);
	uint64_t h = g_hits;
	pthread_mutex_unlock(&g_lock);
	return h;
}

void dm_memo_usage(int *entries, size_t *bytes)
{
	pthread_mutex_lock(&g_lock);
	int n = 0;
	for (int i = 0; i < DM_MEMO_ENTRIES; i++)
		n += g_memo[i].valid;
	*entries = n;
	*bytes = g_bytes;
	pthread_mutex_unlock(&g_lock);
}

void dm_memo_clear(void)
{
	pthread_mutex_lock(&g_lock);
	for (int i = 0; i < DM_MEMO_ENTRIES; i++)
		if (g_memo[i].valid)
			entry_drop(&g_memo[i]);
	pthread_mutex_unlock(&g_lock);
}
