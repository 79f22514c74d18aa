/* SPDX-License-Identifier: MIT */
/*
 * The generic plugin contract (STYLE.md "Tests"), checked on any .so:
 *
 *   load            loader accepts it: magic, ABI, struct size, name = file
 *                   basename, descriptor sanity, every default parses and
 *                   lies in its range
 *   params          out-of-range, wrong-type and unknown parameters are
 *                   refused with a message naming the parameter
 *   init-fini       three init/fini cycles (a failing init must leave a
 *                   message) under the sanitizers in `make asan-test`
 *   fini-no-init    fini on a priv that init never set up (as after a
 *                   failed init) does not crash
 *   empty-input     process on empty inputs (0 points, 0 rows, a 1x1x1
 *                   zero volume) returns 0 or a clean error with a message
 *   typical-input   process on small synthetic inputs, same rule
 *   inputs-untouched  input messages hash the same after process
 *   roundtrip       every output survives MessagePack encode/decode
 *   no-files-left   after a failed or discarded run the output folder is
 *                   empty (sinks write temporary names only)
 *
 * Every check runs in its own child process with a time limit, so a crash
 * or a hang is reported against the check, not fatal to the driver.
 * plugins/<name>/contract.ini (optional, "key = value" lines) gives
 * parameters for the typical-input run (e.g. a small grid).
 */
#ifndef ARMSTG_CONTRACT_H
#define ARMSTG_CONTRACT_H
#include <stddef.h>

/* Run all checks on one plugin file.  report gets one line per failed
 * check ("check: reason").  Returns the number of failed checks. */
int contract_run(const char *so_path, const char *hints_dir, char *report,
		 size_t reportsize);
#endif
