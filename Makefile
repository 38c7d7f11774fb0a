# Brume build. `make` builds build/master and build/worker; `make test` runs every test;
# `make demo` renders the default scene with local workers; `make bench` measures.
# Missing Debian packages are installed on first use (apt-get, with sudo when not root).

CC      ?= gcc
SAN     ?=
BUILD   ?= build
OPT     ?= -O3

WARN    := -Wall -Wextra -Wpedantic -Wshadow -Wstrict-prototypes -Wmissing-prototypes \
           -Wpointer-arith -Wcast-qual -Wwrite-strings -Wformat=2 -Wundef -Wvla
CFLAGS  := -std=c11 -D_GNU_SOURCE $(OPT) -g -fno-fast-math -ffp-contract=off -fno-math-errno $(WARN) -Icommon -I. -pthread
LDLIBS  := -lembree3 -lOpenEXRCore-3_1 -ldeflate -lzmq -ljansson -lsodium -lpng -lstb -lm -pthread
ifneq ($(SAN),)
CFLAGS  += -fsanitize=$(SAN) -fno-omit-frame-pointer -fno-sanitize-recover=undefined
LDFLAGS += -fsanitize=$(SAN)
BUILD   := build-san
endif

DEB_PKGS := gcc make pkg-config libembree-dev libopenexr-dev openexr libzmq3-dev libjansson-dev \
            libsodium-dev libpng-dev libstb-dev libcriterion-dev embree-tools gnuplot-nox python3 clang \
            procps openssh-client openssh-server libnanovdb-dev g++ zlib1g-dev libblosc-dev libfftw3-dev \
            libdeflate-dev openimageio-tools webp
DEPS_STAMP := $(BUILD)/.deps-ok

# One folder per layer under common/ (see README, "Tour of the source"); sources by pattern.
LAYERS     := base image scene render wire
COMMON_SRC := $(foreach l,$(LAYERS),$(wildcard common/$(l)/*.c))
COMMON_OBJ := $(COMMON_SRC:%.c=$(BUILD)/obj/%.o)
MASTER_OBJ := $(patsubst %.c,$(BUILD)/obj/%.o,$(wildcard master/*.c))
MASTER_LIB_OBJ := $(filter-out %/main.o,$(MASTER_OBJ))
WORKER_OBJ := $(patsubst %.c,$(BUILD)/obj/%.o,$(wildcard worker/*.c))
# The smoke simulator (smoke/): its modules without main() also go into the unit tests.
SMOKE_OBJ  := $(patsubst %.c,$(BUILD)/obj/%.o,$(wildcard smoke/*.c))
# Its NanoVDB writer is C++ (NanoVDB's own headers), shared with tests/tools/make_nvdb.cpp.
SMOKE_NVDB_OBJ := $(BUILD)/obj/smoke/nvdb_out.o
SMOKE_LIB_OBJ := $(filter-out %/main.o,$(SMOKE_OBJ)) $(SMOKE_NVDB_OBJ)
FFTW_LIBS  := -lfftw3f_threads -lfftw3f -lstdc++
UNIT_SRC   := $(wildcard tests/unit/test_*.c) tests/unit/helpers.c
UNIT_OBJ   := $(UNIT_SRC:%.c=$(BUILD)/obj/%.o)
# Test tools: one source each in tests/tools/, linked with the library.
TOOLS      := exrtool junkpeer replay maketex texbench meshload codecbench loadpeers
TOOL_BIN   := $(TOOLS:%=$(BUILD)/%)
TOOL_OBJ   := $(TOOLS:%=$(BUILD)/obj/tests/tools/%.o)

.PHONY: smoke-sim smoke-demo showcase-assets showcase showcase-movie showcase-bunny bench-smoke all deps test layers unit integration demo bench bench-master bench-motion bench-media bench-adaptive bench-materials clean fuzz fuzz-ci tools stress test-slurm test-netns
all: $(BUILD)/master $(BUILD)/worker $(BUILD)/smokesim $(TOOL_BIN)

# Install what is missing; the stamp makes later builds skip the check.
$(DEPS_STAMP): scripts/install-deps.sh
	@mkdir -p $(BUILD)
	@sh scripts/install-deps.sh $(DEB_PKGS)
	@touch $@
deps: $(DEPS_STAMP)

$(BUILD)/obj/%.o: %.c $(DEPS_STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -MMD -MP -c $< -o $@

$(BUILD)/libbrume.a: $(COMMON_OBJ)
	rm -f $@ && ar rcs $@ $^

# The master's modules without main(), for unit tests of the journal and the scheduler.
$(BUILD)/libmaster.a: $(MASTER_LIB_OBJ)
	rm -f $@ && ar rcs $@ $^

$(BUILD)/master: $(MASTER_OBJ) $(BUILD)/libbrume.a
	$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)

$(BUILD)/worker: $(WORKER_OBJ) $(BUILD)/libbrume.a
	$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)

$(SMOKE_NVDB_OBJ): smoke/nvdb_out.cpp smoke/nvdb_out.h $(DEPS_STAMP)
	@mkdir -p $(dir $@)
	$(CXX) -std=c++17 -O2 -g -fno-fast-math -ffp-contract=off -Wall -Wextra -I. -pthread -c $< -o $@

$(BUILD)/libsmoke.a: $(SMOKE_LIB_OBJ)
	rm -f $@ && ar rcs $@ $^

$(BUILD)/smokesim: $(BUILD)/obj/smoke/main.o $(BUILD)/libsmoke.a $(BUILD)/libbrume.a
	$(CC) $(LDFLAGS) -o $@ $^ $(FFTW_LIBS) $(LDLIBS)

$(TOOL_BIN): $(BUILD)/%: $(BUILD)/obj/tests/tools/%.o $(BUILD)/libbrume.a
	$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)

$(BUILD)/unit_tests: $(UNIT_OBJ) $(BUILD)/libmaster.a $(BUILD)/libsmoke.a $(BUILD)/libbrume.a
	$(CC) $(LDFLAGS) -o $@ $^ -lcriterion $(FFTW_LIBS) $(LDLIBS)

# NanoVDB test files, written by NanoVDB's own C++ writer (never committed; see make_nvdb.cpp).
# Plain g++ even under SAN=: it is a generator, not code under test.
$(BUILD)/make_nvdb: tests/tools/make_nvdb.cpp tests/tools/nvdb_values.h $(SMOKE_NVDB_OBJ) $(DEPS_STAMP)
	$(CXX) -std=c++17 -O1 -DNANOVDB_USE_ZIP -DNANOVDB_USE_BLOSC -I. $< $(SMOKE_NVDB_OBJ) -o $@ -lz -lblosc -pthread
$(BUILD)/testdata/.stamp: $(BUILD)/make_nvdb
	@mkdir -p $(BUILD)/testdata
	$(BUILD)/make_nvdb $(BUILD)/testdata
	@touch $@

unit: $(BUILD)/unit_tests $(BUILD)/testdata/.stamp
	cd tests/unit && LSAN_OPTIONS=suppressions=lsan.supp BRUME_TESTDATA=../../$(BUILD)/testdata ../../$(BUILD)/unit_tests --jobs=2

integration: all $(BUILD)/make_nvdb
	BUILD=$(BUILD) sh tests/integration/all.sh

# Long fault runs (many master kills); not part of `make test`.
stress: all
	BUILD=$(BUILD) TRIALS=100 KILL_TRIALS=100 sh tests/integration/faults.sh
	BUILD=$(BUILD) FRAME_TRIALS=25 sh tests/integration/frames.sh

# The protocol decoder under libFuzzer for a few seconds (clang, ASan + UBSan).
FUZZ_CI_SECONDS ?= 5
fuzz-ci: $(DEPS_STAMP)
	BUILD=$(BUILD) CC=$(CC) FUZZ_CI_SECONDS=$(FUZZ_CI_SECONDS) sh tests/fuzz/ci.sh

# Includes only downward between layers, no circle between modules (and the check's own test).
layers: $(DEPS_STAMP)
	sh tests/layers/run.sh

test: layers unit integration fuzz-ci

# Need root and daemons or namespaces; not part of `make test` (see README).
test-slurm: all
	BUILD=$(BUILD) sh tests/slurm/run.sh
test-netns: all
	BUILD=$(BUILD) sh tests/netns/run.sh

# The animated smoke scene's grids (scenes/smoke_anim/smoke.####.nvdb, not committed; resumable).
smoke-sim: $(BUILD)/smokesim
	$(BUILD)/smokesim scenes/smoke_anim/sim.json

# Simulates the smoke (resumes a run already done), then renders every 12th of its 48 frames
# with 2 local workers into out/smoke_anim.00NN.exr (docs/smoke.md).
smoke-demo: smoke-sim all
	mkdir -p out
	$(BUILD)/master scenes/smoke_anim/smoke_anim.json -o out/smoke_anim.exr --frames 1:48:12 --workers 2

# The showcase (scenes/showcase/README.md): the glass sculpture's mesh and the smoke's grids
# (not committed: 15 MB and 72 x 1.5 MB), then the still with 2 local workers, or the movie.
scenes/showcase/scherk.obj: scripts/gen_scherk.py
	python3 scripts/gen_scherk.py $@
showcase-assets: $(BUILD)/smokesim scenes/showcase/scherk.obj
	$(BUILD)/smokesim scenes/showcase/sim.json
showcase: showcase-assets all
	mkdir -p out
	$(BUILD)/master scenes/showcase/showcase.json -o out/showcase.exr --frames 72:72 --workers 2 \
	  --preview out/showcase.png
# Rewrites the committed scenes/showcase/bunny.obj from the npm package (needs npm).
showcase-bunny:
	d=$$(mktemp -d) && (cd $$d && npm pack bunny@1.0.1 >/dev/null && tar xzf bunny-1.0.1.tgz) && \
	  python3 scripts/gen_bunny.py $$d/package/index.js scenes/showcase/bunny.obj 0.55; rc=$$?; rm -rf $$d; exit $$rc
showcase-movie: showcase-assets all
	mkdir -p out
	BUILD=$(BUILD) sh scripts/make_movie.sh out/showcase.webp out/movie

# Time per step at 64^3 and 128^3 with 1 and 2 FFTW threads (docs/smoke.md).
bench-smoke: $(BUILD)/smokesim
	BUILD=$(BUILD) sh scripts/bench_smoke.sh

demo: all
	@mkdir -p out
	$(BUILD)/master scenes/cornell/cornell.json -o out/cornell.exr --workers 2 --preview out/cornell.png

bench: all
	BUILD=$(BUILD) sh scripts/bench.sh
	BUILD=$(BUILD) sh scripts/bench_sampling.sh
	BUILD=$(BUILD) sh scripts/bench_motion.sh
	BUILD=$(BUILD) sh scripts/bench_motion_blur.sh
	BUILD=$(BUILD) sh scripts/bench_media.sh
	BUILD=$(BUILD) sh scripts/bench_textures.sh
	BUILD=$(BUILD) sh scripts/bench_io.sh
	BUILD=$(BUILD) sh scripts/bench_master.sh
	BUILD=$(BUILD) sh scripts/bench_adaptive.sh
	BUILD=$(BUILD) sh scripts/bench_materials.sh

# Motion blur: the cost of motion (moving / still throughput), then analytic against
# sampled visibility at equal CPU time on four scenes, with a plot (docs/motion.md).
bench-motion: all
	BUILD=$(BUILD) sh scripts/bench_motion.sh
	BUILD=$(BUILD) sh scripts/bench_motion_blur.sh

# The master's capacity: fake workers (build/loadpeers), blob delivery, scaling, the model
# (docs/cluster.md); quick run: SPP=8 REPS=1 BCAST_NS="1 4" make bench-master
bench-master: all
	BUILD=$(BUILD) sh scripts/bench_master.sh

# Media: error against time for vpt and the photon method against an honest VPT reference
# (docs/benchmarks.md); quick run: SCENES=fog_spot BUDGETS="2 6" REF_SPP=256 SEEDS=11 make bench-media
bench-media: all
	BUILD=$(BUILD) sh scripts/bench_media.sh
# Adaptive rendering against uniform spp at equal error, and calibration (docs/adaptive.md);
# quick run: SCENES="cornell_glass motion" TARGETS="0.05 0.02" REF_SPP=1024 make bench-adaptive
bench-adaptive: all
	BUILD=$(BUILD) sh scripts/bench_adaptive.sh

# GGX sampling (visible normals against D cos) and the environment light (importance
# against uniform) at equal CPU time (docs/benchmarks.md); quick run: REF_SPP=256 SEEDS=1 make bench-materials
bench-materials: all
	BUILD=$(BUILD) sh scripts/bench_materials.sh

# Fuzz targets (libFuzzer, clang): make fuzz FUZZ_SECONDS=60 [FUZZ_ONLY="fuzz_nvdb ..."]
FUZZ_SECONDS ?= 30
FUZZ_ONLY ?=
fuzz: $(BUILD)/make_nvdb
	BUILD=$(BUILD) FUZZ_SECONDS=$(FUZZ_SECONDS) FUZZ_ONLY="$(FUZZ_ONLY)" sh tests/fuzz/run.sh

clean:
	rm -rf build build-san

-include $(COMMON_OBJ:.o=.d) $(MASTER_OBJ:.o=.d) $(SMOKE_OBJ:.o=.d) $(WORKER_OBJ:.o=.d) $(UNIT_OBJ:.o=.d) $(TOOL_OBJ:.o=.d)
