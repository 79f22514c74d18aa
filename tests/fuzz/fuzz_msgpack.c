/* SPDX-License-Identifier: MIT */
/*
 * libFuzzer target: the MessagePack decoder (runtime/msgpack.c).
 * Any input must decode to a valid message or fail with a message; a
 * decoded message must re-encode and decode to an equal one.  Built and
 * run by scripts/fuzz.sh (`make fuzz`) with ASan and UBSan.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "rt.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	msg_t *m = NULL;
	char err[512] = "";
	/* 64 MiB: libFuzzer's memory limit is 2 GiB */
	int rc = msg_unpack((const char *)data, size, UINT64_C(1) << 26, &m,
			    err, sizeof err);
	if (rc) {
		if (m || !err[0] || rc > 0)
			__builtin_trap(); /* failure without a message */
		return 0;
	}
	if (!msg_valid(m, 0))
		__builtin_trap();
	char *buf = NULL;
	size_t len = 0;
	if (msg_pack(m, &buf, &len))
		__builtin_trap();
	msg_t *m2 = NULL;
	if (msg_unpack(buf, len, 0, &m2, err, sizeof err) || !msg_equal(m, m2))
		__builtin_trap(); /* round trip changed the message */
	free(buf);
	msg_unref(m2);
	msg_unref(m);
	return 0;
}
