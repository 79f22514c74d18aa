# lib/field: displacement fields and resampling (field.h), beneath warp and
# demons.  It builds on lib/img (sampling, Gaussian, k-d tree): a plugin
# links both, `NAME_LIBS := field img` (in that order); lib/field's own
# tests get libimg.a through libfield_LDLIBS.
libfield_LDLIBS = $(BUILD)/lib/libimg.a $(libimg_LDLIBS)
$(patsubst lib/field/tests/%.c,$(BUILD)/tests/libfield_%,$(wildcard lib/field/tests/*.c)): $(BUILD)/lib/libimg.a
