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

static const uint64_t b2_iv[8] = {
	0x6a09e667f3bcc908ULL, 0xbb67ae8584caa73bULL, 0x3c6ef372fe94f82bULL,
	0xa54ff53a5f1d36f1ULL, 0x510e527fade682d1ULL, 0x9b05688c2b3e6c1fULL,
	0x1f83d9abfb41bd6bULL, 0x5be0cd19137e2179ULL,
};

static const uint8_t b2_sigma[12][16] = {
	{ 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15 },
	{ 14, 10, 4, 8, 9, 15, 13, 6, 1, 12, 0, 2, 11, 7, 5, 3 },
	{ 11, 8, 12, 0, 5, 2, 15, 13, 10, 14, 3, 6, 7, 1, 9, 4 },
	{ 7, 9, 3, 1, 13, 12, 11, 14, 2, 6, 5, 10, 4, 0, 15, 8 },
	{ 9, 0, 5, 7, 2, 4, 10, 15, 14, 1, 11, 12, 6, 8, 3, 13 },
	{ 2, 12, 6, 10, 0, 11, 8, 3, 4, 13, 7, 5, 15, 14, 1, 9 },
	{ 12, 5, 1, 15, 14, 13, 4, 10, 0, 7, 6, 3, 9, 2, 8, 11 },
	{ 13, 11, 7, 14, 12, 1, 3, 9, 5, 0, 15, 4, 8, 6, 2, 10 },
	{ 6, 15, 14, 9, 11, 3, 0, 8, 12, 2, 13, 7, 1, 4, 10, 5 },
	{ 10, 2, 8, 4, 7, 6, 1, 5, 15, 11, 9, 14, 3, 12, 13, 0 },
	{ 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15 },
	{ 14, 10, 4, 8, 9, 15, 13, 6, 1, 12, 0, 2, 11, 7, 5, 3 },
};

static inline uint64_t rotr64(uint64_t x, int n)
{
	return (x >> n) | (x << (64 - n));
}

static inline uint64_t load64(const uint8_t *p)
{
	uint64_t v = 0;
	for (int i = 7; i >= 0; i--)
		v = (v << 8) | p[i];
	return v;
}

/* RFC 7693 section 3.1: the mixing function G */
#define B2G(a, b, c, d, x, y)                                                \
	do {                                                                 \
		a = a + b + (x);                                             \
		d = rotr64(d ^ a, 32);                                       \
		c = c + d;                                                   \
		b = rotr64(b ^ c, 24);                                       \
		a = a + b + (y);                                             \
		d = rotr64(d ^ a, 16);                                       \
		c = c + d;                                                   \
		b = rotr64(b ^ c, 63);                                       \
	} while (0)

/* RFC 7693 section 3.2: the compression function F */
static void b2_compress(dm_hash_t *s, int last)
{
	uint64_t v[16], m[16];
	for (int i = 0; i < 8; i++) {
		v[i] = s->h[i];
		v[i + 8] = b2_iv[i];
	}
	v[12] ^= s->t[0];
	v[13] ^= s->t[1];
	if (last)
		v[14] = ~v[14];
	for (int i = 0; i < 16; i++)
		m[i] = load64(s->buf + 8 * i);
	for (int r = 0; r < 12; r++) {
		const uint8_t *z = b2_sigma[r];
		B2G(v[0], v[4], v[8], v[12], m[z[0]], m[z[1]]);
		B2G(v[1], v[5], v[9], v[13], m[z[2]], m[z[3]]);
		B2G(v[2], v[6], v[10], v[14], m[z[4]], m[z[5]]);
		B2G(v[3], v[7], v[11], v[15], m[z[6]], m[z[7]]);
		B2G(v[0], v[5], v[10], v[15], m[z[8]], m[z[9]]);
		B2G(v[1], v[6], v[11], v[12], m[z[10]], m[z[11]]);
		B2G(v[2], v[7], v[8], v[13], m[z[12]], m[z[13]]);
		B2G(v[3], v[4], v[9], v[14], m[z[14]], m[z[15]]);
	}
	for (int i = 0; i < 8; i++)
		s->h[i] ^= v[i] ^ v[i + 8];
}

void dm_hash_init(dm_hash_t *s)
{
	memset(s, 0, sizeof *s);
	memcpy(s->h, b2_iv, sizeof s->h);
	s->h[0] ^= 0x01010000u ^ 32u; /* no key, 32-byte digest */
}

void dm_hash_update(dm_hash_t *s, const void *p, size_t n)
{
	const uint8_t *b = p;
	while (n > 0) {
		/* the last block is compressed by dm_hash_final (flagged) */
		if (s->n == sizeof s->buf) {
			s->t[0] += sizeof s->buf;
			if (s->t[0] < sizeof s->buf)
				s->t[1]++;
			b2_compress(s, 0);
			s->n = 0;
		}
		size_t c = sizeof s->buf - s->n;
		if (c > n)
			c = n;
		memcpy(s->buf + s->n, b, c);
		s->n += c;
		b += c;
		n -= c;
	}
}

void dm_hash_final(dm_hash_t *s, uint8_t out[32])
{
	s->t[0] += s->n;
	if (s->t[0] < s->n)
		s->t[1]++;
	memset(s->buf + s->n, 0, sizeof s->buf - s->n);
	b2_compress(s, 1);
	for (int i = 0; i < 32; i++)
		out[i] = (uint8_t)(s->h[i / 8] >> (8 * (i % 8)));
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
