# ARMSTG build.  `make` builds build/armstg and build/plugins/<name>.so, one per
# folder in plugins/.  `make test`, `make demo`, `make asan-test`, `make fuzz`.
#
# Plugin convention (nothing here changes when a plugin is added):
#   plugins/<name>/*.c         -> build/plugins/<name>.so
#   plugins/<name>/*.cu        -> compiled with nvcc when present (else the
#                                 plugin is skipped with a note)
#   plugins/<name>/tests/*.c   -> build/tests/<name>_<file> (cmocka), linked
#                                 with the plugin's objects and the runtime
#   plugins/<name>/plugin.mk   -> optional: <name>_LDLIBS, <name>_CFLAGS,
#                                 <name>_NVFLAGS (nvcc),
#                                 <name>_LIBS (names of lib/ libraries)
#   lib/<name>/*.c             -> build/lib/lib<name>.a (static, PIC): code
#                                 shared by plugins lives here, once; a plugin
#                                 links it by `<plugin>_LIBS := <name>` in its
#                                 plugin.mk and includes "<name>/<file>.h"
#   lib/<name>/lib.mk          -> optional: lib<name>_LDLIBS (what users of
#                                 the library must also link), lib<name>_CFLAGS
#   lib/<name>/tests/*.c       -> build/tests/lib<name>_<file> (cmocka)
#   tests/*.c                  -> build/tests/<file>
#   tests/plugins/<name>/*.c   -> build/test-plugins/<name>.so (test only)

BUILD    ?= build
CC       ?= cc
NVCC     ?= nvcc
SAN      ?=
OPT      ?= -O2
HDF5_CFLAGS := $(shell pkg-config --cflags hdf5 2>/dev/null)
HDF5_LIBS   := $(shell pkg-config --libs hdf5 2>/dev/null)
CFLAGS   ?= $(OPT) -g
CFLAGS   += -std=c11 -D_GNU_SOURCE -Wall -Wextra -Werror -Wno-unused-parameter -Wno-format-truncation \
            -fPIC -fopenmp -Iruntime/include -Iruntime -Ilib -Itests -I/usr/include/nifti \
            $(HDF5_CFLAGS)
ifeq ($(SAN),1)
CFLAGS   += -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined
LDSAN    := -fsanitize=address,undefined
endif
RT_LIBS  := -lniftiio -lznz -lz $(HDF5_LIBS) -lmsgpackc -linih -lpng -lczmq -lzmq -ldl -lpthread -lm
LDFLAGS  += -fopenmp $(LDSAN)

RT_SRC   := $(filter-out runtime/main.c,$(wildcard runtime/*.c))
RT_OBJ   := $(RT_SRC:%.c=$(BUILD)/obj/%.o)
RT_LIB   := $(BUILD)/libarmstg_rt.a
ARMSTG   := $(BUILD)/armstg

HAVE_NVCC := $(shell command -v $(NVCC) >/dev/null 2>&1 && echo 1)
ALL_PLUGINS := $(notdir $(patsubst %/,%,$(dir $(wildcard plugins/*/*.c plugins/*/*.cu))))
ALL_PLUGINS := $(sort $(ALL_PLUGINS))
CUDA_PLUGINS := $(sort $(notdir $(patsubst %/,%,$(dir $(wildcard plugins/*/*.cu)))))
ifeq ($(HAVE_NVCC),1)
PLUGINS  := $(ALL_PLUGINS)
else
PLUGINS  := $(filter-out $(CUDA_PLUGINS),$(ALL_PLUGINS))
endif
PLUGIN_SO := $(PLUGINS:%=$(BUILD)/plugins/%.so)

TEST_SRC := $(wildcard tests/*.c)
TEST_BIN := $(TEST_SRC:tests/%.c=$(BUILD)/tests/%)
TPLUG    := $(notdir $(patsubst %/,%,$(dir $(wildcard tests/plugins/*/*.c))))
TPLUG_SO := $(sort $(TPLUG:%=$(BUILD)/test-plugins/%.so))

.PHONY: all test demo asan-test fuzz clean deps interop bench check-cuda gpu-test
all: $(ARMSTG) $(PLUGIN_SO) check-cuda

deps:
	@sh scripts/deps.sh

check-cuda:
ifneq ($(HAVE_NVCC),1)
	@$(if $(CUDA_PLUGINS),echo "note: nvcc not found: skipping CUDA plugins: $(CUDA_PLUGINS)",true)
endif

$(BUILD)/obj/%.o: %.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(EXTRA_CFLAGS) -MMD -MP -c $< -o $@

$(RT_LIB): $(RT_OBJ)
	@mkdir -p $(dir $@)
	rm -f $@ && ar rcs $@ $^

$(ARMSTG): $(BUILD)/obj/runtime/main.o $(RT_LIB)
	$(CC) $(LDFLAGS) -o $@ $^ $(RT_LIBS)

# ---- lib/<name>: shared code beneath the plugins ----
ALL_LIBS := $(sort $(notdir $(patsubst %/,%,$(dir $(wildcard lib/*/*.c)))))
define LIB_template
-include lib/$(1)/lib.mk
lib$(1)_SRC := $$(wildcard lib/$(1)/*.c)
lib$(1)_OBJ := $$(lib$(1)_SRC:%.c=$(BUILD)/obj/%.o)
$(BUILD)/obj/lib/$(1)/%.o: EXTRA_CFLAGS = $$(lib$(1)_CFLAGS)
# its flags (lib.mk) are part of every object's recipe
$$(lib$(1)_OBJ) $$(patsubst lib/$(1)/tests/%.c,$(BUILD)/obj/lib/$(1)/tests/%.o,$$(wildcard lib/$(1)/tests/*.c)): $$(wildcard lib/$(1)/lib.mk)
$(BUILD)/lib/lib$(1).a: $$(lib$(1)_OBJ)
	@mkdir -p $$(dir $$@)
	rm -f $$@ && ar rcs $$@ $$^
lib$(1)_TESTS := $$(patsubst lib/$(1)/tests/%.c,$(BUILD)/tests/lib$(1)_%,$$(wildcard lib/$(1)/tests/*.c))
$(BUILD)/tests/lib$(1)_%: $(BUILD)/obj/lib/$(1)/tests/%.o $(BUILD)/lib/lib$(1).a $(RT_LIB)
	@mkdir -p $$(dir $$@)
	$$(CC) $$(LDFLAGS) -o $$@ $$^ $$(lib$(1)_LDLIBS) $(RT_LIBS) -lcmocka
LIB_TESTS += $$(lib$(1)_TESTS)
endef
$(foreach l,$(ALL_LIBS),$(eval $(call LIB_template,$(l))))

# ---- plugins ----
define PLUGIN_template
-include plugins/$(1)/plugin.mk
$(1)_SRC := $$(wildcard plugins/$(1)/*.c)
$(1)_CU  := $$(wildcard plugins/$(1)/*.cu)
$(1)_OBJ := $$($(1)_SRC:%.c=$(BUILD)/obj/%.o) $$($(1)_CU:%.cu=$(BUILD)/obj/%.cu.o)
$(1)_LIBA := $$(foreach l,$$($(1)_LIBS),$(BUILD)/lib/lib$$(l).a)
$(1)_LIBDEP := $$(foreach l,$$($(1)_LIBS),$$(lib$$(l)_LDLIBS))
$(BUILD)/obj/plugins/$(1)/%.o: EXTRA_CFLAGS = $$($(1)_CFLAGS)
$(BUILD)/obj/plugins/$(1)/%.cu.o: EXTRA_NVFLAGS = $$($(1)_NVFLAGS)
$(BUILD)/plugins/$(1).so: $$($(1)_OBJ) $$($(1)_LIBA)
	@mkdir -p $$(dir $$@)
	$$(CC) -shared -Wl,-z,defs $$(LDFLAGS) -o $$@ $$(filter-out %.mk,$$^) $$($(1)_LDLIBS) $$($(1)_LIBDEP) $$(if $$($(1)_CU),-L/usr/local/cuda/lib64 -lcudart -lstdc++) -lm
$(1)_TESTS := $$(patsubst plugins/$(1)/tests/%.c,$(BUILD)/tests/$(1)_%,$$(wildcard plugins/$(1)/tests/*.c))
# its flags (plugin.mk) are part of every object's recipe (.c, .cu, tests)
# and of the link: a change to them rebuilds the plugin
$$($(1)_OBJ) $$(patsubst plugins/$(1)/tests/%.c,$(BUILD)/obj/plugins/$(1)/tests/%.o,$$(wildcard plugins/$(1)/tests/*.c)) $(BUILD)/plugins/$(1).so: $$(wildcard plugins/$(1)/plugin.mk)
$(BUILD)/tests/$(1)_%: $(BUILD)/obj/plugins/$(1)/tests/%.o $$($(1)_OBJ) $$($(1)_LIBA) $(RT_LIB)
	@mkdir -p $$(dir $$@)
	$$(CC) $$(LDFLAGS) -o $$@ $$^ $$($(1)_LDLIBS) $$($(1)_LIBDEP) $(RT_LIBS) -lcmocka $$(if $$($(1)_CU),-L/usr/local/cuda/lib64 -lcudart -lstdc++)
PLUGIN_TESTS += $$($(1)_TESTS)
endef
$(foreach p,$(PLUGINS),$(eval $(call PLUGIN_template,$(p))))

$(BUILD)/obj/%.cu.o: %.cu
	@mkdir -p $(dir $@)
	$(NVCC) -arch=sm_90 -O3 $(EXTRA_NVFLAGS) -Xcompiler -fPIC -Iruntime/include -Iruntime -Ilib -MD -MP -MF $(@:.o=.d) -c $< -o $@

$(BUILD)/test-plugins/%.so: $(wildcard tests/plugins/*/*.c)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -shared $(LDFLAGS) -o $@ $(wildcard tests/plugins/$*/*.c) -lm

$(BUILD)/tests/%: $(BUILD)/obj/tests/%.o $(RT_LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $^ $(RT_LIBS) -lcmocka

TESTS := $(TEST_BIN) $(LIB_TESTS) $(PLUGIN_TESTS)
# test tools (tests/tools/*.c -> build/tests/tools/*): used by scripts
TOOLS := $(patsubst tests/tools/%.c,$(BUILD)/tests/tools/%,$(wildcard tests/tools/*.c))
$(BUILD)/tests/tools/%: $(BUILD)/obj/tests/tools/%.o $(RT_LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) -o $@ $^ $(RT_LIBS)
tests: $(TESTS) $(TPLUG_SO) $(TOOLS)

# ---- the two commands of the README ----
test: deps
	@$(MAKE) --no-print-directory all tests
	@BUILD=$(BUILD) sh scripts/run-tests.sh $(TESTS)

# The CUDA backend on a GPU host (skipped tests fail here): the numerical and
# stage tests through tled_cuda, CPU/CUDA parity, the demo phantom with both
# backends.  scripts/gpu-test.sh BUILD runs the same on a host without a
# compiler (a carried build).
gpu-test: deps
	@$(MAKE) --no-print-directory all tests
	@sh scripts/gpu-test.sh $(BUILD)

demo: deps
	@$(MAKE) --no-print-directory all
	@sh scripts/demo.sh $(BUILD)

# Under the sanitizers code runs 5-20x slower: ARMSTG_TEST_QUICK=1 asks the
# few long numerical tests for their smaller variants (same assertions).
asan-test: deps
	@ARMSTG_TEST_QUICK=1 $(MAKE) --no-print-directory BUILD=build-asan SAN=1 OPT=-O1 test

fuzz: deps
	@sh scripts/fuzz.sh

interop: deps all
	@sh scripts/interop.sh $(BUILD)

clean:
	rm -rf build build-asan build-fuzz

-include $(shell find $(BUILD)/obj -name '*.d' 2>/dev/null)
