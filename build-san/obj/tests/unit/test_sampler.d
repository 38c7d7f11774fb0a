build-san/obj/tests/unit/test_sampler.o: tests/unit/test_sampler.c \
 common/sampler.h common/rng.h common/scene.h common/vec.h
common/sampler.h:
common/rng.h:
common/scene.h:
common/vec.h:
