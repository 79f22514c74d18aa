/* SPDX-License-Identifier: MIT */
/*
 * Inside remote stages: what the coordinator's side (remote.c,
 * remote_node.c) and the worker (worker.c, worker_run.c, worker_int.h)
 * share: czmq without its syslog levels, and the key files' loader.
 */
#ifndef ARMSTG_REMOTE_INT_H
#define ARMSTG_REMOTE_INT_H

#include "remote.h"

/* after rt.h: czmq brings <syslog.h>, whose LOG_INFO and LOG_DEBUG would
 * shadow the runtime's log levels */
#include <czmq.h>
#undef LOG_INFO
#undef LOG_DEBUG

/* zcert_load of a key file a [node] section names (need_secret: its
 * secret key too); NULL with err naming the file (remote_node.c) */
zcert_t *remote_load_cert(const char *path, int need_secret, char *err,
			  size_t errsize);

#endif
