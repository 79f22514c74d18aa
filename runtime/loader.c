/* SPDX-License-Identifier: MIT */
/*
 * Plugin loader: dlopen a .so, call its entry with the host table, and
 * refuse anything whose magic, ABI major, name or descriptor is wrong, or
 * that was built for a newer ABI minor than this runtime's, with a message
 * naming the file (plugin.h: versions).  Search path: $ARMSTG_PLUGIN_PATH
 * (':'-separated), then <folder of the executable>/plugins and
 * <folder of the executable>/../plugins.
 */
#include <dirent.h>
#include <dlfcn.h>
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "rt.h"

const char *plugin_search_path(void)
{
	static char buf[4 * PATH_MAX];
	char exe[PATH_MAX];
	const char *env = getenv("ARMSTG_PLUGIN_PATH");
	ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
	char def[2 * PATH_MAX + 16] = "build/plugins";
	if (n > 0) {
		exe[n] = 0;
		char *slash = strrchr(exe, '/');
		if (slash) {
			*slash = 0;
			/* build/armstg -> build/plugins; a test program in
			 * build/tests -> build/plugins too */
			snprintf(def, sizeof def, "%s/plugins:%s/../plugins",
				 exe, exe);
		}
	}
	if (env && *env)
		snprintf(buf, sizeof buf, "%s:%s", env, def);
	else
		snprintf(buf, sizeof buf, "%s", def);
	return buf;
}

static int is_ident(const char *s, size_t max)
{
	if (!s || !*s || strlen(s) >= max)
		return 0;
	if (!(*s >= 'a' && *s <= 'z'))
		return 0;
	for (const char *p = s; *p; p++)
		if (!((*p >= 'a' && *p <= 'z') || (*p >= '0' && *p <= '9') ||
		      *p == '_'))
			return 0;
	return 1;
}

#define BAD(...)                                                              \
	do {                                                                  \
		snprintf(err, errsize, __VA_ARGS__);                          \
		return ARMSTG_EINVAL;                                         \
	} while (0)

int plugin_check_desc(const armstg_plugin_t *d, char *err, size_t errsize)
{
	if (!is_ident(d->name, 64))
		BAD("name '%s' is not an identifier [a-z][a-z0-9_]*",
		    d->name ? d->name : "(null)");
	if (!d->description || !*d->description)
		BAD("no description");
	if (!d->version || !*d->version)
		BAD("no version");
	if (!d->license || !*d->license)
		BAD("no licence");
	if (!d->process)
		BAD("no process function");
	if (d->n_inputs < 0 || d->n_inputs > 32 || (d->n_inputs && !d->inputs))
		BAD("bad input port array (count %d)", d->n_inputs);
	if (d->n_outputs < 0 || d->n_outputs > 32 ||
	    (d->n_outputs && !d->outputs))
		BAD("bad output port array (count %d)", d->n_outputs);
	if (d->n_params < 0 || d->n_params > 128 || (d->n_params && !d->params))
		BAD("bad parameter array (count %d)", d->n_params);
	if (!d->devices)
		BAD("no device listed");
	if (d->citation && !*d->citation)
		BAD("empty citation (NULL for none)");
	for (int pass = 0; pass < 2; pass++) {
		const armstg_port_t *ports = pass ? d->outputs : d->inputs;
		int n = pass ? d->n_outputs : d->n_inputs;
		const char *what = pass ? "output" : "input";
		for (int i = 0; i < n; i++) {
			const armstg_port_t *p = &ports[i];
			if (!is_ident(p->name, 64))
				BAD("%s port %d: name '%s' is not an "
				    "identifier", what, i,
				    p->name ? p->name : "(null)");
			if (p->type < MSG_VOLUME || p->type > MSG_TABLE)
				BAD("%s port '%s': unknown message type %d",
				    what, p->name, p->type);
			if (!p->help || !*p->help)
				BAD("%s port '%s': no help text", what,
				    p->name);
			for (int j = 0; j < i; j++)
				if (!strcmp(ports[j].name, p->name))
					BAD("%s port '%s' declared twice", what,
					    p->name);
		}
	}
	for (int i = 0; i < d->n_params; i++) {
		const armstg_param_t *p = &d->params[i];
		if (!is_ident(p->name, 64))
			BAD("parameter %d: name '%s' is not an identifier", i,
			    p->name ? p->name : "(null)");
		if (!strcmp(p->name, "plugin") || !strcmp(p->name, "node"))
			BAD("parameter '%s': name is reserved", p->name);
		for (int j = 0; j < i; j++)
			if (!strcmp(d->params[j].name, p->name))
				BAD("parameter '%s' declared twice", p->name);
		for (int j = 0; j < d->n_inputs; j++)
			if (!strcmp(d->inputs[j].name, p->name))
				BAD("parameter '%s' has the name of an input "
				    "port", p->name);
		if (!p->help || !*p->help)
			BAD("parameter '%s': no help text", p->name);
		if (!p->unit)
			BAD("parameter '%s': unit is NULL (use \"\" for none)",
			    p->name);
		if (p->type < PT_INT || p->type > PT_ENUM)
			BAD("parameter '%s': unknown type %d", p->name, p->type);
		if (p->type == PT_INT || p->type == PT_DOUBLE) {
			if (!(p->min <= p->max) || isnan(p->min) ||
			    isnan(p->max))
				BAD("parameter '%s': min %g > max %g", p->name,
				    p->min, p->max);
		}
		if ((p->type == PT_INT || p->type == PT_DOUBLE) && p->choices)
			for (const char *c = p->choices; *c;) {
				char *end;
				(void)strtod(c, &end);
				if (end == c || (*end && *end != '|'))
					BAD("parameter '%s': choices '%s' of a "
					    "number are not numbers separated "
					    "by '|'", p->name, p->choices);
				c = *end ? end + 1 : end;
			}
		if (p->type == PT_ENUM && (!p->choices || !*p->choices))
			BAD("parameter '%s': enum without choices", p->name);
		if ((p->flags & (PARAM_OUT_FILE | PARAM_OUT_DIR)) &&
		    p->type != PT_STRING)
			BAD("parameter '%s': an output path must be a string",
			    p->name);
		size_t need = p->type == PT_DOUBLE ? sizeof(double)
			      : p->type == PT_STRING ? sizeof(char *)
						     : sizeof(int);
		if (p->offset + need > d->priv_size)
			BAD("parameter '%s': offset %zu outside priv_size %zu",
			    p->name, p->offset, d->priv_size);
		if (!p->def && !(p->flags & PARAM_REQUIRED) &&
		    p->type != PT_STRING)
			BAD("parameter '%s': no default and not required",
			    p->name);
	}
	/* defaults must parse and lie in range: run them through a stage */
	rt_stage_t *s = stage_new(d, d->name);
	if (!s)
		BAD("out of memory");
	for (int i = 0; i < d->n_params; i++) {
		const armstg_param_t *p = &d->params[i];
		char e[512];
		if (p->def && stage_set_param(s, p->name, p->def, e, sizeof e)) {
			stage_free(s);
			BAD("default of %s", e);
		}
	}
	stage_free(s);
	return 0;
}

static const char *basename_noext(const char *path, char *buf, size_t n)
{
	const char *slash = strrchr(path, '/');
	snprintf(buf, n, "%s", slash ? slash + 1 : path);
	char *dot = strstr(buf, ".so");
	if (dot && !dot[3])
		*dot = 0;
	return buf;
}

/* Descriptor size each minor promises (plugin.h's version list). */
static const size_t desc_size_of_minor[] = {
	ARMSTG_PLUGIN_SIZE_1_0,
	ARMSTG_PLUGIN_SIZE_1_1,
	ARMSTG_PLUGIN_SIZE_1_2,
};

/*
 * SQLite/Redis rule: a plugin of an older minor is accepted, its struct_size
 * bytes copied into a zero-filled descriptor of this runtime's size (members
 * added since read 0/NULL); a plugin of a newer minor is refused by name, as
 * is a size that does not match what its minor promises.
 */
static int desc_copy(const armstg_plugin_t *pd, rt_plugin_t *out,
		     const char *path, const char *base, char *err,
		     size_t errsize)
{
	_Static_assert(sizeof desc_size_of_minor / sizeof desc_size_of_minor[0]
			       == ARMSTG_ABI_MINOR + 1,
		       "one descriptor size per minor");
	if (pd->abi_minor > ARMSTG_ABI_MINOR) {
		snprintf(err, errsize, "%s: plugin '%s' was built for plugin "
			 "ABI %u.%u, newer than this runtime's %d.%d: update "
			 "ARMSTG or rebuild the plugin against this runtime's "
			 "headers", path, base, pd->abi_major, pd->abi_minor,
			 ARMSTG_ABI_MAJOR, ARMSTG_ABI_MINOR);
		return ARMSTG_EINVAL;
	}
	size_t want = desc_size_of_minor[pd->abi_minor];
	if (pd->struct_size < want || pd->struct_size > sizeof out->desc_copy) {
		snprintf(err, errsize, "%s: plugin '%s' claims ABI %u.%u with a "
			 "descriptor of %u bytes (that minor's is %zu, this "
			 "runtime's at most %zu): a corrupt or hand-edited "
			 "descriptor; rebuild the plugin", path, base,
			 pd->abi_major, pd->abi_minor, pd->struct_size, want,
			 sizeof out->desc_copy);
		return ARMSTG_EINVAL;
	}
	memset(&out->desc_copy, 0, sizeof out->desc_copy);
	memcpy(&out->desc_copy, pd, pd->struct_size);
	return 0;
}

int plugin_load_file(const char *path, rt_plugin_t *out, char *err,
		     size_t errsize)
{
	memset(out, 0, sizeof *out);
	snprintf(out->path, sizeof out->path, "%s", path);
	int erc = plugin_check_elf(path, err, errsize);
	if (erc)
		return erc;
	void *dl = dlopen(path, RTLD_NOW | RTLD_LOCAL);
	if (!dl) {
		snprintf(err, errsize, "%s: cannot load: %s", path, dlerror());
		return ARMSTG_EIO;
	}
	armstg_entry_fn entry;
	*(void **)&entry = dlsym(dl, ARMSTG_ENTRY_SYMBOL);
	if (!entry) {
		snprintf(err, errsize, "%s: no '%s' symbol: not an ARMSTG "
			 "plugin", path, ARMSTG_ENTRY_SYMBOL);
		dlclose(dl);
		return ARMSTG_EINVAL;
	}
	const char *perr = NULL;
	const armstg_plugin_t *pd = entry(rt_host(), &perr);
	char base[256];
	basename_noext(path, base, sizeof base);
	int rc = ARMSTG_EINVAL;
	if (!pd) {
		snprintf(err, errsize, "%s: plugin refused to load: %s", path,
			 perr ? perr : "no reason given");
	} else if (pd->magic != ARMSTG_PLUGIN_MAGIC) {
		snprintf(err, errsize, "%s: bad magic 0x%08x (expected 0x%08x):"
			 " not an ARMSTG plugin", path, pd->magic,
			 ARMSTG_PLUGIN_MAGIC);
	} else if (pd->abi_major != ARMSTG_ABI_MAJOR) {
		snprintf(err, errsize, "%s: built for plugin ABI %u.x, this "
			 "runtime speaks %d.x: rebuild the plugin", path,
			 pd->abi_major, ARMSTG_ABI_MAJOR);
	} else if (!(rc = desc_copy(pd, out, path, base, err, errsize))) {
		/* from here on only the zero-filled copy is read */
		const armstg_plugin_t *d = &out->desc_copy;
		char e[512];
		if (!d->name || strcmp(d->name, base)) {
			snprintf(err, errsize, "%s: plugin calls itself '%s' "
				 "but the file is named '%s.so'", path,
				 d->name ? d->name : "(null)", base);
			rc = ARMSTG_EINVAL;
		} else if (plugin_check_desc(d, e, sizeof e)) {
			snprintf(err, errsize, "%s: invalid descriptor: %s",
				 path, e);
			rc = ARMSTG_EINVAL;
		} else {
			out->dl = dl;
			out->desc = d;
			return 0;
		}
	}
	dlclose(dl);
	return rc;
}

int plugin_load(const char *name, rt_plugin_t *out, char *err,
		size_t errsize)
{
	/* by name from the plugin path only: "../x" or "/tmp/x" would load
	 * any shared object on disk */
	if (!is_ident(name, 64)) {
		char shown[256];
		rt_escape_ctl(name, shown, sizeof shown);
		snprintf(err, errsize, "'%s' is not a plugin name (plugins are "
			 "loaded by name, [a-z][a-z0-9_]*, from the plugin "
			 "path; 'armstg plugins' lists them)", shown);
		return ARMSTG_EINVAL;
	}
	char sp[4 * PATH_MAX];
	snprintf(sp, sizeof sp, "%s", plugin_search_path());
	for (char *save = NULL, *dir = strtok_r(sp, ":", &save); dir;
	     dir = strtok_r(NULL, ":", &save)) {
		char path[PATH_MAX];
		struct stat st;
		if (snprintf(path, sizeof path, "%s/%s.so", dir, name) >=
		    (int)sizeof path)
			continue;
		if (!stat(path, &st))
			return plugin_load_file(path, out, err, errsize);
	}
	snprintf(err, errsize, "unknown plugin '%s' (not found in %s; "
		 "'armstg plugins' lists them)", name, plugin_search_path());
	return ARMSTG_EINVAL;
}

void plugin_unload(rt_plugin_t *p)
{
	/* Plugins stay mapped until exit: OpenMP worker threads created by a
	 * plugin may still reference its code, and dlclose of such a library
	 * is a classic crash.  Only the handle is dropped. */
	p->desc = NULL;
	p->dl = NULL;
}

static int cmpstr(const void *a, const void *b)
{
	return strcmp(*(char *const *)a, *(char *const *)b);
}

int plugin_foreach(void (*cb)(const char *path, void *user), void *user)
{
	char sp[4 * PATH_MAX];
	snprintf(sp, sizeof sp, "%s", plugin_search_path());
	char *seen[512];
	int nseen = 0;
	for (char *save = NULL, *dir = strtok_r(sp, ":", &save); dir;
	     dir = strtok_r(NULL, ":", &save)) {
		DIR *dp = opendir(dir);
		if (!dp)
			continue;
		char *names[512];
		int n = 0;
		struct dirent *de;
		while ((de = readdir(dp)) && n < 512) {
			size_t l = strlen(de->d_name);
			if (l > 3 && !strcmp(de->d_name + l - 3, ".so"))
				names[n++] = strdup(de->d_name);
		}
		closedir(dp);
		qsort(names, (size_t)n, sizeof *names, cmpstr);
		for (int i = 0; i < n; i++) {
			int dup = 0;
			for (int j = 0; j < nseen; j++)
				if (!strcmp(seen[j], names[i]))
					dup = 1;
			if (!dup && nseen < 512) {
				char path[PATH_MAX];
				snprintf(path, sizeof path, "%s/%s", dir,
					 names[i]);
				seen[nseen++] = names[i];
				cb(path, user);
			} else {
				free(names[i]);
			}
		}
	}
	for (int j = 0; j < nseen; j++)
		free(seen[j]);
	return nseen;
}
