/* SPDX-License-Identifier: MIT */
/*
 * libFuzzer target: the NIfTI-1 reader (runtime/nifti.c, vol_read_nifti:
 * the raw header check, niftilib's header parse, the zlib data path with
 * its truncation / CRC checks, datatype conversion, scaling, the affine).
 * The input is written to a file (named .nii.gz when it starts with the
 * gzip magic, else .nii) and read.  Any file must be read or refused with a
 * message naming it, never crash; a volume read must be valid and survive
 * vol_write_nifti + vol_read_nifti unchanged (bit for bit).  Built and run
 * by scripts/fuzz.sh (`make fuzz`) with ASan and UBSan.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "rt.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static char dir[256];

static const char *scratch(void)
{
	if (!dir[0]) {
		const char *base = access("/dev/shm", W_OK) ? "/tmp" : "/dev/shm";
		snprintf(dir, sizeof dir, "%s/armstg-fuzz-nifti-%ld", base,
			 (long)getpid());
		if (mkdir(dir, 0700) && access(dir, W_OK))
			__builtin_trap();
	}
	return dir;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	char in[512], back[512], err[1024] = "";
	int gz = size >= 2 && data[0] == 0x1f && data[1] == 0x8b;
	snprintf(in, sizeof in, "%s/in.nii%s", scratch(), gz ? ".gz" : "");
	snprintf(back, sizeof back, "%s/back.nii", scratch());
	FILE *f = fopen(in, "wb");
	if (!f || fwrite(data, 1, size, f) != size || fclose(f))
		__builtin_trap();
	vol_t *v = NULL;
	int rc = vol_read_nifti(in, &v, err, sizeof err);
	unlink(in);
	if (rc) {
		/* a refusal: negative, no volume, a message naming the file */
		if (rc > 0 || v || !err[0] || !strstr(err, in))
			__builtin_trap();
		return 0;
	}
	if (!v || !msg_valid(&v->base, MSG_VOLUME) || v->nx < 1 || v->ny < 1 ||
	    v->nz < 1 || v->nc < 1)
		__builtin_trap();
	/* what was read writes and reads back the same (small volumes: the
	 * round trip costs a file) */
	if (vol_nvox(v) * v->nc <= 65536) {
		vol_t *w = NULL;
		if (vol_write_nifti(back, v, err, sizeof err) ||
		    vol_read_nifti(back, &w, err, sizeof err) ||
		    !msg_equal(&v->base, &w->base))
			__builtin_trap();
		msg_unref(&w->base);
		unlink(back);
	}
	msg_unref(&v->base);
	return 0;
}
