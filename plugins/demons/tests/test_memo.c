/* SPDX-License-Identifier: MIT */
/*
 * memo = true (demons_memo.c): a registration that starts at the finest
 * level from the field an earlier run of the same coarse levels kept.
 *
 * The case is the final registration of graphs/armstg.ini and its [tune]
 * candidates on a synthetic head (synth_head.h, 1.5 mm grids, fixed LAS and
 * moving LPS): the fixed head is the moving one's anatomy at x + u(x) for a
 * smooth u of up to 2.6 mm, each with a tumour of its own at another place,
 * left out of the masks (the fixed one with a 6 mm ring of edema) and given
 * as the labels.  The candidate: LNCC, iterations 40,30,0, label_weight 0
 * (search_set); the final run: 40,30,10, the label correction after the
 * registration (label_weight 1, label_where after).
 *
 * Asserted (test_memo_resume): the final run after the candidate takes its
 * coarse levels from the memo (the hit counter goes up by one) and gives
 * the field, the warped image and every figure of the table but the seconds
 * the same bits as the final run without the memo; the candidate ran on 3
 * threads, the final runs on 1 and 2.  test_memo_miss: a final run does not
 * hit when one voxel of the moving image, the fixed mask, a parameter of
 * the coarse levels (sigma_fluid, the middle level's iterations) or the
 * label term's place (on every level) differs, and then gives the field of
 * a run without the memo; a parameter of the finest level or of the
 * correction alone (label_iterations) does hit.  test_memo_bound: at most
 * DM_MEMO_ENTRIES fields, the least recently used dropped.  test_hash: the
 * key's BLAKE2b-256 against Python's hashlib.blake2b(digest_size=32) (RFC
 * 7693) across block boundaries.
 */
#include "synth_head.h"
#include "demons/demons_memo.h"

/* the pair of synth_head.h: the fixed head displaced by synth_u, a 6 mm
 * ring of edema, the bright blob */
static int setup(void **state)
{
	static fx_t x;
	static const fx_opts_t o = { .u = synth_u, .edema_mm = 6, .blob = 1 };
	fx_make(&x, &o);
	*state = &x;
	return 0;
}

static int teardown(void **state)
{
	fx_free(*state);
	dm_memo_clear();
	return 0;
}

/* graphs/armstg.ini's register stage; its [tune] candidates' overrides */
#define REG "metric=lncc", "radius=2", "normalize=minmax", "sigma_unit=voxel", \
	    "sigma_fluid=3", "sigma_field=1.5", "levels=3", "label_reach=5",  \
	    "label_levels=1"
#define FINAL REG, "iterations=40,30,10", "label_weight=1", \
	      "label_where=after", "label_iterations=5"
/* the final run with a shorter finest level and correction (what the
 * key leaves out), for the tests of what misses */
#define SHORT REG, "iterations=40,30,2", "label_weight=1", \
	      "label_where=after", "label_iterations=2"
#define CAND REG, "iterations=40,30,0", "label_weight=0", "label_where=after"

typedef struct res {
	vol_t *field, *warped;
	tab_t *tab;
} res_t;

/* one run on nt threads of x's inputs, with m and fm in place of x's
 * moving image and fixed mask when given */
static res_t run(const char *const *params, const fx_t *x, const vol_t *m,
		 const vol_t *fm, int nt)
{
	const msg_t *in[7] = { &x->f->base, m ? &m->base : &x->m->base,
			       fm ? &fm->base : &x->fm->base, &x->mm->base,
			       NULL, &x->ft->base, &x->mt->base };
	msg_t *out[3] = { 0 };
	char e[1024] = "";
	int rc = tu_run_nt(TU_PLUGIN(), params, in, out, nt, e, sizeof e);
	if (rc)
		print_message("error: %s\n", e);
	assert_int_equal(rc, 0);
	return (res_t){ (vol_t *)out[OUT_FIELD], (vol_t *)out[OUT_WARPED],
			(tab_t *)out[OUT_TABLE] };
}

static void res_free(res_t *r)
{
	msg_unref(&r->field->base);
	msg_unref(&r->warped->base);
	msg_unref(&r->tab->base);
}

static double last(const tab_t *t, const char *col)
{
	const tab_col_t *c = tab_col(t, col);
	assert_non_null(c);
	return c->num[t->nrows - 1];
}

/* every number of two tables the same bits but the seconds */
static void same_table(const tab_t *a, const tab_t *b)
{
	assert_int_equal(a->nrows, b->nrows);
	assert_int_equal(a->ncols, b->ncols);
	for (int c = 0; c < a->ncols; c++) {
		const tab_col_t *ca = &a->col[c], *cb = &b->col[c];
		assert_string_equal(ca->name, cb->name);
		if (ca->type != TAB_NUM || !strcmp(ca->name, "seconds"))
			continue;
		for (int64_t r = 0; r < a->nrows; r++)
			assert_memory_equal(&ca->num[r], &cb->num[r],
					    sizeof(double));
	}
}

static void test_memo_resume(void **state)
{
	fx_t *x = *state;
	dm_memo_clear();
	const char *fin_off[] = { FINAL, "memo=false", NULL };
	const char *fin_on[] = { FINAL, "memo=true", NULL };
	const char *cand[] = { CAND, "memo=true", NULL };
	const uint64_t h0 = dm_memo_hits();
	res_t ref = run(fin_off, x, NULL, NULL, 2);
	/* nothing kept without memo */
	int ne;
	size_t nb;
	dm_memo_usage(&ne, &nb);
	assert_int_equal(ne, 0);
	/* the candidate keeps its field after level 2 (on 3 threads) */
	res_t c = run(cand, x, NULL, NULL, 3);
	dm_memo_usage(&ne, &nb);
	assert_int_equal(ne, 1);
	assert_int_equal(dm_memo_hits(), h0);
	/* the final run (on 1 thread) starts from it */
	res_t r = run(fin_on, x, NULL, NULL, 1);
	assert_int_equal(dm_memo_hits(), h0 + 1);
	assert_true(same_bits(ref.field, r.field));
	assert_true(same_bits(ref.warped, r.warped));
	same_table(ref.tab, r.tab);
	/* and so does a second one (the entry stays) */
	res_t r2 = run(fin_on, x, NULL, NULL, 2);
	assert_int_equal(dm_memo_hits(), h0 + 2);
	assert_true(same_bits(ref.field, r2.field));
	const tab_col_t *lv = tab_col(r.tab, "level");
	int64_t n12 = 0;
	for (int64_t i = 0; i < r.tab->nrows; i++)
		n12 += lv->num[i] < 3;
	const double jm = jac_min(r.field);
	print_message("resumed after %lld iterations of levels 1-2 (%d field "
		      "kept, %.2f MB): field, warped image and table the same "
		      "bits as without the memo; label Dice %.3f -> %.3f, min "
		      "det J %.3f\n", (long long)n12, ne, nb / 1048576.0,
		      last(r.tab, "label_dice_before"), last(r.tab, "label_dice"),
		      jm);
	assert_true(jm > 0);
	assert_true(n12 > 0 && n12 < r.tab->nrows);
	/* the candidate's own coarse levels are the final run's */
	assert_int_equal(c.tab->nrows, n12);
	res_free(&ref);
	res_free(&c);
	res_free(&r);
	res_free(&r2);
}

static void test_memo_miss(void **state)
{
	fx_t *x = *state;
	dm_memo_clear();
	const char *cand[] = { CAND, "memo=true", NULL };
	res_t c = run(cand, x, NULL, NULL, 2);
	res_free(&c);
	const uint64_t h0 = dm_memo_hits();

	/* one voxel of the moving image, inside both masks, 1e-3 brighter:
	 * no hit, and the field of the run without the memo */
	vol_t *m2 = vol_clone(x->m);
	int64_t e = vol_idx(m2, PAIR_NX / 2, PAIR_NY / 2 - 8, PAIR_NZ / 2);
	while (e < vol_nvox(m2) && !(vol_get(x->mm, e) > 0))
		e++;
	assert_true(e < vol_nvox(m2));
	vol_set(m2, e, vol_get(m2, e) + 1e-3);
	const char *fin_on[] = { SHORT, "memo=true", NULL };
	const char *fin_off[] = { SHORT, "memo=false", NULL };
	res_t a = run(fin_on, x, m2, NULL, 2);
	assert_int_equal(dm_memo_hits(), h0);
	res_t b = run(fin_off, x, m2, NULL, 2);
	assert_true(same_bits(a.field, b.field));
	res_free(&a);
	res_free(&b);
	msg_unref(&m2->base);

	/* the fixed mask one voxel smaller */
	vol_t *fm2 = vol_clone(x->fm);
	int64_t nv = vol_nvox(fm2), f = 0;
	while (f < nv && vol_get(fm2, f) <= 0)
		f++;
	assert_true(f < nv);
	vol_set(fm2, f, 0);
	a = run(fin_on, x, NULL, fm2, 2);
	assert_int_equal(dm_memo_hits(), h0);
	res_free(&a);
	msg_unref(&fm2->base);

	/* a parameter of the coarse levels, the middle level's iterations,
	 * the label term on every level */
	const char *p1[] = { REG, "iterations=40,30,2", "label_weight=1",
			     "label_where=after", "label_iterations=2",
			     "memo=true", "sigma_fluid=2.9", NULL };
	const char *p2[] = { REG, "iterations=40,29,2", "label_weight=1",
			     "label_where=after", "label_iterations=2",
			     "memo=true", NULL };
	const char *p3[] = { REG, "iterations=40,30,2", "label_weight=1",
			     "label_where=all", "label_levels=0", "memo=true",
			     NULL };
	const char *const *miss[] = { p1, p2, p3 };
	for (int i = 0; i < 3; i++) {
		a = run(miss[i], x, NULL, NULL, 2);
		assert_int_equal(dm_memo_hits(), h0);
		res_free(&a);
	}
	/* the finest level's and the correction's parameters alone: a hit */
	const char *p4[] = { SHORT, "memo=true", NULL };
	a = run(p4, x, NULL, NULL, 2);
	assert_int_equal(dm_memo_hits(), h0 + 1);
	res_free(&a);
	print_message("no hit for a moving voxel +1e-3, a fixed mask voxel, "
		      "sigma_fluid, the middle level's iterations, the label "
		      "term on every level; a hit for the finest level's "
		      "iterations and label_iterations\n");
}

static void test_memo_bound(void **state)
{
	(void)state;
	dm_memo_clear();
	fgrid_t g;
	const double A[16] = { 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1 };
	assert_int_equal(fgrid_make(&g, 20, 20, 20, A), 0);
	fimg_t S = { 0 };
	assert_int_equal(fimg_alloc(&S, &g, 3), 0);
	dm_memo_row_t row = { 1, 1, 0.5, 0.1, 0.2, NAN, NAN };
	dm_key_t k[DM_MEMO_ENTRIES + 2];
	for (int i = 0; i < DM_MEMO_ENTRIES + 2; i++) {
		memset(k[i].b, 0, sizeof k[i].b);
		k[i].b[0] = (uint8_t)(i + 1);
		S.d[0] = (float)i;
		assert_int_equal(dm_memo_put(&k[i], &S, &row, 1), 0);
		/* the first stays the most recently used */
		fimg_t T = { 0 };
		dm_memo_row_t *rows = NULL;
		int nr;
		assert_int_equal(dm_memo_get(&k[0], &T, &rows, &nr), 1);
		assert_true(T.d[0] == 0.0f && nr == 1);
		fimg_free(&T);
		free(rows);
	}
	int ne;
	size_t nb;
	dm_memo_usage(&ne, &nb);
	assert_int_equal(ne, DM_MEMO_ENTRIES);
	assert_true(nb <= DM_MEMO_BYTES);
	/* dropped: the least recently used, k[1] and k[2] */
	for (int i = 0; i < DM_MEMO_ENTRIES + 2; i++) {
		fimg_t T = { 0 };
		dm_memo_row_t *rows = NULL;
		int nr;
		int hit = dm_memo_get(&k[i], &T, &rows, &nr);
		assert_int_equal(hit, i == 1 || i == 2 ? 0 : 1);
		if (hit)
			assert_true(T.d[0] == (float)i);
		fimg_free(&T);
		free(rows);
	}
	fimg_free(&S);
	dm_memo_clear();
	dm_memo_usage(&ne, &nb);
	assert_int_equal(ne, 0);
	assert_true(nb == 0);
}

static void test_hash(void **state)
{
	(void)state;
	/* hashlib.blake2b(b, digest_size=32).hexdigest(), b = 'abc' or the
	 * bytes (7 i + 3) mod 256 */
	static const struct {
		size_t n;
		const char *hex;
	} v[] = {
		{ 0, "0e5751c026e543b2e8ab2eb06099daa1d1e5df47778f7787faab45cdf12fe3a8" },
		{ 3, "bddd813c634239723171ef3fee98579b94964e3bb1cb3e427262c8c068d52319" },
		{ 127, "c9ae3859964b35f04c54b36d33cf299d7290ee621005d28e51598a943560aaaa" },
		{ 128, "f0501d06597880592bc49234eef100ec1ff349058d0e9d9b753504e24af86dd6" },
		{ 129, "a34a4e1e03c541dfbf3099c4b6c143c022ced65c28bd7e8a10e0a098461aecf0" },
		{ 256, "d93ebb9c802f5630ab22516fd82b6c21bc8bd551d531349b715f046ed11ed871" },
		{ 1000, "d62b6c768ce1afc8367e0498ab2f8e3f7c178c35b1429f14c4604b545d200f52" },
	};
	uint8_t buf[1000];
	for (size_t i = 0; i < sizeof buf; i++)
		buf[i] = (uint8_t)(7 * i + 3);
	for (size_t t = 0; t < sizeof v / sizeof v[0]; t++) {
		/* at once, and in pieces of 1, 5, 64 and 200 bytes */
		static const size_t piece[] = { 1000000, 1, 5, 64, 200 };
		for (int pc = 0; pc < 5; pc++) {
			dm_hash_t s;
			uint8_t d[32];
			char hex[65];
			const uint8_t *src = v[t].n == 3 ? (const uint8_t *)"abc" : buf;
			dm_hash_init(&s);
			for (size_t o = 0; o < v[t].n; o += piece[pc])
				dm_hash_update(&s, src + o, v[t].n - o < piece[pc]
							    ? v[t].n - o : piece[pc]);
			dm_hash_final(&s, d);
			for (int i = 0; i < 32; i++)
				snprintf(hex + 2 * i, 3, "%02x", d[i]);
			assert_string_equal(hex, v[t].hex);
		}
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_hash),
		cmocka_unit_test(test_memo_bound),
		cmocka_unit_test(test_memo_resume),
		cmocka_unit_test(test_memo_miss),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
