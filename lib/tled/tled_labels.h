/* SPDX-License-Identifier: MIT */
/*
 * TLED: integration-domain test from an atlas label volume.
 *
 * An integration point (reference coordinates, m) lies in the brain when the
 * nearest voxel of the labels volume (world mm -> voxel through the inverse
 * affine, rounded) exists and has a label > 0.  Points outside the volume
 * are outside the brain.
 */
#ifndef TLED_LABELS_H
#define TLED_LABELS_H

#include "armstg/msg.h"

typedef struct tled_labctx {
	const vol_t *lab; /* scalar label volume */
	double inv[16];   /* world mm -> voxel */
} tled_labctx_t;

/* 0 ok, -1 singular affine or not a scalar volume */
int tled_labctx_init(tled_labctx_t *c, const vol_t *lab);
/* label of the nearest voxel to x (m), or 0 outside the volume */
long tled_label_at(const tled_labctx_t *c, const double x[3]);
/* tled_model_opts_t.inside callback: 1 where tled_label_at > 0 */
int tled_labels_inside(const double x[3], void *ctx);

#endif
