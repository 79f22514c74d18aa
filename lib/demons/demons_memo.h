/* SPDX-License-Identifier: MIT */
/*
 * demons_memo.h: the coarse levels' field kept for a later registration of
 * the same process (private to plugins/demons; demons_memo.c says what it
 * keeps, under which key, and why the resumed field is the same bits).
 */
#ifndef DEMONS_MEMO_H
#define DEMONS_MEMO_H

#include <sodium.h>
#include <stddef.h>
#include <stdint.h>

#include "armstg/plugin.h"
#include "field/field.h"

struct demons_priv; /* demons_int.h */

/* at most this many fields, and this many bytes of them (fields and rows),
 * in one process; the least recently used goes first */
#define DM_MEMO_ENTRIES 8
#define DM_MEMO_BYTES ((size_t)256 << 20)

/* BLAKE2b (RFC 7693) with a 32-byte digest, sequential: libsodium's
 * crypto_generichash */
typedef struct dm_hash {
	crypto_generichash_state st;
} dm_hash_t;

void dm_hash_init(dm_hash_t *s);
void dm_hash_update(dm_hash_t *s, const void *p, size_t n);
void dm_hash_final(dm_hash_t *s, uint8_t out[32]);

/* the key of the coarse levels 1..k */
typedef struct dm_key {
	uint8_t b[32];
} dm_key_t;

/* one row of the levels' table, as the run that computed it wrote it
 * (label_dice and label_mm NaN at a level without the label term) */
typedef struct dm_memo_row {
	int level, it;
	double cost, mean_u, max_u, ldice, lcost;
} dm_memo_row_t;

/*
 * The key of levels 1..k (k < nlev) of a registration: every input volume
 * those levels read (the labels only when label_prefix: the label term acts
 * on one of them), its grid, type, affine and bytes; nlev, k, the levels'
 * iterations iters[0..k-1]; and the value of every parameter of the table
 * params[0..np-1] but 'iterations' (replaced by iters), 'memo' and, without
 * label_prefix, the label term's (label_*).  A parameter added to the
 * plugin is in the key unless it is named here.  The volumes' bytes are
 * hashed in 1 MiB chunks on nt threads, then the chunks' digests in order
 * (the same key on any thread count).  Returns 0 or ARMSTG_ENOMEM.
 */
int dm_memo_key(dm_key_t *key, const armstg_param_t *params, int np,
		const struct demons_priv *p, const vol_t *const in[7], int nlev,
		int k, const int *iters, int label_prefix, int nt);

/*
 * A field S (on the grid of level k, as that level left it) and the rows
 * of levels 1..k kept under key (a copy; nothing when key is already kept
 * or the entry alone exceeds DM_MEMO_BYTES).  Returns 0 or ARMSTG_ENOMEM.
 */
int dm_memo_put(const dm_key_t *key, const fimg_t *S,
		const dm_memo_row_t *rows, int nrows);

/*
 * Copies of the field and rows kept under key: 1 (S allocated, *rows
 * malloc'd, free both), 0 when none is kept, ARMSTG_ENOMEM.
 */
int dm_memo_get(const dm_key_t *key, fimg_t *S, dm_memo_row_t **rows,
		int *nrows);

/* the process's memo: fields handed out so far, entries and bytes kept;
 * dm_memo_clear drops every entry (tests) */
uint64_t dm_memo_hits(void);
void dm_memo_usage(int *entries, size_t *bytes);
void dm_memo_clear(void);

#endif
