build-san/obj/tests/unit/test_rng.o: tests/unit/test_rng.c common/rng.h \
 common/sampler.h common/rng.h common/scene.h common/vec.h
common/rng.h:
common/sampler.h:
common/rng.h:
common/scene.h:
common/vec.h:
