/* SPDX-License-Identifier: MIT */
/*
 * armstg: the command line.
 *
 *   armstg run GRAPH [--set stage.key=value]... [--out DIR] [--jobs N]
 *              [--target STAGE]... [-v] [-q]
 *   armstg check GRAPH [--set ...]... [--out DIR] [--target STAGE]...
 *   armstg worker [--bind EP] [--plugins DIR] [--keys DIR] ...  (worker.c)
 *   armstg keygen DIR NAME
 *   armstg batch GRAPH --cases FILE --workers EP,... --out DIR  (batch.c)
 *   armstg plugins
 *   armstg describe PLUGIN
 *   armstg --help | --version
 *
 * Exit codes: 0 success (every output written); 1 the run failed after
 * stages ran (a stage failed, every [tune] value failed, or the outputs
 * could not be committed: none was written); 2 refused before any stage
 * ran (usage error, invalid graph, unknown target, an output folder that is
 * a file, cannot be created or is in use by another run, two outputs that
 * are one file); 3 a plugin could not be loaded (run, check, plugins,
 * describe); 130 interrupted by SIGINT, SIGTERM, SIGHUP or SIGPIPE before
 * the outputs were committed (none was written).
 */
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "graph.h"
#include "remote.h"

enum { EXIT_STAGE = 1, EXIT_USAGE = 2, EXIT_PLUGIN = 3, EXIT_INTR = 130 };

static void usage(FILE *f)
{
	fprintf(f,
"usage: armstg COMMAND [ARGS]\n"
"\n"
"ARMSTG: atlas-to-patient registration for brains with tumours.\n"
"\n"
"commands:\n"
"  run GRAPH [options]   validate GRAPH (INI) and run it\n"
"      --set STAGE.KEY=VALUE   override or add a key (repeatable);\n"
"                              tune.KEY: a key of the [tune] section;\n"
"                              vars.NAME: a variable, over the\n"
"                              environment and the graph's [vars]\n"
"      --out DIR               folder for outputs and run.tsv (default .)\n"
"      --jobs N                stages run at the same time (default 1)\n"
"      --target STAGE          run only what STAGE needs (repeatable)\n"
"      -v / -q                 more / less logging (ARMSTG_LOG=debug,stage=trace)\n"
"  check GRAPH [--set ...] [--out DIR] [--target STAGE]\n"
"                          validate only: plugins, ports, types, parameters,\n"
"                          cycles, outputs, targets, the output folder (as\n"
"                          run would, nothing run or made); every error\n"
"                          with file:line\n"
"  plugins                 list the plugins found (ARMSTG_PLUGIN_PATH, then\n"
"                          build/plugins beside the executable)\n"
"  describe PLUGIN         ports, parameters (default, range, unit, help)\n"
"  worker [--bind EP] [--plugins DIR] [--keys DIR] [--max-message MB]\n"
"                          host this build's plugins for remote stages\n"
"                          ([node] sections); 'armstg worker --help'\n"
"  keygen DIR NAME         a CURVE key pair for workers and coordinators\n"
"  batch GRAPH --cases FILE --workers EP,... --out DIR\n"
"                          one graph over many cases, spread over workers;\n"
"                          'armstg batch --help'\n"
"  --help, --version\n"
"\n"
"exit codes: 0 ok (every output written), 1 the run failed (no output\n"
"            written), 2 refused before any stage ran (usage, invalid graph,\n"
"            bad or busy --out), 3 a plugin could not be loaded,\n"
"            130 interrupted (no output written)\n");
}

static void on_signal(int sig)
{
	(void)sig;
	rt_interrupted = 1;
}

typedef struct cli {
	const char *graph;
	const char *sets[256];
	int nsets;
	const char *targets[64];
	int ntargets;
	const char *out;
	int jobs;
	int quiet;
} cli_t;

static int parse_cli(int argc, char **argv, int i, cli_t *c)
{
	memset(c, 0, sizeof *c);
	c->jobs = 1;
	for (; i < argc; i++) {
		const char *a = argv[i];
		const char *next = i + 1 < argc ? argv[i + 1] : NULL;
		if (!strcmp(a, "--set") || !strcmp(a, "-s")) {
			if (!next || c->nsets >= 256)
				goto missing;
			c->sets[c->nsets++] = next;
			i++;
		} else if (!strncmp(a, "--set=", 6)) {
			if (c->nsets < 256)
				c->sets[c->nsets++] = a + 6;
		} else if (!strcmp(a, "--out") || !strcmp(a, "-o")) {
			if (!next)
				goto missing;
			if (!*next) {
				fprintf(stderr, "armstg: --out needs a folder "
					"name ('.' for the current folder)\n");
				return -1;
			}
			c->out = next;
			i++;
		} else if (!strcmp(a, "--jobs") || !strcmp(a, "-j")) {
			char *end;
			if (!next)
				goto missing;
			long j = strtol(next, &end, 10);
			if (*end || j < 1 || j > 64) {
				fprintf(stderr, "armstg: --jobs takes 1..64, "
					"got '%s'\n", next);
				return -1;
			}
			c->jobs = (int)j;
			i++;
		} else if (!strcmp(a, "--target") || !strcmp(a, "-t")) {
			if (!next || c->ntargets >= 64)
				goto missing;
			c->targets[c->ntargets++] = next;
			i++;
		} else if (!strcmp(a, "-v") || !strcmp(a, "--verbose")) {
			rt_log_set_level(LOG_DEBUG);
		} else if (!strcmp(a, "-q") || !strcmp(a, "--quiet")) {
			rt_log_set_level(LOG_WARN);
			c->quiet = 1;
		} else if (a[0] == '-' && a[1]) {
			fprintf(stderr, "armstg: unknown option '%s' (see "
				"armstg --help)\n", a);
			return -1;
		} else if (!c->graph) {
			c->graph = a;
		} else {
			fprintf(stderr, "armstg: unexpected argument '%s'\n",
				a);
			return -1;
		}
	}
	if (!c->graph) {
		fprintf(stderr, "armstg: no graph file given (see armstg "
			"--help)\n");
		return -1;
	}
	return 0;
missing:
	fprintf(stderr, "armstg: option '%s' needs a value\n", argv[i]);
	return -1;
}

static int cmd_run(int argc, char **argv, int check_only)
{
	cli_t c;
	if (parse_cli(argc, argv, 2, &c))
		return EXIT_USAGE;
	char *err = malloc(65536);
	if (!err)
		return EXIT_USAGE;
	int plugin_failed = 0;
	graph_t *g = graph_load_ex(c.graph, c.sets, c.nsets, &plugin_failed,
				   err, 65536);
	if (!g) {
		fprintf(stderr, "%s\n", err);
		free(err);
		return plugin_failed ? EXIT_PLUGIN : EXIT_USAGE;
	}
	if (check_only) {
		/* what run checks before any stage, nothing made */
		run_opts_t o = { .outdir = c.out ? c.out : ".", .jobs = c.jobs,
				 .targets = c.targets, .ntargets = c.ntargets,
				 .quiet = 1 };
		int code = 0;
		if (graph_check_run(g, &o, err, 65536)) {
			char shown[4096];
			rt_escape_ctl(err, shown, sizeof shown);
			fprintf(stderr, "armstg: %s\n", shown);
			code = EXIT_USAGE;
		} else {
			printf("%s: ok (%d stages)\n", c.graph,
			       graph_nstages(g));
		}
		graph_free(g);
		free(err);
		return code;
	}
	/* a dropped ssh session (SIGHUP) or a closed pipe (SIGPIPE, e.g.
	 * `armstg run ... 2>&1 | head`) stops the run like Ctrl-C: the
	 * stages stop, nothing is committed, the temporaries go */
	struct sigaction sa;
	memset(&sa, 0, sizeof sa);
	sa.sa_handler = on_signal;
	sigaction(SIGINT, &sa, NULL);
	sigaction(SIGTERM, &sa, NULL);
	sigaction(SIGHUP, &sa, NULL);
	sigaction(SIGPIPE, &sa, NULL);
	run_opts_t o = { .outdir = c.out ? c.out : ".", .jobs = c.jobs,
			 .targets = c.targets, .ntargets = c.ntargets,
			 .quiet = c.quiet };
	int refused = 0;
	int rc = graph_run_ex(g, &o, &refused, err, 65536);
	int code = 0;
	char shown[4096];
	rt_escape_ctl(err, shown, sizeof shown);
	if (!rc) {
		fprintf(stderr, "armstg: graph '%s' done; outputs and run.tsv "
			"in %s%s\n", graph_name(g), o.outdir,
			rt_interrupted ? " (the interrupt came after every "
					 "output was written)" : "");
	} else if (refused) {
		fprintf(stderr, "armstg: %s\n", shown);
		code = EXIT_USAGE;
	} else if (rc == ARMSTG_ECANCELLED) {
		fprintf(stderr, "armstg: interrupted; no output was written "
			"(the run table is %s/run.failed.tsv)\n", o.outdir);
		code = EXIT_INTR;
	} else {
		fprintf(stderr, "armstg: %s\nno output was written (the run "
			"table is %s/run.failed.tsv)\n", shown, o.outdir);
		code = EXIT_STAGE;
	}
	graph_free(g);
	free(err);
	return code;
}

static void list_cb(const char *path, void *user)
{
	int *bad = user;
	rt_plugin_t p;
	char err[1024];
	if (plugin_load_file(path, &p, err, sizeof err)) {
		fprintf(stderr, "armstg: %s\n", err);
		(*bad)++;
		return;
	}
	const armstg_plugin_t *d = p.desc;
	printf("%-14s %-8s %s%s\n", d->name, d->version, d->description,
	       (d->devices & DEV_CUDA) ? " [cuda]" : "");
	plugin_unload(&p);
}

static int cmd_plugins(void)
{
	int bad = 0;
	int n = plugin_foreach(list_cb, &bad);
	if (!n)
		fprintf(stderr, "armstg: no plugins found in %s\n",
			plugin_search_path());
	return bad || !n ? EXIT_PLUGIN : 0;
}

static const char *ptype(int t)
{
	switch (t) {
	case PT_INT: return "int";
	case PT_DOUBLE: return "double";
	case PT_BOOL: return "bool";
	case PT_STRING: return "string";
	case PT_ENUM: return "enum";
	default: return "?";
	}
}

static int cmd_describe(const char *name)
{
	rt_plugin_t p;
	char err[1024];
	int rc = strchr(name, '/') ? plugin_load_file(name, &p, err, sizeof err)
				   : plugin_load(name, &p, err, sizeof err);
	if (rc) {
		fprintf(stderr, "armstg: %s\n", err);
		return EXIT_PLUGIN;
	}
	const armstg_plugin_t *d = p.desc;
	printf("%s %s (%s) - %s\n", d->name, d->version, d->license,
	       d->description);
	printf("file: %s\nABI: %u.%u\ndevices:%s%s\n", p.path, d->abi_major,
	       d->abi_minor, (d->devices & DEV_CPU) ? " cpu" : "",
	       (d->devices & DEV_CUDA) ? " cuda" : "");
	if (d->citation)
		printf("method: %s\n", d->citation);
	printf("\ninputs:\n");
	for (int i = 0; i < d->n_inputs; i++)
		printf("  %-14s %-9s %-9s %s\n", d->inputs[i].name,
		       msg_type_name(d->inputs[i].type),
		       d->inputs[i].optional ? "optional" : "required",
		       d->inputs[i].help);
	if (!d->n_inputs)
		printf("  (none)\n");
	printf("\noutputs:\n");
	for (int i = 0; i < d->n_outputs; i++)
		printf("  %-14s %-9s %-9s %s\n", d->outputs[i].name,
		       msg_type_name(d->outputs[i].type),
		       d->outputs[i].optional ? "optional" : "always",
		       d->outputs[i].help);
	if (!d->n_outputs)
		printf("  (none)\n");
	printf("\nparameters:\n");
	for (int i = 0; i < d->n_params; i++) {
		const armstg_param_t *q = &d->params[i];
		char range[160] = "", def[128];
		if (q->type == PT_INT || q->type == PT_DOUBLE)
			snprintf(range, sizeof range, " range [%g, %g]%s%s%s%s",
				 q->min, q->max, *q->unit ? " " : "", q->unit,
				 q->choices ? ", or " : "",
				 q->choices ? q->choices : "");
		else if (q->type == PT_ENUM)
			snprintf(range, sizeof range, " one of %s", q->choices);
		snprintf(def, sizeof def, "%s",
			 (q->flags & PARAM_REQUIRED) ? "required"
			 : q->def ? q->def : "unset");
		printf("  %-16s %-6s = %-12s%s\n      %s\n", q->name,
		       ptype(q->type), def, range, q->help);
	}
	if (!d->n_params)
		printf("  (none)\n");
	plugin_unload(&p);
	return 0;
}

int main(int argc, char **argv)
{
	/* Idle OpenMP threads spin by default; on a shared or small machine
	 * that makes 2 threads slower than 1.  libgomp reads the variable at
	 * load time, so set it and start again once. */
	if (!getenv("OMP_WAIT_POLICY")) {
		setenv("OMP_WAIT_POLICY", "passive", 1);
		execv("/proc/self/exe", argv);
		/* if exec fails, carry on with the default policy */
	}
	/* reads ARMSTG_LOG now: a bad value is reported whatever runs */
	rt_log_level_for(NULL);
	if (argc < 2) {
		usage(stderr);
		return EXIT_USAGE;
	}
	const char *cmd = argv[1];
	if (!strcmp(cmd, "--help") || !strcmp(cmd, "-h") ||
	    !strcmp(cmd, "help")) {
		usage(stdout);
		return 0;
	}
	if (!strcmp(cmd, "--version") || !strcmp(cmd, "version")) {
		printf("armstg %s (plugin ABI %d.%d)\n", ARMSTG_VERSION,
		       ARMSTG_ABI_MAJOR, ARMSTG_ABI_MINOR);
		return 0;
	}
	if (!strcmp(cmd, "run"))
		return cmd_run(argc, argv, 0);
	if (!strcmp(cmd, "check"))
		return cmd_run(argc, argv, 1);
	if (!strcmp(cmd, "plugins"))
		return cmd_plugins();
	if (!strcmp(cmd, "worker"))
		return worker_main(argc, argv);
	if (!strcmp(cmd, "keygen"))
		return keygen_main(argc, argv);
	if (!strcmp(cmd, "batch"))
		return batch_main(argc, argv);
	if (!strcmp(cmd, "describe")) {
		if (argc != 3) {
			fprintf(stderr, "usage: armstg describe PLUGIN\n");
			return EXIT_USAGE;
		}
		return cmd_describe(argv[2]);
	}
	fprintf(stderr, "armstg: unknown command '%s' (see armstg --help)\n",
		cmd);
	return EXIT_USAGE;
}
