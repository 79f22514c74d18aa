/* SPDX-License-Identifier: MIT */
/*
 * libFuzzer target: the worker's frame decoder (runtime/wire.c), the code
 * that sees whatever a client sends `armstg worker`, and the coordinator's
 * decoder of the worker's replies.
 *
 * Input layout: byte 0 chooses (bit 0) the RUN decoder or the DONE decoder
 * and (bit 1) whether the frames [ARMSTG-W1, verb] are put in front; the
 * rest is frames, each a 2-byte little-endian length and its bytes (the
 * last one takes what is left).  A decoded request must hold valid
 * messages and identifier plugin names; a decoded reply, valid messages
 * and relative file names.  Built and run by scripts/fuzz.sh (`make fuzz`)
 * with ASan and UBSan; seeds from tests/fuzz/mkseeds_wire.c.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "wire.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define MAXF 128

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	if (size < 1)
		return 0;
	int done = data[0] & 1, prefix = data[0] & 2;
	wire_buf_t f[MAXF];
	int n = 0;
	if (prefix) {
		f[n].data = WIRE_PROTO;
		f[n++].size = strlen(WIRE_PROTO);
		f[n].data = done ? "DONE" : "RUN";
		f[n++].size = done ? 4 : 3;
	}
	size_t at = 1;
	while (at < size && n < MAXF) {
		size_t len = size - at < 2 ? 0 : (size_t)data[at] |
						 (size_t)data[at + 1] << 8;
		at += size - at < 2 ? size - at : 2;
		if (len > size - at)
			len = size - at;
		f[n].data = data + at;
		f[n++].size = len;
		at += len;
	}
	char err[1024] = "";
	if (!done) {
		wire_req_t r;
		/* 1 MiB cap: libFuzzer's memory limit is 2 GiB */
		if (wire_req_decode(f, n, 1u << 20, &r, err, sizeof err)) {
			if (!err[0])
				__builtin_trap(); /* refused without a reason */
			return 0;
		}
		if (!r.plugin[0] || r.threads < 1 || r.ninputs > WIRE_MAX_PORTS)
			__builtin_trap();
		for (const char *p = r.plugin; *p; p++)
			if (*p == '/' || *p == '.')
				__builtin_trap(); /* a path got through */
		for (int i = 0; i < r.ninputs; i++)
			if (r.in[i] && !msg_valid(r.in[i], 0))
				__builtin_trap();
		wire_req_free(&r);
		return 0;
	}
	wire_done_t d;
	if (wire_done_decode(f, n, &d, err, sizeof err)) {
		if (!err[0])
			__builtin_trap();
		return 0;
	}
	for (int i = 0; i < d.noutputs; i++)
		if (d.out[i] && !msg_valid(d.out[i], 0))
			__builtin_trap();
	for (int i = 0; i < d.nfiles; i++)
		if (!wire_path_ok(d.file[i]) || !d.file_data[i])
			__builtin_trap();
	wire_done_free(&d);
	return 0;
}
