/* SPDX-License-Identifier: MIT */
/*
 * libFuzzer target: the graph file parser (runtime/graph_parse.c,
 * graph_parse_string: INI syntax, sections, keys, ${VAR} expansion; no
 * plugin loading).  Any text must parse or fail with a message, never
 * crash.  Built and run by scripts/fuzz.sh (`make fuzz`).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "graph.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	char *text = malloc(size + 1);
	if (!text)
		return 0;
	memcpy(text, data, size);
	text[size] = 0;
	char err[8192] = "";
	int rc = graph_parse_string(text, "fuzz.ini", err, sizeof err);
	if (rc && !err[0])
		__builtin_trap(); /* refusal without a message */
	free(text);
	return 0;
}
