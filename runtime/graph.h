/* SPDX-License-Identifier: MIT */
/*
 * Graph files (DESIGN.md section 5): INI parsed with libinih.
 *
 *   [graph]             name = ..., targets = stage, stage   (optional)
 *   [stage NAME]        plugin = PLUGIN, node = NODE (optional),
 *                       <parameter> = value, <input port> = <stage>.<port>
 *   [node NAME]         endpoint = tcp://host:port
 *
 * Values may use ${VAR} and ${VAR:-default} (environment variables; "$$" is a
 * literal '$').  `--set stage.key=value` overrides or adds any key.  Loading
 * validates everything before any stage runs; each error reads
 *     FILE:LINE: stage 'S': key 'K': what is wrong
 */
#ifndef ARMSTG_GRAPH_H
#define ARMSTG_GRAPH_H

#include "rt.h"

typedef struct graph graph_t;

/* Parse + validate.  sets: "stage.key=value" strings.  On failure returns
 * NULL and err holds every error found, one per line. */
graph_t *graph_load(const char *path, const char *const *sets, int nsets,
		    char *err, size_t errsize);
/* Syntax-level parse of text only (no plugin loading): for fuzzing. */
int graph_parse_string(const char *text, const char *fname, char *err,
		       size_t errsize);
void graph_free(graph_t *g);

typedef struct run_opts {
	const char *outdir;          /* NULL: "." */
	int jobs;                    /* stages run concurrently (>= 1) */
	const char *const *targets;  /* stages wanted (NULL: [graph] targets,
					else all) */
	int ntargets;
	int quiet;                   /* no run table on stderr */
} run_opts_t;

/* Run the stages the targets need.  0 on success; a negative code when a
 * stage failed (its message is logged and copied to err). */
int graph_run(graph_t *g, const run_opts_t *o, char *err, size_t errsize);

const char *graph_name(const graph_t *g);
int graph_nstages(const graph_t *g);

#endif
