/* Test-only plugin as a binary built against a NEWER plugin ABI than the
 * runtime's would be: minor ARMSTG_ABI_MINOR + 1, with a descriptor one
 * member longer.  The loader must refuse it, naming it; it must never run
 * (process would report it). */
#include <stddef.h>
#include "armstg/plugin.h"

static const armstg_port_t outs[] = {
	{ "table", MSG_TABLE, 0, "nothing: never runs" },
};

static int process(armstg_stage_t *st)
{
	return st->host->fail(st, ARMSTG_EINTERNAL,
			      "tp_new_minor ran: the loader let a plugin of "
			      "a newer ABI minor in");
}

/* the descriptor of the next minor: today's plus a member */
static const struct {
	armstg_plugin_t d;
	const void *next_minor_member;
} desc = {
	.d = {
		.magic = ARMSTG_PLUGIN_MAGIC,
		.abi_major = ARMSTG_ABI_MAJOR,
		.abi_minor = ARMSTG_ABI_MINOR + 1,
		.struct_size = sizeof(armstg_plugin_t) + sizeof(void *),
		.name = "tp_new_minor",
		.description = "plugin built for a newer ABI minor (tests only)",
		.version = "1",
		.license = "MIT",
		ARMSTG_OUTPUTS(outs),
		.devices = DEV_CPU,
		.process = process,
	},
	.next_minor_member = NULL,
};
ARMSTG_PLUGIN(desc.d)
