/* SPDX-License-Identifier: MIT */
/*
 * Stages: one plugin instance with its parameters, lifecycle and pending
 * output files; and the host API table plugins call.
 */
#include <errno.h>
#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#include "rt.h"

typedef struct pending_file {
	char tmp[PATH_MAX];
	char final[PATH_MAX];
} pending_file_t;

struct rt_stage {
	armstg_stage_t pub;           /* first: plugins see this */
	const armstg_plugin_t *desc;
	char name[128];
	char **strval;                /* per param: the value's text as set
				         (owned; for STRING also what priv
				         points to) */
	unsigned char *isset;         /* per param */
	int inited;                   /* 1 after a successful init */
	int init_called;
	char err[2048];
	char outdir[PATH_MAX];
	char staging[PATH_MAX];       /* "" : temporaries beside the finals */
	int threads;
	msg_t **outs;
	pending_file_t *files;
	int nfiles;
	char **made_dirs;             /* folders out_path created */
	int nmade;
	double last_progress;         /* monotonic seconds */
	double last_fraction;
	msg_t *run_graph;             /* host->run_graph's table (a ref) */
	const int *cancel;            /* host->cancelled's flag besides
				         rt_interrupted (NULL: none) */
};

static rt_stage_t *of(armstg_stage_t *st)
{
	return (rt_stage_t *)st;
}

/* ------------------------------------------------------------------ */
/* host API                                                            */

static void h_log(armstg_stage_t *st, int level, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	rt_vlog(st ? st->name : NULL, level, fmt, ap);
	va_end(ap);
}

static int h_fail(armstg_stage_t *st, int code, const char *fmt, ...)
{
	if (code >= 0)
		code = ARMSTG_EINTERNAL;
	if (st) {
		va_list ap;
		va_start(ap, fmt);
		vsnprintf(of(st)->err, sizeof of(st)->err, fmt, ap);
		va_end(ap);
	}
	return code;
}

static void h_progress(armstg_stage_t *st, double fraction, const char *fmt,
		       ...)
{
	rt_stage_t *s = of(st);
	double t = sched_now();
	/* at most one line per second, plus the final one */
	if (fraction < 1.0 && t - s->last_progress < 1.0)
		return;
	s->last_progress = t;
	s->last_fraction = fraction;
	char msg[1024];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	if (fraction >= 0)
		rt_log(st->name, LOG_INFO, "%3.0f%% %s", 100.0 * fraction, msg);
	else
		rt_log(st->name, LOG_INFO, "%s", msg);
}

static int h_cancelled(armstg_stage_t *st)
{
	const int *c = of(st)->cancel;
	return rt_interrupted != 0 ||
	       (c && __atomic_load_n(c, __ATOMIC_RELAXED));
}

static void note_dir(rt_stage_t *s, const char *d)
{
	char **n = realloc(s->made_dirs, (size_t)(s->nmade + 1) * sizeof *n);
	if (!n)
		return;
	s->made_dirs = n;
	if ((n[s->nmade] = strdup(d)))
		s->nmade++;
}

/* mkdir -p; the folders it creates are noted so a discarded run can remove
 * them again when they stay empty */
static int mkdirs(rt_stage_t *s, const char *dir)
{
	char buf[PATH_MAX];
	if (snprintf(buf, sizeof buf, "%s", dir) >= (int)sizeof buf)
		return -1;
	for (char *p = buf + 1; *p; p++) {
		if (*p != '/')
			continue;
		*p = 0;
		if (!mkdir(buf, 0777))
			note_dir(s, buf);
		else if (errno != EEXIST)
			return -1;
		*p = '/';
	}
	if (!mkdir(buf, 0777))
		note_dir(s, buf);
	else if (errno != EEXIST)
		return -1;
	return 0;
}

static int h_out_path(armstg_stage_t *st, const char *path, char *tmp,
		      size_t tmpsize)
{
	rt_stage_t *s = of(st);
	char final[PATH_MAX];
	if (!path || !*path)
		return h_fail(st, ARMSTG_EINVAL, "output path is empty");
	if (path[0] == '/' || !s->outdir[0])
		snprintf(final, sizeof final, "%s", path);
	else if (snprintf(final, sizeof final, "%s/%s", s->outdir, path) >=
		 (int)sizeof final)
		return h_fail(st, ARMSTG_EINVAL, "output path too long: %s",
			      path);
	const char *slash = strrchr(final, '/');
	const char *base = slash ? slash + 1 : final;
	if (!*base || !strcmp(base, ".") || !strcmp(base, ".."))
		return h_fail(st, ARMSTG_EINVAL,
			      "output path '%s' names a folder, not a file",
			      final);
	if (!strncmp(base, ".armstg", 7))
		return h_fail(st, ARMSTG_EINVAL,
			      "output path '%s': names starting with "
			      "'.armstg' are the runtime's own", final);
	char dir[PATH_MAX] = ".";
	if (s->staging[0]) {
		/* a run: every file is staged in one folder (nothing appears
		 * under a final name before the run commits) */
		snprintf(dir, sizeof dir, "%s", s->staging);
	} else if (slash) {
		size_t dl = (size_t)(slash - final);
		memcpy(dir, final, dl);
		dir[dl ? dl : 1] = 0;
		if (!dl)
			dir[0] = '/';
		if (mkdirs(s, dir))
			return h_fail(st, ARMSTG_EIO,
				      "cannot create folder '%s': %s", dir,
				      strerror(errno));
	}
	for (int i = 0; i < s->nfiles; i++)
		if (!strcmp(s->files[i].final, final))
			return h_fail(st, ARMSTG_EINVAL,
				      "output '%s' written twice", final);
	pending_file_t *nf = realloc(s->files, (size_t)(s->nfiles + 1) *
						       sizeof *nf);
	if (!nf)
		return h_fail(st, ARMSTG_ENOMEM, "out of memory");
	s->files = nf;
	static _Atomic int counter;
	pending_file_t *f = &s->files[s->nfiles];
	snprintf(f->final, sizeof f->final, "%s", final);
	/* keep the basename's extension last: writers pick the format
	 * (.nii.gz, .h5, .tsv) from it */
	int w = s->staging[0]
		? snprintf(f->tmp, sizeof f->tmp, "%s/%d-%s", dir,
			   atomic_fetch_add(&counter, 1), base)
		: snprintf(f->tmp, sizeof f->tmp, "%s/.armstg-tmp-%ld-%d-%s",
			   dir, (long)getpid(), atomic_fetch_add(&counter, 1),
			   base);
	if (w >= (int)sizeof f->tmp)
		return h_fail(st, ARMSTG_EINVAL, "output path too long: %s",
			      final);
	if (strlen(f->tmp) >= tmpsize)
		return h_fail(st, ARMSTG_EINVAL,
			      "output path buffer too small for %s", final);
	snprintf(tmp, tmpsize, "%s", f->tmp);
	s->nfiles++;
	return 0;
}

/* Messages from the writers name the temporary file: show the final one. */
static int fail_tmp(armstg_stage_t *st, int rc, const char *e, const char *tmp)
{
	rt_stage_t *s = of(st);
	const char *final = s->nfiles ? s->files[s->nfiles - 1].final : tmp;
	char buf[2048];
	size_t o = 0, tl = strlen(tmp);
	for (const char *p = e; *p && o + 1 < sizeof buf;) {
		if (tl && !strncmp(p, tmp, tl)) {
			o += (size_t)snprintf(buf + o, sizeof buf - o, "%s",
					      final);
			p += tl;
		} else {
			buf[o++] = *p++;
		}
	}
	buf[o < sizeof buf ? o : sizeof buf - 1] = 0;
	return h_fail(st, rc, "%s", buf);
}

static int h_vol_read(armstg_stage_t *st, const char *path, vol_t **out)
{
	char e[1024] = "";
	int rc = vol_read_nifti(path, out, e, sizeof e);
	if (rc)
		return h_fail(st, rc, "%s", e);
	return 0;
}

typedef int (*writer_fn)(const char *path, const void *obj, int nthreads,
			 char *err, size_t errsize);

static int h_threads(armstg_stage_t *st);

/* Every sink write: a temporary name in the target folder, renamed when the
 * run succeeds (see h_out_path). */
static int write_via_tmp(armstg_stage_t *st, const char *path, writer_fn w,
			 const void *obj)
{
	char tmp[PATH_MAX], e[1024] = "";
	int rc = h_out_path(st, path, tmp, sizeof tmp);
	if (rc)
		return rc;
	rc = w(tmp, obj, h_threads(st), e, sizeof e);
	if (rc) {
		unlink(tmp);
		return fail_tmp(st, rc, e, tmp);
	}
	return 0;
}

/* .nii.gz compressed on the stage's threads */
static int w_vol(const char *p, const void *o, int nt, char *e, size_t n)
{
	return vol_write_nifti_nt(p, o, nt, e, n);
}

static int w_ps(const char *p, const void *o, int nt, char *e, size_t n)
{
	return ps_write_h5(p, o, e, n);
}

static int w_tab(const char *p, const void *o, int nt, char *e, size_t n)
{
	return tab_write_file(p, o, e, n);
}

static int h_vol_write(armstg_stage_t *st, const char *path, const vol_t *v)
{
	return write_via_tmp(st, path, w_vol, v);
}

static int h_ps_read(armstg_stage_t *st, const char *path, ps_t **out)
{
	char e[1024] = "";
	int rc = ps_read_h5(path, out, e, sizeof e);
	return rc ? h_fail(st, rc, "%s", e) : 0;
}

static int h_ps_write(armstg_stage_t *st, const char *path, const ps_t *p)
{
	return write_via_tmp(st, path, w_ps, p);
}

static int h_tab_read(armstg_stage_t *st, const char *path, tab_t **out)
{
	char e[1024] = "";
	int rc = tab_read_file(path, out, e, sizeof e);
	return rc ? h_fail(st, rc, "%s", e) : 0;
}

static int h_tab_write(armstg_stage_t *st, const char *path, const tab_t *t)
{
	return write_via_tmp(st, path, w_tab, t);
}

static int h_threads(armstg_stage_t *st)
{
	const int n = stage_threads(of(st));
	return n > 0 ? n : 1;
}

static const tab_t *h_run_graph(armstg_stage_t *st)
{
	msg_t *m = of(st)->run_graph;
	return m ? (const tab_t *)m : NULL;
}

static const armstg_host_t host_table = {
	.size = sizeof(armstg_host_t),
	.abi_major = ARMSTG_ABI_MAJOR,
	.abi_minor = ARMSTG_ABI_MINOR,
	.log = h_log,
	.fail = h_fail,
	.progress = h_progress,
	.cancelled = h_cancelled,
	.strerror = armstg_strerror,
	.vol_new = vol_new,
	.vol_clone = vol_clone,
	.vol_convert = vol_convert,
	.ps_new = ps_new,
	.ps_clone = ps_clone,
	.ps_add_attr = ps_add_attr,
	.ps_attr = ps_attr,
	.tab_new = tab_new,
	.tab_add_row = tab_add_row,
	.tab_set_num = tab_set_num,
	.tab_set_str = tab_set_str,
	.msg_ref = msg_ref,
	.msg_unref = msg_unref,
	.out_path = h_out_path,
	.vol_read = h_vol_read,
	.vol_write = h_vol_write,
	.ps_read = h_ps_read,
	.ps_write = h_ps_write,
	.tab_read = h_tab_read,
	.tab_write = h_tab_write,
	.threads = h_threads,
	.run_graph = h_run_graph,
};

const armstg_host_t *rt_host(void)
{
	return &host_table;
}

/* ------------------------------------------------------------------ */
/* stages                                                              */

rt_stage_t *stage_new(const armstg_plugin_t *desc, const char *name)
{
	if (!desc)
		return NULL;
	rt_stage_t *s = calloc(1, sizeof *s);
	if (!s)
		return NULL;
	s->desc = desc;
	snprintf(s->name, sizeof s->name, "%s", name ? name : desc->name);
	s->strval = calloc((size_t)(desc->n_params > 0 ? desc->n_params : 1),
			   sizeof(char *));
	s->isset = calloc((size_t)(desc->n_params > 0 ? desc->n_params : 1), 1);
	s->outs = calloc((size_t)(desc->n_outputs > 0 ? desc->n_outputs : 1),
			 sizeof(msg_t *));
	s->pub.priv = calloc(1, desc->priv_size ? desc->priv_size : 1);
	if (!s->strval || !s->isset || !s->outs || !s->pub.priv) {
		stage_free(s);
		return NULL;
	}
	s->pub.host = &host_table;
	s->pub.plugin = desc;
	s->pub.name = s->name;
	s->pub.out = s->outs;
	s->pub.rt = s;
#ifdef _OPENMP
	s->threads = omp_get_max_threads();
#else
	s->threads = 1;
#endif
	return s;
}

armstg_stage_t *stage_pub(rt_stage_t *s)
{
	return &s->pub;
}

const char *stage_error(rt_stage_t *s)
{
	return s->err;
}

void stage_set_outdir(rt_stage_t *s, const char *dir)
{
	snprintf(s->outdir, sizeof s->outdir, "%s", dir ? dir : "");
}

void stage_set_staging(rt_stage_t *s, const char *dir)
{
	snprintf(s->staging, sizeof s->staging, "%s", dir ? dir : "");
}

/* set by the scheduler while the stage runs, read by its plugin's threads
 * (sched.c, resplit): atomic */
void stage_set_threads(rt_stage_t *s, int n)
{
	__atomic_store_n(&s->threads, n > 0 ? n : 1, __ATOMIC_RELAXED);
}

void stage_set_cancel(rt_stage_t *s, const int *flag)
{
	s->cancel = flag;
}

int stage_threads(const rt_stage_t *s)
{
	return __atomic_load_n(&s->threads, __ATOMIC_RELAXED);
}

static int find_param(const armstg_plugin_t *d, const char *key)
{
	for (int i = 0; i < d->n_params; i++)
		if (d->params[i].name && !strcmp(d->params[i].name, key))
			return i;
	return -1;
}

static const char *unit_sfx(const armstg_param_t *p, char *buf, size_t n)
{
	if (p->unit && *p->unit)
		snprintf(buf, n, " %s", p->unit);
	else
		buf[0] = 0;
	return buf;
}

/* 1 when x is one of the values that the numeric param p lists in choices
 * ("-1|0.5") to be accepted outside [min, max] */
static int num_special(const armstg_param_t *p, double x)
{
	for (const char *c = p->choices; c && *c;) {
		char *end;
		double v = strtod(c, &end);
		if (end != c && v == x)
			return 1;
		c += strcspn(c, "|");
		if (*c == '|')
			c++;
	}
	return 0;
}

/* " (or -1)", " (or -1 or 0.5)": the numeric param's values outside its
 * range, for the range error; "" without */
static const char *special_sfx(const armstg_param_t *p, char *buf, size_t n)
{
	buf[0] = 0;
	if (!p->choices || !*p->choices)
		return buf;
	size_t lo = 0;
	for (const char *c = p->choices; *c;) {
		size_t k = strcspn(c, "|");
		lo = str_addf(buf, n, lo, "%s%.*s", lo ? " or " : " (or ",
			      (int)k, c);
		c += k;
		if (*c == '|')
			c++;
	}
	str_addf(buf, n, lo, ")");
	return buf;
}

/* Parse value for param p into dst (NULL: only check).  0 or EINVAL. */
static int parse_value(const armstg_param_t *p, const char *value, void *dst,
		       char *err, size_t errsize)
{
	char u[64], sp[96];
	char *end;
	switch (p->type) {
	case PT_INT: {
		errno = 0;
		long long x = strtoll(value, &end, 10);
		while (*end == ' ' || *end == '\t')
			end++;
		if (end == value || *end) {
			snprintf(err, errsize,
				 "parameter '%s': '%s' is not an integer",
				 p->name, value);
			return ARMSTG_EINVAL;
		}
		if (errno == ERANGE) {
			snprintf(err, errsize,
				 "parameter '%s': %s is out of range [%g, %g]%s",
				 p->name, value, p->min, p->max,
				 unit_sfx(p, u, sizeof u));
			return ARMSTG_EINVAL;
		}
		if (((double)x < p->min || (double)x > p->max) &&
		    !num_special(p, (double)x)) {
			snprintf(err, errsize,
				 "parameter '%s': %lld is out of range "
				 "[%g, %g]%s%s", p->name, x, p->min, p->max,
				 unit_sfx(p, u, sizeof u),
				 special_sfx(p, sp, sizeof sp));
			return ARMSTG_EINVAL;
		}
		if (dst)
			*(int *)dst = (int)x;
		return 0;
	}
	case PT_DOUBLE: {
		errno = 0;
		double x = strtod(value, &end);
		while (*end == ' ' || *end == '\t')
			end++;
		if (end == value || *end) {
			snprintf(err, errsize,
				 "parameter '%s': '%s' is not a number",
				 p->name, value);
			return ARMSTG_EINVAL;
		}
		if (errno == ERANGE) {
			/* strtod's overflow (+-HUGE_VAL) or underflow (a
			 * subnormal or 0) */
			if (isinf(x))
				snprintf(err, errsize, "parameter '%s': %s is "
					 "too large in magnitude (the largest "
					 "double is %g)", p->name, value,
					 DBL_MAX);
			else
				snprintf(err, errsize, "parameter '%s': %s is "
					 "too small in magnitude (the smallest "
					 "normal double is %g; write 0 for "
					 "zero)", p->name, value, DBL_MIN);
			return ARMSTG_EINVAL;
		}
		if (!isfinite(x)) {
			snprintf(err, errsize,
				 "parameter '%s': '%s' is not a finite number",
				 p->name, value);
			return ARMSTG_EINVAL;
		}
		if ((x < p->min || x > p->max) && !num_special(p, x)) {
			snprintf(err, errsize,
				 "parameter '%s': %g is out of range "
				 "[%g, %g]%s%s", p->name, x, p->min, p->max,
				 unit_sfx(p, u, sizeof u),
				 special_sfx(p, sp, sizeof sp));
			return ARMSTG_EINVAL;
		}
		if (dst)
			*(double *)dst = x;
		return 0;
	}
	case PT_BOOL: {
		static const char *t[] = { "true", "yes", "on", "1" };
		static const char *f[] = { "false", "no", "off", "0" };
		for (int i = 0; i < 4; i++) {
			if (!strcasecmp(value, t[i])) {
				if (dst)
					*(int *)dst = 1;
				return 0;
			}
			if (!strcasecmp(value, f[i])) {
				if (dst)
					*(int *)dst = 0;
				return 0;
			}
		}
		snprintf(err, errsize,
			 "parameter '%s': '%s' is not a boolean "
			 "(true/false)", p->name, value);
		return ARMSTG_EINVAL;
	}
	case PT_ENUM: {
		const char *c = p->choices ? p->choices : "";
		int idx = 0;
		size_t vl = strlen(value);
		while (*c) {
			const char *bar = strchr(c, '|');
			size_t n = bar ? (size_t)(bar - c) : strlen(c);
			if (n == vl && !strncmp(c, value, n)) {
				if (dst)
					*(int *)dst = idx;
				return 0;
			}
			idx++;
			c += n;
			if (*c == '|')
				c++;
		}
		snprintf(err, errsize,
			 "parameter '%s': '%s' is not one of %s", p->name,
			 value, p->choices ? p->choices : "(none)");
		return ARMSTG_EINVAL;
	}
	case PT_STRING:
		return 0;
	default:
		snprintf(err, errsize, "parameter '%s': unknown type %d",
			 p->name, p->type);
		return ARMSTG_EINVAL;
	}
}

static int ends_with_ci(const char *s, const char *suf, size_t m)
{
	size_t n = strlen(s);
	return n > m && s[n - m - 1] == '.' && !strncasecmp(s + n - m, suf, m);
}

/* an output file or folder parameter: a name that can be a file (or a
 * folder), with one of the declared endings */
static int check_out_path(const armstg_param_t *p, const char *value,
			  char *err, size_t errsize)
{
	const char *slash = strrchr(value, '/');
	const char *base = slash ? slash + 1 : value;
	int file = (p->flags & PARAM_OUT_FILE) != 0;
	if (!*value) {
		snprintf(err, errsize, "parameter '%s': the %s name is empty",
			 p->name, file ? "file" : "folder");
		return ARMSTG_EINVAL;
	}
	if (file && (!*base || !strcmp(base, ".") || !strcmp(base, ".."))) {
		snprintf(err, errsize, "parameter '%s': '%s' names a folder, "
			 "not a file", p->name, value);
		return ARMSTG_EINVAL;
	}
	if (!strncmp(base, ".armstg", 7)) {
		snprintf(err, errsize, "parameter '%s': '%s': names starting "
			 "with '.armstg' are the runtime's own", p->name, value);
		return ARMSTG_EINVAL;
	}
	if (!file || !p->choices || !*p->choices)
		return 0;
	char list[256] = "";
	size_t lo = 0;
	for (const char *c = p->choices; *c;) {
		size_t n = strcspn(c, "|");
		if (ends_with_ci(value, c, n))
			return 0;
		const char *bar = c[n] ? "" : NULL;
		lo = str_addf(list, sizeof list, lo, "%s.%.*s",
			      lo ? (bar ? ", " : " or ") : "", (int)n, c);
		c += n;
		if (*c == '|')
			c++;
	}
	snprintf(err, errsize, "parameter '%s': '%s' must end in %s", p->name,
		 value, list);
	return ARMSTG_EINVAL;
}

int stage_set_param(rt_stage_t *s, const char *key, const char *value,
		    char *err, size_t errsize)
{
	const armstg_plugin_t *d = s->desc;
	int i = find_param(d, key);
	if (i < 0) {
		snprintf(err, errsize,
			 "unknown parameter '%s' for plugin '%s' (see "
			 "'armstg describe %s')", key, d->name, d->name);
		return ARMSTG_EINVAL;
	}
	const armstg_param_t *p = &d->params[i];
	if (p->offset + (p->type == PT_DOUBLE ? sizeof(double)
			 : p->type == PT_STRING ? sizeof(char *) : sizeof(int)) >
	    d->priv_size) {
		snprintf(err, errsize,
			 "parameter '%s': offset outside the plugin's private"
			 " data (plugin bug)", key);
		return ARMSTG_EINTERNAL;
	}
	void *dst = (char *)s->pub.priv + p->offset;
	if (p->type == PT_STRING && (p->flags & (PARAM_OUT_FILE | PARAM_OUT_DIR))) {
		int rc = check_out_path(p, value, err, errsize);
		if (rc)
			return rc;
	}
	if (p->type != PT_STRING) {
		int rc = parse_value(p, value, dst, err, errsize);
		if (rc)
			return rc;
	}
	char *dup = strdup(value);
	if (!dup)
		return ARMSTG_ENOMEM;
	free(s->strval[i]);
	s->strval[i] = dup;
	if (p->type == PT_STRING)
		*(const char **)dst = dup;
	s->isset[i] = 1;
	return 0;
}

const char *stage_param_text(const rt_stage_t *s, int i)
{
	return i >= 0 && i < s->desc->n_params ? s->strval[i] : NULL;
}

int stage_param_isset(const rt_stage_t *s, int i)
{
	return i >= 0 && i < s->desc->n_params && s->isset[i];
}

void stage_set_run_graph(rt_stage_t *s, const msg_t *m)
{
	msg_unref(s->run_graph);
	s->run_graph = m ? msg_ref(m) : NULL;
}

int stage_finish_params(rt_stage_t *s, char *err, size_t errsize)
{
	const armstg_plugin_t *d = s->desc;
	for (int i = 0; i < d->n_params; i++) {
		const armstg_param_t *p = &d->params[i];
		if (s->isset[i])
			continue;
		if (p->flags & PARAM_REQUIRED) {
			snprintf(err, errsize,
				 "required parameter '%s' is not set (%s)",
				 p->name, p->help ? p->help : "");
			return ARMSTG_EINVAL;
		}
		if (!p->def)
			continue; /* optional string: stays NULL */
		int rc = stage_set_param(s, p->name, p->def, err, errsize);
		if (rc) {
			char inner[1024];
			snprintf(inner, sizeof inner, "%s", err);
			snprintf(err, errsize, "default of %s (plugin bug)",
				 inner);
			return ARMSTG_EINTERNAL;
		}
		s->isset[i] = 0; /* still "unset" by the user */
	}
	return 0;
}

int stage_init(rt_stage_t *s)
{
	s->init_called = 1;
	s->err[0] = 0;
	if (!s->desc->init) {
		s->inited = 1;
		return 0;
	}
	int rc = s->desc->init(&s->pub);
	if (rc) {
		if (rc > 0)
			rc = ARMSTG_EINTERNAL;
		if (!s->err[0])
			snprintf(s->err, sizeof s->err, "init failed: %s",
				 armstg_strerror(rc));
		return rc;
	}
	s->inited = 1;
	return 0;
}

static void drop_outputs(rt_stage_t *s)
{
	for (int o = 0; o < s->desc->n_outputs; o++) {
		msg_unref(s->outs[o]);
		s->outs[o] = NULL;
	}
}

int stage_process(rt_stage_t *s, const msg_t *const *inputs)
{
	const armstg_plugin_t *d = s->desc;
	s->err[0] = 0;
	if (!s->inited) {
		snprintf(s->err, sizeof s->err,
			 "process called before a successful init");
		return ARMSTG_EINTERNAL;
	}
	for (int i = 0; i < d->n_inputs; i++) {
		const msg_t *m = inputs[i];
		if (!m) {
			if (d->inputs[i].optional)
				continue;
			snprintf(s->err, sizeof s->err,
				 "required input '%s' is missing",
				 d->inputs[i].name);
			return ARMSTG_EINVAL;
		}
		if (!msg_valid(m, d->inputs[i].type)) {
			snprintf(s->err, sizeof s->err,
				 "input '%s' expects a %s, got a %s",
				 d->inputs[i].name,
				 msg_type_name(d->inputs[i].type),
				 msg_valid(m, 0) ? msg_type_name(m->type)
						 : "corrupt message");
			return ARMSTG_EINVAL;
		}
	}
	drop_outputs(s);
	s->pub.in = inputs;
#ifdef _OPENMP
	/* the stage's share of the threads is also the OpenMP default of
	 * what it runs (a parallel region without num_threads, the host's
	 * conversions): no stage of a --jobs run takes every core */
	const int nt_prev = omp_get_max_threads();
	omp_set_num_threads(stage_threads(s) > 0 ? stage_threads(s) : 1);
#endif
	int rc = d->process(&s->pub);
#ifdef _OPENMP
	omp_set_num_threads(nt_prev);
#endif
	s->pub.in = NULL;
	if (rc) {
		if (rc > 0)
			rc = ARMSTG_EINTERNAL;
		if (!s->err[0])
			snprintf(s->err, sizeof s->err, "%s",
				 armstg_strerror(rc));
		drop_outputs(s);
		stage_discard_files(s);
		return rc;
	}
	for (int o = 0; o < d->n_outputs; o++) {
		msg_t *m = s->outs[o];
		if (!m && d->outputs[o].optional)
			continue;
		if (!m || !msg_valid(m, d->outputs[o].type)) {
			snprintf(s->err, sizeof s->err,
				 "plugin bug: output '%s' %s", d->outputs[o].name,
				 m ? "has the wrong message type"
				   : "was not produced");
			drop_outputs(s);
			stage_discard_files(s);
			return ARMSTG_EINTERNAL;
		}
		msg_freeze(m);
	}
	return 0;
}

msg_t *stage_output(rt_stage_t *s, int port)
{
	if (port < 0 || port >= s->desc->n_outputs)
		return NULL;
	return s->outs[port];
}

msg_t *stage_take_output(rt_stage_t *s, int port)
{
	if (port < 0 || port >= s->desc->n_outputs)
		return NULL;
	msg_t *m = s->outs[port];
	s->outs[port] = NULL;
	return m;
}

int stage_commit_files(rt_stage_t *s, char *err, size_t errsize)
{
	int rc = 0;
	for (int i = 0; i < s->nfiles; i++) {
		if (rc) {
			unlink(s->files[i].tmp);
			continue;
		}
		if (rename(s->files[i].tmp, s->files[i].final)) {
			snprintf(err, errsize, "cannot rename '%s' to '%s': %s",
				 s->files[i].tmp, s->files[i].final,
				 strerror(errno));
			unlink(s->files[i].tmp);
			rc = ARMSTG_EIO;
		}
	}
	s->nfiles = 0;
	for (int i = 0; i < s->nmade; i++)
		free(s->made_dirs[i]);
	s->nmade = 0;
	return rc;
}

void stage_discard_files(rt_stage_t *s)
{
	for (int i = 0; i < s->nfiles; i++)
		unlink(s->files[i].tmp);
	s->nfiles = 0;
	for (int i = s->nmade - 1; i >= 0; i--) {
		rmdir(s->made_dirs[i]); /* only succeeds when empty */
		free(s->made_dirs[i]);
	}
	s->nmade = 0;
}

/* list of final paths still pending */
int stage_pending_files(rt_stage_t *s, const char ***paths)
{
	static __thread const char *buf[64];
	int n = s->nfiles < 64 ? s->nfiles : 64;
	for (int i = 0; i < n; i++)
		buf[i] = s->files[i].final;
	*paths = buf;
	return n;
}

int stage_nfiles(const rt_stage_t *s)
{
	return s->nfiles;
}

const char *stage_file_tmp(const rt_stage_t *s, int i)
{
	return i >= 0 && i < s->nfiles ? s->files[i].tmp : NULL;
}

const char *stage_file_final(const rt_stage_t *s, int i)
{
	return i >= 0 && i < s->nfiles ? s->files[i].final : NULL;
}

void stage_forget_files(rt_stage_t *s)
{
	s->nfiles = 0;
	for (int i = 0; i < s->nmade; i++)
		free(s->made_dirs[i]);
	s->nmade = 0;
}

void stage_fini(rt_stage_t *s)
{
	if (s->init_called && s->desc->fini)
		s->desc->fini(&s->pub);
	s->init_called = 0;
	s->inited = 0;
}

void stage_free(rt_stage_t *s)
{
	if (!s)
		return;
	if (s->init_called)
		stage_fini(s);
	stage_discard_files(s);
	free(s->files);
	free(s->made_dirs);
	if (s->outs)
		drop_outputs(s);
	free(s->outs);
	for (int i = 0; s->strval && i < s->desc->n_params; i++)
		free(s->strval[i]);
	free(s->strval);
	free(s->isset);
	msg_unref(s->run_graph);
	free(s->pub.priv);
	free(s);
}
