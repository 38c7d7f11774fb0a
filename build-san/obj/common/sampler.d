build-san/obj/common/sampler.o: common/sampler.c common/sampler.h \
 common/rng.h common/scene.h common/vec.h
common/sampler.h:
common/rng.h:
common/scene.h:
common/vec.h:
